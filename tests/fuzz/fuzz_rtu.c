/* libFuzzer target: the RTU framer (firmware/protocol/modbus_rtu.c) fed a
 * byte stream with timing, and the USB bulk reassembler fed the same bytes
 * as packets. Input: byte 0 picks the baud rate (and the USB packet size);
 * then pairs (ctl, byte): the byte arrives ctl & 0x3F times 64 us after the
 * previous one (0: in the same burst); ctl bit 7 polls the framer before the
 * byte; ctl bit 6 ends a USB packet after it. At the end the line falls
 * silent and the framer is polled.
 * Contract checked (abort on violation): every RTU reply is 5..256 bytes,
 * carries our unit id, has a valid CRC and an answer function code; no reply
 * to a broadcast; a USB answer has the magic, the request's sequence number
 * and a length matching its size. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "modbus_rtu.h"
#include "test_modbus_regs.h"
#include "usb_bulk.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static const uint32_t bauds[8] = {1200, 4800, 9600, 19200, 38400, 57600, 115200, 1000000};
static const size_t packets[4] = {8, 16, 64, 512};

static void check_reply(const uint8_t *reply, size_t n, uint8_t unit)
{
    if (n == 0u) {
        return;
    }
    if (n < 5u || n > PIEZO_RTU_ADU_MAX || reply[0] != unit || piezo_rtu_crc16(reply, n) != 0u) {
        abort();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1u) {
        return 0;
    }
    static tregs_t bank;
    piezo_mb_regs_t regs = tregs_init(&bank);
    static piezo_rtu_t rtu;
    const uint8_t unit = 1u;
    if (piezo_rtu_init(&rtu, unit, bauds[data[0] & 7u]) != 0) {
        abort();
    }
    static piezo_usb_rx_t usb;
    piezo_usb_rx_init(&usb);
    size_t mps = packets[(data[0] >> 3) & 3u];
    uint8_t pkt[512];
    size_t plen = 0;
    uint32_t t = 0xFFFFF000u;  /* the clock wraps during long inputs */
    uint8_t reply[PIEZO_RTU_ADU_MAX];
    uint8_t rsp[PIEZO_USB_FRAME_MAX];
    for (size_t i = 1; i + 1 < size; i += 2) {
        uint8_t ctl = data[i];
        uint8_t byte = data[i + 1];
        t += (uint32_t)(ctl & 0x3Fu) * 64u;
        if ((ctl & 0x80u) != 0u) {
            check_reply(reply, piezo_rtu_poll(&rtu, t, &regs, reply, sizeof reply), unit);
        }
        piezo_rtu_rx_byte(&rtu, byte, t);
        pkt[plen++] = byte;
        if ((ctl & 0x40u) != 0u || plen == mps) {
            /* sequence byte of the request this packet continues or starts */
            uint8_t req_seq = usb.len >= 2u ? usb.buf[1]
                              : usb.len == 1u ? pkt[0] : (plen > 1u ? pkt[1] : 0u);
            size_t n = piezo_usb_feed(&usb, pkt, plen, mps, &regs, rsp, sizeof rsp);
            if (n != 0u) {
                size_t len = (size_t)rsp[2] | ((size_t)rsp[3] << 8);
                if (n < 6u || rsp[0] != PIEZO_USB_MAGIC || rsp[1] != req_seq ||
                    len != n - PIEZO_USB_HDR) {
                    abort();
                }
            }
            plen = 0;
        }
    }
    uint32_t broadcasts = rtu.stats.broadcasts;
    uint32_t answered = rtu.stats.answered;
    t += piezo_rtu_t35_us(&rtu);
    for (int k = 0; k < 3; k++) {
        check_reply(reply, piezo_rtu_poll(&rtu, t, &regs, reply, sizeof reply), unit);
    }
    if (rtu.stats.broadcasts < broadcasts || rtu.stats.answered < answered ||
        rtu.stats.answered + rtu.stats.broadcasts > rtu.stats.frames) {
        abort();
    }
    return 0;
}
