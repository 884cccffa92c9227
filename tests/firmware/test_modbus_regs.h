/* A small register bank behind piezo_mb_regs_t for the protocol tests, the
 * pty/TCP test servers and the fuzzers (not the controller's register map):
 *
 *   input   0x0000..0x01FF  in[a]: 0x505A at 0, else (0x4000 + 3a) & 0xFFFF
 *   holding 0x1000..0x10FF and 0x2000..0x20FF, zero at start
 *   holding 0x1001 (mode) refuses values above 3: ILLEGAL DATA VALUE
 *   holding 0x10FE fails on any access: SERVER DEVICE FAILURE
 *   everything else: ILLEGAL DATA ADDRESS
 *
 * A write is checked over its whole range before anything is stored. */
#ifndef TEST_MODBUS_REGS_H
#define TEST_MODBUS_REGS_H

#include <stdint.h>

#include "modbus_pdu.h"

#define TREGS_INPUT_BASE 0x0000u
#define TREGS_INPUT_N 0x0200u
#define TREGS_HOLD_A 0x1000u
#define TREGS_HOLD_B 0x2000u
#define TREGS_HOLD_N 0x0100u     /* per block */
#define TREGS_MODE 0x1001u
#define TREGS_MODE_MAX 3u
#define TREGS_FAULT 0x10FEu

typedef struct tregs {
    uint16_t in[TREGS_INPUT_N];
    uint16_t hold[2u * TREGS_HOLD_N];
    unsigned calls_read_input;
    unsigned calls_read_holding;
    unsigned calls_write_holding;
} tregs_t;

/* Fills the bank (inputs as above, holdings 0, counters 0) and returns the
 * callback struct bound to it. */
piezo_mb_regs_t tregs_init(tregs_t *t);

/* Expected input register value. */
uint16_t tregs_input_value(uint16_t addr);

/* Pointer to holding register addr, or NULL when unmapped. */
uint16_t *tregs_holding(tregs_t *t, uint16_t addr);

#endif /* TEST_MODBUS_REGS_H */
