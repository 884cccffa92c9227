/* libFuzzer target: the Modbus PDU server (firmware/protocol/modbus_pdu.c)
 * with the test register bank. Besides the sanitizers it checks the
 * server's contract and aborts when one is broken:
 *   - an answer for every non-empty request, 2..253 bytes;
 *   - the answer's function code is the request's, or it with 0x80 and then
 *     the answer is 2 bytes with an exception code 01..04;
 *   - a normal answer to FC 3/4/23 carries exactly the registers asked for;
 *   - a request answered with an exception changed no register, except an
 *     FC 23 whose write was done before its read failed (spec order);
 *   - no callback saw a count outside 1..125 or a range past 0xFFFF. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_regs_check.h"
#include "modbus_pdu.h"
#include "test_modbus_regs.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static tregs_t bank;

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int ready;
    if (!ready) {
        fuzz_inner = tregs_init(&bank);
        ready = 1;
    }
    piezo_mb_regs_t regs = {&bank, fuzz_read_input, fuzz_read_holding, fuzz_write_holding, NULL};
    static uint16_t before[sizeof bank.hold / sizeof bank.hold[0]];
    memcpy(before, bank.hold, sizeof before);
    fuzz_writes_ok = 0;
    uint8_t rsp[PIEZO_MB_PDU_MAX];
    size_t n = piezo_mb_pdu_process(&regs, data, size, rsp, sizeof rsp);
    if (size == 0u) {
        if (n != 0u) {
            abort();
        }
        return 0;
    }
    if (n < 2u || n > PIEZO_MB_PDU_MAX) {
        abort();
    }
    uint8_t fc = data[0];
    if (rsp[0] == (uint8_t)(fc | 0x80u) && (rsp[0] != fc || n == 2u)) {
        if (n != 2u || rsp[1] < 1u || rsp[1] > 4u) {
            abort();
        }
        int fc23_read_failed = fc == PIEZO_MB_FC_READ_WRITE_MULTIPLE && fuzz_writes_ok == 1;
        if (!fc23_read_failed && memcmp(before, bank.hold, sizeof before) != 0) {
            abort();  /* a refused request changed registers */
        }
        return 0;
    }
    if (rsp[0] != fc) {
        abort();
    }
    if (fc == 3u || fc == 4u || fc == 23u) {
        uint16_t count = (uint16_t)((data[3] << 8) | data[4]);
        if (rsp[1] != 2u * count || n != 2u + 2u * count) {
            abort();
        }
    } else if (n != 5u || memcmp(rsp, data, 5) != 0) {
        abort();  /* FC 6 echoes, FC 16 echoes start and quantity */
    }
    return 0;
}
