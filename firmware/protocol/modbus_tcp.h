/* Modbus TCP: the MBAP header around the PDU server (modbus_pdu.h).
 *
 * Reference: "MODBUS Messaging on TCP/IP Implementation Guide V1.0b" (2006),
 * cited as [TCP x.y]. ADU = MBAP header (7 bytes) + PDU [TCP 3.1.3]:
 *
 *   transaction id (2)  copied by the server from request to response
 *   protocol id (2)     0 = MODBUS
 *   length (2)          bytes that follow: unit id + PDU, 2..254
 *   unit id (1)         copied from request to response
 *
 * All fields big-endian. Transport-free: the caller owns the socket (see
 * tcp_server_libmodbus.h for the Linux/SIL server loop).
 */
#ifndef PIEZO_MODBUS_TCP_H
#define PIEZO_MODBUS_TCP_H

#include <stddef.h>
#include <stdint.h>

#include "modbus_pdu.h"

#define PIEZO_MBAP_HDR 7u
#define PIEZO_TCP_ADU_MAX (PIEZO_MBAP_HDR + PIEZO_MB_PDU_MAX)  /* 260 [TCP 4.2] */

/* Total length of the ADU that starts buf, from the first `have` bytes:
 * > 0 the frame length (8..260); 0 when fewer than 6 bytes are there yet;
 * -1 when the header cannot start a Modbus frame (protocol id != 0, or a
 * length field outside 2..254), after which the byte stream cannot be
 * resynchronised and the connection should be closed. */
int piezo_mb_tcp_frame_len(const uint8_t *buf, size_t have);

/* Answers one complete ADU of n bytes into rsp (cap >= PIEZO_TCP_ADU_MAX).
 * unit_id is the device's own id: requests for it, for 0 or for 0xFF are
 * answered ([TCP 4.4.2]: on TCP the unit id is of no use to address a server,
 * 0xFF is recommended); requests for another unit get no answer, as on a
 * serial line. Returns the response length, or 0 for no answer (another unit,
 * or an ADU that piezo_mb_tcp_frame_len() refuses or that is not n bytes). */
size_t piezo_mb_tcp_process(const piezo_mb_regs_t *regs, uint8_t unit_id, const uint8_t *req,
                            size_t n, uint8_t *rsp, size_t cap);

#endif /* PIEZO_MODBUS_TCP_H */
