/* The register callbacks of the fuzz targets (fuzz_pdu, fuzz_regmap): the
 * callbacks of a register bank (fuzz_inner) with the PDU server's side of
 * their contract checked, aborting when it is broken: every call names
 * 1..PIEZO_MB_MAX_READ registers inside 0..0xFFFF, a write at most
 * PIEZO_MB_MAX_WRITE. fuzz_writes_ok counts the writes the bank accepted;
 * the target zeroes it before each request, so that a refused request can
 * be told from an FC 23 whose write was done before its read failed.
 *
 * One translation unit per fuzz target includes this. */
#ifndef FUZZ_REGS_CHECK_H
#define FUZZ_REGS_CHECK_H

#include <stdint.h>
#include <stdlib.h>

#include "modbus_pdu.h"

static piezo_mb_regs_t fuzz_inner; /* the bank behind the checks */
static int fuzz_writes_ok;         /* write_holding calls the bank accepted */

static void fuzz_check_span(uint16_t addr, uint16_t count)
{
    if (count < 1u || count > PIEZO_MB_MAX_READ || (uint32_t)addr + count > 0x10000u) {
        abort();
    }
}

static uint8_t fuzz_read_input(void *ctx, uint16_t addr, uint16_t count, uint16_t *out)
{
    fuzz_check_span(addr, count);
    return fuzz_inner.read_input(ctx, addr, count, out);
}

static uint8_t fuzz_read_holding(void *ctx, uint16_t addr, uint16_t count, uint16_t *out)
{
    fuzz_check_span(addr, count);
    return fuzz_inner.read_holding(ctx, addr, count, out);
}

static uint8_t fuzz_write_holding(void *ctx, uint16_t addr, uint16_t count, const uint16_t *v)
{
    fuzz_check_span(addr, count);
    if (count > PIEZO_MB_MAX_WRITE) {
        abort();
    }
    uint8_t r = fuzz_inner.write_holding(ctx, addr, count, v);
    if (r == 0u) {
        fuzz_writes_ok++;
    }
    return r;
}

#endif /* FUZZ_REGS_CHECK_H */
