/* Modbus PDU server, independent of the transport (RTU, TCP, USB bulk).
 *
 * References: "MODBUS Application Protocol Specification V1.1b3" (2012),
 * cited below as [AP 6.3] etc. The PDU is the function code and its data,
 * without address/unit id and checksum [AP 4.1]; its size is at most 253
 * bytes [AP 4.1].
 *
 * The server decodes a request, checks function code, quantities, byte count
 * and address range before it calls the application, then calls the
 * register-access interface below and encodes the response or the exception
 * response [AP 7]. No heap, no globals; reentrant for distinct buffers.
 */
#ifndef PIEZO_MODBUS_PDU_H
#define PIEZO_MODBUS_PDU_H

#include <stddef.h>
#include <stdint.h>

/* Sizes [AP 4.1]: RS232/RS485 ADU 256 bytes = address (1) + PDU (253) + CRC (2). */
#define PIEZO_MB_PDU_MAX 253u

/* Function codes [AP 5.1, 6.3, 6.4, 6.6, 6.12, 6.17]. */
#define PIEZO_MB_FC_READ_HOLDING 0x03u
#define PIEZO_MB_FC_READ_INPUT 0x04u
#define PIEZO_MB_FC_WRITE_SINGLE 0x06u
#define PIEZO_MB_FC_WRITE_MULTIPLE 0x10u
#define PIEZO_MB_FC_READ_WRITE_MULTIPLE 0x17u
/* An exception response carries the function code with this bit set [AP 7]. */
#define PIEZO_MB_EXCEPTION_BIT 0x80u

/* Exception codes [AP 7]. */
#define PIEZO_MB_EX_ILLEGAL_FUNCTION 0x01u
#define PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS 0x02u
#define PIEZO_MB_EX_ILLEGAL_DATA_VALUE 0x03u
#define PIEZO_MB_EX_SERVER_DEVICE_FAILURE 0x04u

/* Quantity limits per request. */
#define PIEZO_MB_MAX_READ 125u      /* 0x007D [AP 6.3, 6.4] */
#define PIEZO_MB_MAX_WRITE 123u     /* 0x007B [AP 6.12] */
#define PIEZO_MB_MAX_RW_READ 125u   /* 0x007D [AP 6.17] */
#define PIEZO_MB_MAX_RW_WRITE 121u  /* 0x0079 [AP 6.17]: the request must fit 253 bytes */

/* Register access supplied by the application. Each callback returns 0 or an
 * exception code (PIEZO_MB_EX_*); any other nonzero value is reported as
 * PIEZO_MB_EX_SERVER_DEVICE_FAILURE.
 *
 * The server has already checked: 1 <= count <= the function's limit and
 * addr + count <= 0x10000. A callback either performs the whole access or
 * none of it: write_holding must not store anything when it refuses (the
 * server never calls it for a request it refuses itself). A NULL callback
 * makes its function codes answer ILLEGAL FUNCTION. */
typedef struct piezo_mb_regs {
    void *ctx;
    uint8_t (*read_input)(void *ctx, uint16_t addr, uint16_t count, uint16_t *out);
    uint8_t (*read_holding)(void *ctx, uint16_t addr, uint16_t count, uint16_t *out);
    uint8_t (*write_holding)(void *ctx, uint16_t addr, uint16_t count,
                             const uint16_t *values);
    /* Optional (NULL: one anonymous session). A transport with sessions
     * calls it with PIEZO_MB_SESSION_BEGIN before each request of session
     * `id` (TCP: the connection's slot; RTU: 0), and with
     * PIEZO_MB_SESSION_END when that session is over (connection closed,
     * timed out or replaced): what it unlocked and staged goes with it. */
    void (*session)(void *ctx, uint8_t id, uint8_t event);
} piezo_mb_regs_t;

#define PIEZO_MB_SESSION_BEGIN 1u
#define PIEZO_MB_SESSION_END 2u
/* Session ids: the RTU line, TCP connection slots, the USB link. */
#define PIEZO_MB_SESSION_RTU 0u
#define PIEZO_MB_SESSION_TCP_FIRST 1u   /* slot i is session 1 + i (at most 5 slots) */
#define PIEZO_MB_SESSION_USB 6u
/* The RTU line's session ends after this long without a request to us. */
#define PIEZO_MB_RTU_SESSION_IDLE_US 30000000u

/* Exception code 06, SERVER DEVICE BUSY [AP 7]: the unlock backoff or lockout. */
#define PIEZO_MB_EX_SERVER_DEVICE_BUSY 0x06u

/* Processes one request PDU (req[0] is the function code) and writes the
 * response PDU or exception response to rsp. Returns the response length
 * (2..PIEZO_MB_PDU_MAX), or 0 when there is nothing to answer (req_len == 0,
 * or rsp_cap < PIEZO_MB_PDU_MAX, an argument error). Requests longer than
 * PIEZO_MB_PDU_MAX, or whose length differs from what their function code and
 * byte count imply, get ILLEGAL DATA VALUE [AP 7, code 03: "the implied length
 * is incorrect"]. req and rsp may not overlap. */
size_t piezo_mb_pdu_process(const piezo_mb_regs_t *regs, const uint8_t *req, size_t req_len,
                            uint8_t *rsp, size_t rsp_cap);

/* 1 for the function codes a broadcast may carry (writes without a read:
 * 06 and 16) [Modbus over Serial Line V1.02, 2.1: broadcast requests are
 * necessarily writing commands], else 0. */
int piezo_mb_pdu_is_broadcast_write(uint8_t function);

#endif /* PIEZO_MODBUS_PDU_H */
