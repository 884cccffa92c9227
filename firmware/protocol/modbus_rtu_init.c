/* Modbus RTU framer set-up: the framer's only divisions, done once, so the
 * per-byte path (modbus_rtu.c) has none (tested: protocol_has_no_division).
 * [SL x.y] = MODBUS over Serial Line V1.02. */
#include "modbus_rtu.h"

#include "piezo_err.h"

/* ceil(bits_x10 * 100000 / baud) microseconds: bits_x10 is tenths of a bit. */
static uint32_t bit_time_us(uint32_t bits_x10, uint32_t baud)
{
    uint64_t num = (uint64_t)bits_x10 * 100000u;
    return (uint32_t)((num + baud - 1u) / baud);
}

int piezo_rtu_init(piezo_rtu_t *r, uint8_t unit_id, uint32_t baud)
{
    if (r == NULL) {
        return PIEZO_EINVAL;
    }
    *r = (piezo_rtu_t){0};
    if (unit_id < 1u || unit_id > PIEZO_RTU_UNIT_MAX || baud == 0u) {
        return PIEZO_EINVAL;
    }
    r->unit_id = unit_id;
    uint32_t tchar = bit_time_us(110u, baud);  /* 11 bits per character [SL 2.5.1] */
    uint32_t t15;
    uint32_t t35;
    if (baud > 19200u) {
        /* Fixed timers above 19200 baud [SL 2.5.1.1]. */
        t15 = 750u;
        t35 = 1750u;
    } else {
        t15 = bit_time_us(165u, baud);  /* 1.5 x 11 bits */
        t35 = bit_time_us(385u, baud);  /* 3.5 x 11 bits */
    }
    r->t35_us = t35;
    r->gap15_us = tchar + t15;
    r->gap35_us = tchar + t35;
    return PIEZO_OK;
}
