/* Test register bank: see test_modbus_regs.h. */
#include "test_modbus_regs.h"

#include <stddef.h>
#include <string.h>

uint16_t tregs_input_value(uint16_t addr)
{
    return addr == 0u ? 0x505Au : (uint16_t)(0x4000u + 3u * addr);
}

uint16_t *tregs_holding(tregs_t *t, uint16_t addr)
{
    if (addr >= TREGS_HOLD_A && addr < TREGS_HOLD_A + TREGS_HOLD_N) {
        return &t->hold[addr - TREGS_HOLD_A];
    }
    if (addr >= TREGS_HOLD_B && addr < TREGS_HOLD_B + TREGS_HOLD_N) {
        return &t->hold[TREGS_HOLD_N + (addr - TREGS_HOLD_B)];
    }
    return NULL;
}

static uint8_t read_input(void *ctx, uint16_t addr, uint16_t count, uint16_t *out)
{
    tregs_t *t = ctx;
    t->calls_read_input++;
    if ((uint32_t)addr + count > TREGS_INPUT_N) {
        return PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS;
    }
    memcpy(out, &t->in[addr], count * sizeof out[0]);
    return 0u;
}

/* 0 when every register of [addr, addr + count) is mapped, else an exception. */
static uint8_t check_holding(tregs_t *t, uint16_t addr, uint16_t count)
{
    for (uint32_t a = addr; a < (uint32_t)addr + count; a++) {
        if (tregs_holding(t, (uint16_t)a) == NULL) {
            return PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS;
        }
    }
    for (uint32_t a = addr; a < (uint32_t)addr + count; a++) {
        if (a == TREGS_FAULT) {
            return PIEZO_MB_EX_SERVER_DEVICE_FAILURE;
        }
    }
    return 0u;
}

static uint8_t read_holding(void *ctx, uint16_t addr, uint16_t count, uint16_t *out)
{
    tregs_t *t = ctx;
    t->calls_read_holding++;
    uint8_t r = check_holding(t, addr, count);
    if (r != 0u) {
        return r;
    }
    for (uint16_t i = 0; i < count; i++) {
        out[i] = *tregs_holding(t, (uint16_t)(addr + i));
    }
    return 0u;
}

static uint8_t write_holding(void *ctx, uint16_t addr, uint16_t count, const uint16_t *values)
{
    tregs_t *t = ctx;
    t->calls_write_holding++;
    uint8_t r = check_holding(t, addr, count);
    if (r != 0u) {
        return r;
    }
    for (uint16_t i = 0; i < count; i++) {
        if (addr + i == TREGS_MODE && values[i] > TREGS_MODE_MAX) {
            return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
        }
    }
    for (uint16_t i = 0; i < count; i++) {
        *tregs_holding(t, (uint16_t)(addr + i)) = values[i];
    }
    return 0u;
}

piezo_mb_regs_t tregs_init(tregs_t *t)
{
    memset(t, 0, sizeof *t);
    for (uint16_t a = 0; a < TREGS_INPUT_N; a++) {
        t->in[a] = tregs_input_value(a);
    }
    piezo_mb_regs_t regs = {t, read_input, read_holding, write_holding, NULL};
    return regs;
}
