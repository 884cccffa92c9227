/* Modbus PDUs over USB bulk endpoints: see usb_bulk.h. */
#include "usb_bulk.h"

/* The PDU length a header announces, or 0 when the header is invalid. */
static size_t header_pdu_len(const uint8_t *h)
{
    size_t len = (size_t)h[2] | ((size_t)h[3] << 8);
    if (h[0] != PIEZO_USB_MAGIC || len < 1u || len > PIEZO_MB_PDU_MAX) {
        return 0u;
    }
    return len;
}

void piezo_usb_rx_init(piezo_usb_rx_t *rx)
{
    rx->len = 0u;
    rx->dropped = 0u;
}

size_t piezo_usb_process(const piezo_mb_regs_t *regs, const uint8_t *req, size_t n,
                         uint8_t *rsp, size_t cap)
{
    if (req == NULL || rsp == NULL || cap < PIEZO_USB_FRAME_MAX || n < PIEZO_USB_HDR) {
        return 0u;
    }
    size_t len = header_pdu_len(req);
    if (len == 0u || n != PIEZO_USB_HDR + len) {
        return 0u;
    }
    if (regs->session != NULL) {
        regs->session(regs->ctx, PIEZO_MB_SESSION_USB, PIEZO_MB_SESSION_BEGIN);
    }
    size_t out = piezo_mb_pdu_process(regs, &req[PIEZO_USB_HDR], len, &rsp[PIEZO_USB_HDR],
                                      PIEZO_MB_PDU_MAX);
    if (out == 0u) {
        return 0u;
    }
    rsp[0] = PIEZO_USB_MAGIC;
    rsp[1] = req[1];
    rsp[2] = (uint8_t)out;
    rsp[3] = (uint8_t)(out >> 8);
    return PIEZO_USB_HDR + out;
}

size_t piezo_usb_feed(piezo_usb_rx_t *rx, const uint8_t *pkt, size_t n, size_t max_packet,
                      const piezo_mb_regs_t *regs, uint8_t *rsp, size_t cap)
{
    int short_packet = n < max_packet;
    for (size_t i = 0; i < n; i++) {
        size_t need = PIEZO_USB_HDR;
        if (rx->len >= PIEZO_USB_HDR) {
            need += header_pdu_len(rx->buf);
        }
        if (rx->len >= need) {
            /* More bytes than the header announced in this transfer. */
            rx->len = 0u;
            rx->dropped++;
            return 0u;
        }
        rx->buf[rx->len++] = pkt[i];
        if (rx->len == PIEZO_USB_HDR && header_pdu_len(rx->buf) == 0u) {
            rx->len = 0u;
            rx->dropped++;
            return 0u;
        }
    }
    if (rx->len >= PIEZO_USB_HDR && rx->len == PIEZO_USB_HDR + header_pdu_len(rx->buf)) {
        /* Complete, whether on a short or a full packet: the header's
         * length says where the request ends, no zero-length packet needed. */
        size_t len = rx->len;
        rx->len = 0u;
        return piezo_usb_process(regs, rx->buf, len, rsp, cap);
    }
    if (short_packet && rx->len > 0u) {
        rx->len = 0u;  /* the transfer ended before the announced length */
        rx->dropped++;
    }
    return 0u;
}
