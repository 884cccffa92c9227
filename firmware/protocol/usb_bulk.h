/* Modbus PDUs over a pair of USB vendor-class bulk endpoints (see
 * docs/protocol.md, "USB bulk").
 *
 * Every transfer, either direction, is a 4-byte header and one PDU:
 *
 *   byte 0   magic 0xA5
 *   byte 1   sequence number: chosen by the host, echoed by the device
 *   byte 2-3 PDU length, little-endian, 1..253
 *   byte 4.. PDU (function code and data, as in modbus_pdu.h)
 *
 * The device answers every well-formed request with exactly one transfer
 * (the response or exception PDU). A malformed request (wrong magic, a length
 * of 0 or above 253, more bytes than the header announces, or a short packet
 * before the announced length) is dropped without an answer, like a bad RTU
 * frame; the host times out and retries with a new sequence number.
 *
 * The device side reassembles a request from bulk OUT packets: the header's
 * length says where it ends, so a request whose size is a multiple of the
 * packet size needs no zero-length packet; a short packet ends a transfer.
 */
#ifndef PIEZO_USB_BULK_H
#define PIEZO_USB_BULK_H

#include <stddef.h>
#include <stdint.h>

#include "modbus_pdu.h"

#define PIEZO_USB_MAGIC 0xA5u
#define PIEZO_USB_HDR 4u
#define PIEZO_USB_FRAME_MAX (PIEZO_USB_HDR + PIEZO_MB_PDU_MAX)

/* Request reassembly state of one OUT endpoint. */
typedef struct piezo_usb_rx {
    uint8_t buf[PIEZO_USB_FRAME_MAX];
    uint16_t len;         /* bytes of the current request so far */
    uint32_t dropped;     /* malformed requests dropped */
} piezo_usb_rx_t;

void piezo_usb_rx_init(piezo_usb_rx_t *rx);

/* Answers one complete request transfer (header + PDU) into rsp (cap >=
 * PIEZO_USB_FRAME_MAX). Returns the response transfer length, or 0 when the
 * request is malformed (no answer). */
size_t piezo_usb_process(const piezo_mb_regs_t *regs, const uint8_t *req, size_t n,
                         uint8_t *rsp, size_t cap);

/* Feeds one bulk OUT packet (n bytes; max_packet is the endpoint's
 * wMaxPacketSize, so n < max_packet marks the end of a transfer). When the
 * packet completes a request, answers it into rsp and returns the response
 * length; returns 0 while a request is incomplete or when one was dropped. */
size_t piezo_usb_feed(piezo_usb_rx_t *rx, const uint8_t *pkt, size_t n, size_t max_packet,
                      const piezo_mb_regs_t *regs, uint8_t *rsp, size_t cap);

#endif /* PIEZO_USB_BULK_H */
