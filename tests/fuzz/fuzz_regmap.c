/* libFuzzer target: the real register map (firmware/control/regmap.c) of a
 * real controller (piezo_ctl_t) behind the Modbus PDU server, driven by a
 * sequence of operations decoded from the input:
 *
 *   op % 9  0 raw request: length byte n, then n bytes of PDU (n may be 0)
 *           1 ticks: 1..64 controller ticks with an ADC value (2 bytes)
 *           2 unlock: FC 06 of the unlock key (or, with the low bit of the
 *             next byte set, of the next two bytes)
 *           3 table chunk: FC 16 of table_offset + table_window, as the host
 *             uploads: offset (2 bytes, x2), n (1 byte, 1..121 words), 2n
 *             bytes of image
 *           4 seal: write the CRC-32 the staged header's payload length
 *             implies (so mutated images reach the commit's checks)
 *           5 commit, 6 rollback, 7 clear staged: FC 06 of table_command
 *           8 read-back: FC 23 offset + window (1 byte: chunk index) and
 *             compare with the staged bank
 *
 * The controller starts fresh for every input (no store). Besides ASan and
 * UBSan it aborts when a contract is broken:
 *   - every request gets an answer of 2..253 bytes whose function code is the
 *     request's, or it | 0x80 with exception code 01..04 (2 bytes), and a
 *     normal answer to FC 3/4/23 carries exactly the registers asked for;
 *   - a request answered with an exception changed no holding register, no
 *     byte of the staged bank and no configuration (except an FC 23 whose
 *     write was done before its read was refused, the spec's order);
 *   - the table in effect (active or pending) is none, or one whose CRC is a
 *     table this input committed successfully: it changes only to the CRC of
 *     the staged image, recomputed here independently (own CRC-32, the
 *     staged header's length), when that image was intact and passes
 *     piezo_table_check, or back to a CRC committed before (rollback);
 *   - every status and identity input register stays readable;
 *   - the FC 23 read-back returns the staged bytes.
 * Seeds: tests/fuzz/seed_regmap.py. Built with -DFUZZ_REGMAP_TRACE it prints
 * one line per request (to replay a crash: the binary with the input file). */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "controller.h"
#include "ctl_test_cfg.h"
#include "fuzz_regs_check.h"
#include "modbus_pdu.h"
#include "piezo_interface.h"
#include "regmap.h"
#include "table_image.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define H_TABLE_OFFSET 0x2000u
#define H_TABLE_WINDOW 0x2002u
#define H_TABLE_COMMAND 0x2080u
#define H_UNLOCK_KEY 0x1008u
#define WINDOW 121u
#define MAX_GOOD 64u
#define MAX_HOLD 4096u

static piezo_ctl_t ctl, ctl_before;
static piezo_regmap_t map;
static uint32_t good[MAX_GOOD];      /* CRCs of tables committed successfully */
static unsigned n_good;
static uint16_t hold_before[MAX_HOLD], hold_after[MAX_HOLD];

static void fail(void)
{
    abort();
}

/* ---- independent CRC-32 (IEEE, reflected; zlib.crc32) */
static uint32_t crc32_ref(const uint8_t *p, size_t n)
{
    uint32_t c = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        c ^= p[i];
        for (int k = 0; k < 8; k++) {
            c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
        }
    }
    return ~c;
}

static uint32_t le32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

/* Length of the image the staged bank holds by its header, or 0. */
static uint32_t staged_image_len(const piezo_ctl_t *c)
{
    if (c->staged_len < PIEZO_TABLE_HDR_BYTES + 4u) {
        return 0u;
    }
    uint32_t payload = le32(c->staged + PIEZO_TABLE_HDR_PAYLOAD_LEN_OFFSET);
    if (payload > PIEZO_TABLE_MAX_BYTES || PIEZO_TABLE_HDR_BYTES + payload + 4u > c->staged_len) {
        return 0u;
    }
    return PIEZO_TABLE_HDR_BYTES + payload + 4u;
}

static int is_good(uint32_t crc)
{
    for (unsigned i = 0; i < n_good; i++) {
        if (good[i] == crc) {
            return 1;
        }
    }
    return 0;
}

/* the register map's callbacks with the server's own contract checked (fuzz_regs_check.h) */
static const piezo_mb_regs_t regs = {&map, fuzz_read_input, fuzz_read_holding, fuzz_write_holding, NULL};

/* Every holding register's value, read through map m (descriptor order). */
static unsigned snapshot_holding(piezo_regmap_t *m, uint16_t *out)
{
    piezo_mb_regs_t r = piezo_regmap_regs(m);
    unsigned n = 0u;
    for (unsigned i = 0; i < PIEZO_HREG_N; i++) {
        const piezo_reg_desc_t *d = &piezo_holding_regs[i];
        uint32_t words = (uint32_t)d->words * d->count;
        for (uint32_t k = 0; k < words; k += PIEZO_MB_MAX_READ) {
            uint16_t m = (uint16_t)(words - k < PIEZO_MB_MAX_READ ? words - k : PIEZO_MB_MAX_READ);
            if (n + m > MAX_HOLD || r.read_holding(r.ctx, (uint16_t)(d->addr + k), m, &out[n]) != 0u) {
                fail(); /* a defined holding register must be readable */
            }
            n += m;
        }
    }
    return n;
}

/* Every input register readable (identity and status). */
static void check_inputs(void)
{
    for (unsigned i = 0; i < PIEZO_IREG_N; i++) {
        const piezo_reg_desc_t *d = &piezo_input_regs[i];
        uint16_t words = (uint16_t)(d->words * d->count);
        uint8_t req[5] = {PIEZO_MB_FC_READ_INPUT, (uint8_t)(d->addr >> 8), (uint8_t)d->addr, 0,
                          (uint8_t)words};
        uint8_t rsp[PIEZO_MB_PDU_MAX];
        if (words > PIEZO_MB_MAX_READ ||
            piezo_mb_pdu_process(&regs, req, sizeof req, rsp, sizeof rsp) != 2u + 2u * words ||
            rsp[0] != PIEZO_MB_FC_READ_INPUT) {
            fail();
        }
    }
}

/* The table in effect may only be none, or a good one. */
static void check_active(void)
{
    uint32_t crc = piezo_ctl_active_crc(&ctl);
    if (crc != 0u && !is_good(crc)) {
        fail();
    }
    if (ctl.active >= 0 && (ctl.set[ctl.active].kind == 0u || !is_good(ctl.set[ctl.active].crc))) {
        fail();
    }
    if (ctl.pending >= 0 && (ctl.set[ctl.pending].kind == 0u || !is_good(ctl.set[ctl.pending].crc))) {
        fail();
    }
}

/* One request through the server, with every per-request check. Returns the
 * response length; rsp receives the response. */
static size_t request(const uint8_t *req, size_t len, uint8_t *rsp)
{
    /* before: the controller and the map (their holding registers are read
     * from this copy when the request is refused); the staged image's CRC */
    memcpy(&ctl_before, &ctl, sizeof ctl);
    piezo_regmap_t map_before = map;
    map_before.ctl = &ctl_before;
    uint32_t active_before = piezo_ctl_active_crc(&ctl);
    uint32_t img_len = staged_image_len(&ctl);
    uint32_t cand = 0u;
    int cand_ok = 0;
    if (img_len != 0u) {
        piezo_table_info_t info;
        cand = crc32_ref(ctl.staged, img_len - 4u);
        cand_ok = cand == le32(ctl.staged + img_len - 4u) &&
                  piezo_table_check(ctl.staged, img_len, &info) == PIEZO_TABLE_REASON_OK;
    }

    fuzz_writes_ok = 0;
    size_t n = piezo_mb_pdu_process(&regs, req, len, rsp, PIEZO_MB_PDU_MAX);

    /* the answer's shape */
    if (len == 0u) {
        if (n != 0u) {
            fail();
        }
        return 0u;
    }
    if (n < 2u || n > PIEZO_MB_PDU_MAX) {
        fail();
    }
    uint8_t fc = req[0];
    int exc = rsp[0] == (uint8_t)(fc | 0x80u) && rsp[0] != fc;
    if (exc) {
        if (n != 2u || rsp[1] < 1u || (rsp[1] > 4u && rsp[1] != 6u)) {
            fail();
        }
    } else if (rsp[0] != fc) {
        fail();
    } else if (fc == 3u || fc == 4u || fc == 23u) {
        uint16_t q = (uint16_t)((req[3] << 8) | req[4]); /* read quantity: same place in 3, 4, 23 */
        if (n != 2u + 2u * (size_t)q || rsp[1] != 2u * q) {
            fail();
        }
    }

    /* a refused request changes nothing (FC 23: unless its write was done) */
    if (exc && !(fc == PIEZO_MB_FC_READ_WRITE_MULTIPLE && fuzz_writes_ok != 0)) {
        /* Holding registers are a function of the controller and the map, so
         * an unchanged state (the cheap test) means unchanged registers; when
         * the state differs, the registers are compared to tell which broke. */
        piezo_regmap_t map_now = map;
        map_now.ctl = &ctl_before;
        /* a refused key is counted, and locks the session that sent it */
        ctl_before.st.bad_unlocks = ctl.st.bad_unlocks;
        ctl_before.unlock_bad_run = ctl.unlock_bad_run;
        ctl_before.bad_at_ms = ctl.bad_at_ms;
        ctl_before.unlocked = ctl.unlocked;
        if (memcmp(&ctl_before, &ctl, sizeof ctl) != 0 || memcmp(&map_before, &map_now, sizeof map) != 0) {
            unsigned nb = snapshot_holding(&map_before, hold_before);
            if (snapshot_holding(&map, hold_after) != nb ||
                memcmp(hold_before, hold_after, nb * sizeof hold_after[0]) != 0) {
                fail(); /* a holding register changed */
            }
            fail(); /* state behind no register changed: staged bank, tables, counters */
        }
    }

    /* the table in effect: unchanged, the intact staged image, or a good one back */
    uint32_t active = piezo_ctl_active_crc(&ctl);
    if (active != active_before) {
        if (cand_ok && active == cand && ctl.st.table_result == PIEZO_TABLE_REASON_OK) {
            if (!is_good(cand) && n_good < MAX_GOOD) {
                good[n_good++] = cand;
            }
        } else if (active == 0u || !is_good(active)) {
            fail();
        }
    }
    check_active();
#ifdef FUZZ_REGMAP_TRACE /* -DFUZZ_REGMAP_TRACE: one line per request on stderr */
    fprintf(stderr, "fc %02x len %zu -> %02x %s, active %08x, result %u, staged %u, good %u\n", fc, len, rsp[0],
            exc ? "exception" : "ok", active, ctl.st.table_result, ctl.staged_len, n_good);
#endif
    return n;
}

static size_t fc06(uint16_t addr, uint16_t value, uint8_t *rsp)
{
    uint8_t req[5] = {PIEZO_MB_FC_WRITE_SINGLE, (uint8_t)(addr >> 8), (uint8_t)addr, (uint8_t)(value >> 8),
                      (uint8_t)value};
    return request(req, sizeof req, rsp);
}

/* FC 16 of table_offset (2 words) and n window words from bytes (staged order). */
static void chunk(uint32_t offset, const uint8_t *bytes, unsigned n, uint8_t *rsp)
{
    uint8_t req[PIEZO_MB_PDU_MAX];
    unsigned q = n + 2u;
    req[0] = PIEZO_MB_FC_WRITE_MULTIPLE;
    req[1] = (uint8_t)(H_TABLE_OFFSET >> 8);
    req[2] = (uint8_t)H_TABLE_OFFSET;
    req[3] = 0u;
    req[4] = (uint8_t)q;
    req[5] = (uint8_t)(2u * q);
    req[6] = (uint8_t)(offset >> 24);
    req[7] = (uint8_t)(offset >> 16);
    req[8] = (uint8_t)(offset >> 8);
    req[9] = (uint8_t)offset;
    for (unsigned i = 0; i < n; i++) {
        req[10 + 2 * i] = bytes[2 * i + 1]; /* register value lo | hi << 8, big-endian on the wire */
        req[11 + 2 * i] = bytes[2 * i];
    }
    (void)request(req, 6u + 2u * q, rsp);
}

static void setup(void)
{
    piezo_ctl_cfg_t c = unit_cfg();
    c.overrun_limit = 0; /* never (unit_cfg: 5): the register reads back 0 here, as it always has */
    if (piezo_ctl_init(&ctl, &c) != 0) {
        fail();
    }
    piezo_regmap_init(&map, &ctl);
    map.drive_min_mv = 0;
    map.drive_max_mv = 150000;
    map.position_max_nm = 100000;
    piezo_ctl_set_key(&ctl, TEST_UNLOCK_KEY);
    fuzz_inner = piezo_regmap_regs(&map);
    n_good = 0u;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    uint8_t rsp[PIEZO_MB_PDU_MAX];
    size_t i = 0;
    setup();
#define NEED(k) do { if (size - i < (size_t)(k)) { goto done; } } while (0)
    while (i < size) {
        uint8_t op = (uint8_t)(data[i++] % 9u);
        switch (op) {
        case 0: {
            NEED(1);
            size_t n = data[i++];
            if (n > size - i) {
                n = size - i;
            }
            (void)request(&data[i], n, rsp);
            i += n;
            break;
        }
        case 1: {
            NEED(3);
            unsigned k = 1u + (data[i] & 63u);
            int32_t in[2] = {(int16_t)(data[i + 1] | (data[i + 2] << 8)), 0}, dac = 0;
            i += 3;
            for (unsigned t = 0; t < k; t++) {
                piezo_ctl_tick(&ctl, in, &dac);
            }
            check_active();
            break;
        }
        case 2: {
            NEED(1);
            uint32_t key = TEST_UNLOCK_KEY;
            if (data[i++] & 1u) {
                NEED(2);
                key = (uint32_t)(data[i] | (data[i + 1] << 8));
                i += 2;
            }
            uint8_t req[10] = {PIEZO_MB_FC_WRITE_MULTIPLE, (uint8_t)(H_UNLOCK_KEY >> 8), (uint8_t)H_UNLOCK_KEY, 0u, 2u,
                               4u, (uint8_t)(key >> 24), (uint8_t)(key >> 16), (uint8_t)(key >> 8), (uint8_t)key};
            (void)request(req, sizeof req, rsp);
            break;
        }
        case 3: {
            NEED(3);
            uint32_t off = 2u * (uint32_t)(data[i] | (data[i + 1] << 8));
            unsigned n = 1u + data[i + 2] % WINDOW;
            uint8_t bytes[2u * WINDOW];
            i += 3;
            memset(bytes, 0, sizeof bytes);
            size_t have = size - i < 2u * n ? size - i : 2u * n;
            memcpy(bytes, &data[i], have);
            i += have;
            chunk(off, bytes, n, rsp);
            break;
        }
        case 4: {
            uint32_t len = staged_image_len(&ctl);
            if (len != 0u && (len & 1u) == 0u && piezo_ctl_is_unlocked(&ctl, map.session)) {
                uint8_t crc[4];
                uint32_t v = crc32_ref(ctl.staged, len - 4u);
                for (int k = 0; k < 4; k++) {
                    crc[k] = (uint8_t)(v >> (8 * k));
                }
                chunk(len - 4u, crc, 2u, rsp);
            }
            break;
        }
        case 5: (void)fc06(H_TABLE_COMMAND, 1u, rsp); break;
        case 6: (void)fc06(H_TABLE_COMMAND, 2u, rsp); break;
        case 7: (void)fc06(H_TABLE_COMMAND, 3u, rsp); break;
        default: {
            NEED(1);
            uint32_t off = 2u * WINDOW * (uint32_t)(data[i++] % 8u);
            uint8_t req[14] = {PIEZO_MB_FC_READ_WRITE_MULTIPLE,
                               (uint8_t)(H_TABLE_WINDOW >> 8), (uint8_t)H_TABLE_WINDOW, 0, WINDOW,
                               (uint8_t)(H_TABLE_OFFSET >> 8), (uint8_t)H_TABLE_OFFSET, 0, 2, 4,
                               (uint8_t)(off >> 24), (uint8_t)(off >> 16), (uint8_t)(off >> 8), (uint8_t)off};
            size_t n = request(req, sizeof req, rsp);
            if (n != 2u + 2u * WINDOW || rsp[0] != PIEZO_MB_FC_READ_WRITE_MULTIPLE) {
                fail(); /* an even offset inside the bank is always legal */
            }
            for (unsigned k = 0; k < 2u * WINDOW; k++) {
                uint8_t want = off + k < sizeof ctl.staged ? ctl.staged[off + k] : 0u;
                if (rsp[2 + (k ^ 1u)] != want) { /* word k/2: high byte first on the wire */
                    fail();
                }
            }
            break;
        }
        }
        check_inputs();
    }
done:
    check_active();
    return 0;
}
