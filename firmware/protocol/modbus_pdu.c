/* Modbus PDU server: see modbus_pdu.h. Section numbers [AP x.y] refer to the
 * MODBUS Application Protocol Specification V1.1b3. */
#include "modbus_pdu.h"

static uint16_t get_u16(const uint8_t *p)
{
    return (uint16_t)(((uint16_t)p[0] << 8) | p[1]);  /* big-endian [AP 4.2] */
}

static void put_u16(uint8_t *p, uint16_t v)
{
    p[0] = (uint8_t)(v >> 8);
    p[1] = (uint8_t)v;
}

static size_t exception(uint8_t *rsp, uint8_t function, uint8_t code)
{
    rsp[0] = (uint8_t)(function | PIEZO_MB_EXCEPTION_BIT);  /* [AP 7] */
    rsp[1] = code;
    return 2u;
}

/* A callback's result as an exception code: 0, 01..04 and 06 pass, anything
 * else becomes SERVER DEVICE FAILURE. */
static uint8_t app_result(uint8_t r)
{
    return r <= PIEZO_MB_EX_SERVER_DEVICE_FAILURE || r == PIEZO_MB_EX_SERVER_DEVICE_BUSY
               ? r
               : PIEZO_MB_EX_SERVER_DEVICE_FAILURE;
}

/* Starting address and starting address + quantity must both lie in the
 * 16-bit address space [AP 6.3 state diagram: "Starting Address == OK AND
 * Starting Address + Quantity of Registers == OK"]. */
static int range_ok(uint16_t addr, uint16_t count)
{
    return (uint32_t)addr + count <= 0x10000u;
}

static size_t encode_registers(uint8_t *rsp, uint8_t function, const uint16_t *v, uint16_t n)
{
    rsp[0] = function;
    rsp[1] = (uint8_t)(2u * n);  /* byte count [AP 6.3]: 2 x N */
    for (uint16_t i = 0; i < n; i++) {
        put_u16(&rsp[2u + 2u * i], v[i]);
    }
    return 2u + 2u * (size_t)n;
}

/* FC 03 read holding registers [AP 6.3], FC 04 read input registers [AP 6.4]:
 * request fc, start (2), quantity (2); quantity 1..125. */
static size_t read_registers(const piezo_mb_regs_t *regs, const uint8_t *req, size_t len,
                             uint8_t *rsp)
{
    uint8_t fc = req[0];
    uint8_t (*read)(void *, uint16_t, uint16_t, uint16_t *) =
        fc == PIEZO_MB_FC_READ_HOLDING ? regs->read_holding : regs->read_input;
    if (read == NULL) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_FUNCTION);
    }
    if (len != 5u) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    uint16_t addr = get_u16(&req[1]);
    uint16_t count = get_u16(&req[3]);
    if (count < 1u || count > PIEZO_MB_MAX_READ) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    if (!range_ok(addr, count)) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS);
    }
    uint16_t v[PIEZO_MB_MAX_READ];
    uint8_t r = app_result(read(regs->ctx, addr, count, v));
    if (r != 0u) {
        return exception(rsp, fc, r);
    }
    return encode_registers(rsp, fc, v, count);
}

/* FC 06 write single register [AP 6.6]: request fc, address (2), value (2);
 * the normal response echoes the request. Any 16-bit value is legal. */
static size_t write_single(const piezo_mb_regs_t *regs, const uint8_t *req, size_t len,
                           uint8_t *rsp)
{
    uint8_t fc = req[0];
    if (regs->write_holding == NULL) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_FUNCTION);
    }
    if (len != 5u) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    uint16_t value = get_u16(&req[3]);
    uint8_t r = app_result(regs->write_holding(regs->ctx, get_u16(&req[1]), 1u, &value));
    if (r != 0u) {
        return exception(rsp, fc, r);
    }
    for (size_t i = 0; i < 5u; i++) {
        rsp[i] = req[i];
    }
    return 5u;
}

/* Decodes n big-endian register values. */
static void decode_values(const uint8_t *p, uint16_t n, uint16_t *v)
{
    for (uint16_t i = 0; i < n; i++) {
        v[i] = get_u16(&p[2u * i]);
    }
}

/* FC 16 write multiple registers [AP 6.12]: request fc, start (2), quantity
 * (2), byte count (1) = 2 x quantity, values; quantity 1..123. Response fc,
 * start, quantity. */
static size_t write_multiple(const piezo_mb_regs_t *regs, const uint8_t *req, size_t len,
                             uint8_t *rsp)
{
    uint8_t fc = req[0];
    if (regs->write_holding == NULL) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_FUNCTION);
    }
    if (len < 6u) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    uint16_t addr = get_u16(&req[1]);
    uint16_t count = get_u16(&req[3]);
    uint8_t nbytes = req[5];
    if (count < 1u || count > PIEZO_MB_MAX_WRITE || nbytes != 2u * count ||
        len != 6u + (size_t)nbytes) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    if (!range_ok(addr, count)) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS);
    }
    uint16_t v[PIEZO_MB_MAX_WRITE];
    decode_values(&req[6], count, v);
    uint8_t r = app_result(regs->write_holding(regs->ctx, addr, count, v));
    if (r != 0u) {
        return exception(rsp, fc, r);
    }
    for (size_t i = 0; i < 5u; i++) {
        rsp[i] = req[i];
    }
    return 5u;
}

/* FC 23 read/write multiple registers [AP 6.17]: request fc, read start (2),
 * read quantity (2) 1..125, write start (2), write quantity (2) 1..121, write
 * byte count (1) = 2 x write quantity, values. "The write operation is
 * performed before the read" [AP 6.17]. Both halves are checked before the
 * write; if the application then refuses the read, the write has happened
 * (the exception response says so only by its code). */
static size_t read_write_multiple(const piezo_mb_regs_t *regs, const uint8_t *req, size_t len,
                                  uint8_t *rsp)
{
    uint8_t fc = req[0];
    if (regs->read_holding == NULL || regs->write_holding == NULL) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_FUNCTION);
    }
    if (len < 10u) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    uint16_t raddr = get_u16(&req[1]);
    uint16_t rcount = get_u16(&req[3]);
    uint16_t waddr = get_u16(&req[5]);
    uint16_t wcount = get_u16(&req[7]);
    uint8_t nbytes = req[9];
    if (rcount < 1u || rcount > PIEZO_MB_MAX_RW_READ || wcount < 1u ||
        wcount > PIEZO_MB_MAX_RW_WRITE || nbytes != 2u * wcount ||
        len != 10u + (size_t)nbytes) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    if (!range_ok(raddr, rcount) || !range_ok(waddr, wcount)) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS);
    }
    uint16_t v[PIEZO_MB_MAX_RW_READ];  /* the written values, then the read ones */
    decode_values(&req[10], wcount, v);
    uint8_t r = app_result(regs->write_holding(regs->ctx, waddr, wcount, v));
    if (r == 0u) {
        r = app_result(regs->read_holding(regs->ctx, raddr, rcount, v));
    }
    if (r != 0u) {
        return exception(rsp, fc, r);
    }
    return encode_registers(rsp, fc, v, rcount);
}

size_t piezo_mb_pdu_process(const piezo_mb_regs_t *regs, const uint8_t *req, size_t req_len,
                            uint8_t *rsp, size_t rsp_cap)
{
    if (regs == NULL || req == NULL || rsp == NULL || req_len == 0u ||
        rsp_cap < PIEZO_MB_PDU_MAX) {
        return 0u;
    }
    uint8_t fc = req[0];
    switch (fc) {
    case PIEZO_MB_FC_READ_HOLDING:
    case PIEZO_MB_FC_READ_INPUT:
    case PIEZO_MB_FC_WRITE_SINGLE:
    case PIEZO_MB_FC_WRITE_MULTIPLE:
    case PIEZO_MB_FC_READ_WRITE_MULTIPLE:
        break;
    default:
        /* Unsupported, including 0 and codes with the exception bit [AP 7, code 01]. */
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_FUNCTION);
    }
    if (req_len > PIEZO_MB_PDU_MAX) {
        return exception(rsp, fc, PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    }
    switch (fc) {
    case PIEZO_MB_FC_READ_HOLDING:
    case PIEZO_MB_FC_READ_INPUT:
        return read_registers(regs, req, req_len, rsp);
    case PIEZO_MB_FC_WRITE_SINGLE:
        return write_single(regs, req, req_len, rsp);
    case PIEZO_MB_FC_WRITE_MULTIPLE:
        return write_multiple(regs, req, req_len, rsp);
    default:
        return read_write_multiple(regs, req, req_len, rsp);
    }
}

int piezo_mb_pdu_is_broadcast_write(uint8_t function)
{
    return function == PIEZO_MB_FC_WRITE_SINGLE || function == PIEZO_MB_FC_WRITE_MULTIPLE;
}
