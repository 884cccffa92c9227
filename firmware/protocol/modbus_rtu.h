/* Modbus RTU framer for the firmware: frames bytes from a serial line into
 * requests for the PDU server (modbus_pdu.h) and builds reply frames.
 *
 * References: "MODBUS over Serial Line Specification and Implementation Guide
 * V1.02" (2006), cited as [SL x.y], and the MODBUS Application Protocol
 * V1.1b3 [AP x.y].
 *
 * Frame [SL 2.5.1]: address (1), PDU (1..253), CRC-16 (2, low byte first).
 * A frame ends after 3.5 character times of silence; a silence of more than
 * 1.5 character times inside a frame makes it incomplete, and it is discarded
 * [SL 2.5.1.1]. Above 19200 baud the timers are fixed: t1.5 = 750 us,
 * t3.5 = 1750 us [SL 2.5.1.1, "implementation"]. A character is 11 bits
 * (start, 8 data, parity or second stop, stop) [SL 2.5.1].
 *
 * Receiving: the target calls piezo_rtu_rx_byte() with each byte and the time
 * it was completely received (microseconds of a free-running 32-bit counter,
 * wrapping is fine; bytes drained from a FIFO together may share one
 * timestamp), and piezo_rtu_poll() from its main loop or a timer at least
 * every t3.5 / 2. Frames with a wrong CRC, another address, a length
 * below 4 or above 256 bytes, or an inner gap are dropped in silence
 * [SL 2.4.1: "the slave ... does not send a response"].
 *
 * Broadcast (address 0) [SL 2.1]: writes (FC 06, 16) are executed and not
 * answered; other broadcast requests are ignored.
 *
 * Fixed buffers, no heap, no division per byte: the timing is precomputed by
 * piezo_rtu_init(). rx_byte() and poll() must not run concurrently (call rx
 * from the loop that polls, or mask the UART interrupt around poll).
 */
#ifndef PIEZO_MODBUS_RTU_H
#define PIEZO_MODBUS_RTU_H

#include <stddef.h>
#include <stdint.h>

#include "modbus_pdu.h"

#define PIEZO_RTU_ADU_MAX 256u     /* [SL 2.5.1] address + 253-byte PDU + CRC */
#define PIEZO_RTU_ADU_MIN 4u       /* address, function code, CRC */
#define PIEZO_RTU_BROADCAST 0u     /* [SL 2.2] */
#define PIEZO_RTU_UNIT_MAX 247u    /* [SL 2.2] individual addresses 1..247 */

/* Diagnostic counters (wrap at 2^32). */
typedef struct piezo_rtu_stats {
    uint32_t frames;         /* complete frames seen, valid or not */
    uint32_t answered;       /* requests for us answered (normal or exception) */
    uint32_t broadcasts;     /* broadcast writes executed */
    uint32_t crc_errors;     /* right length, wrong CRC */
    uint32_t malformed;      /* too short, too long, or a gap above t1.5 inside */
    uint32_t not_for_us;     /* another address, or a broadcast read */
    uint32_t overruns;       /* a frame completed while the previous was unpolled */
} piezo_rtu_stats_t;

typedef struct piezo_rtu {
    /* session of the line (regs->session): last request to us */
    uint32_t last_req_us;
    uint8_t in_session;
    /* configuration (piezo_rtu_init) */
    uint8_t unit_id;
    uint32_t t35_us;     /* silence after the last byte that ends a frame */
    uint32_t gap15_us;   /* byte-to-byte interval above which a frame is broken: char + t1.5 */
    uint32_t gap35_us;   /* byte-to-byte interval that starts a new frame: char + t3.5 */
    /* receiver */
    uint8_t buf[2][PIEZO_RTU_ADU_MAX];
    uint16_t len[2];
    uint8_t rx;          /* buffer being received into */
    uint8_t broken;      /* current frame had an inner gap or overflowed */
    uint8_t ready;       /* buf[rx ^ 1] holds a valid frame for us, unprocessed */
    uint16_t crc;        /* running CRC-16 of buf[rx] */
    uint32_t last_us;    /* timestamp of the last received byte */
    piezo_rtu_stats_t stats;
} piezo_rtu_t;

/* CRC-16/MODBUS: polynomial 0x8005 reflected (0xA001), initial value 0xFFFF,
 * no final XOR [SL 6.2.2]. "123456789" gives 0x4B37. */
uint16_t piezo_rtu_crc16(const uint8_t *data, size_t n);
uint16_t piezo_rtu_crc16_update(uint16_t crc, uint8_t byte);

/* Sets up a framer for unit_id (1..247) at baud (> 0). Returns PIEZO_OK, or
 * PIEZO_EINVAL (piezo_err.h) for an invalid argument (the framer is then unusable). The only divisions of
 * the framer are here. */
int piezo_rtu_init(piezo_rtu_t *r, uint8_t unit_id, uint32_t baud);

/* Silence that ends a frame [us]: the target's poll period should be at most
 * half of it. */
uint32_t piezo_rtu_t35_us(const piezo_rtu_t *r);

/* One received byte, timestamped when it was completely received. */
void piezo_rtu_rx_byte(piezo_rtu_t *r, uint8_t byte, uint32_t now_us);

/* n bytes received together (one timestamp). */
void piezo_rtu_rx(piezo_rtu_t *r, const uint8_t *data, size_t n, uint32_t now_us);

/* Ends a frame after t3.5 of silence, runs a complete request through the PDU
 * server and writes the reply frame (address, PDU, CRC) to reply. Returns the
 * reply length to transmit, or 0 when there is nothing to send (no complete
 * request, a dropped frame, a broadcast, or cap < PIEZO_RTU_ADU_MAX). One
 * request per call: a frame ended by silence while another waited is
 * processed by the next call. */
size_t piezo_rtu_poll(piezo_rtu_t *r, uint32_t now_us, const piezo_mb_regs_t *regs,
                      uint8_t *reply, size_t cap);

#endif /* PIEZO_MODBUS_RTU_H */
