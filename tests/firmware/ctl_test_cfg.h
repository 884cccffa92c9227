/* The controller configuration of the controller and register-map tests
 * (and of tests/fuzz/fuzz_regmap.c):
 * ADC and DAC codes equal q15 values; nothing clamps or slews; the safe
 * drive is the bottom of the range (the DCC reset state). */
#ifndef CTL_TEST_CFG_H
#define CTL_TEST_CFG_H

#include <string.h>

#include "controller.h"

static inline piezo_ctl_cfg_t unit_cfg(void)
{
    piezo_ctl_cfg_t c;
    memset(&c, 0, sizeof c);
    c.sensor_gain_q16 = 65536;
    c.adc_min_ok = -32768;
    c.adc_max_ok = 32767;
    c.bad_limit = 3;
    c.overrun_limit = 5;
    c.u_safe_q15 = -32768;
    c.dac_gain_q16 = 65536;
    c.dac_min = -32768;
    c.dac_max = 32767;
    c.limit.min_q15 = -32768;
    c.limit.max_q15 = 32767;
    c.pid.out_min_q15 = -32768;
    c.pid.out_max_q15 = 32767;
    c.notch.b0_q24 = 1 << 24;
    return c;
}

/* The unlock key the tests provision (>= 32 bits). */
#define TEST_UNLOCK_KEY 0x5EC0A71Du

#endif
