/*
 * control.c - the control loop of the firmware image: one axis, a
 * piezo_ctl_t sized for the chip (the capacities are set by the target's
 * CMakeLists.txt), ticked from SysTick through piezo_control_tick().
 *
 * The ADC and DAC drivers belong to another issue; until they exist the
 * weak defaults below stand in: the sensor reads its zero code and the DAC
 * code goes nowhere. The configuration is the safe boot state: disarmed,
 * IDLE, no table; the host configures and arms it over Modbus.
 */
#include <string.h>

#include "board.h"
#include "controller.h"
#include "flash_f4.h"
#include "control.h"
#include "tick.h"

/* Codes of a 16-bit ADC and DAC, mid-scale zero (the SIL target's scaling). */
#define CODE_BITS 16
#define CODE_ZERO (1 << (CODE_BITS - 1))
#define CODE_MAX ((1 << CODE_BITS) - 1)

piezo_ctl_t piezo_axis;

void piezo_control_default_cfg(piezo_ctl_cfg_t *cfg)
{
    memset(cfg, 0, sizeof *cfg);
    cfg->adc_zero = CODE_ZERO;
    cfg->sensor_gain_q16 = 1 << (32 - CODE_BITS); /* q15 LSB per code, q16 */
    cfg->adc_min_ok = 1;                           /* the rail codes are implausible */
    cfg->adc_max_ok = CODE_MAX - 1;
    cfg->max_jump_q15 = 8192;
    cfg->bad_limit = 3;
    cfg->overrun_limit = 100;
    cfg->u_safe_q15 = 0;
    cfg->dac_zero = CODE_ZERO;
    cfg->dac_gain_q16 = 1 << CODE_BITS; /* DAC codes per q15 LSB, q16 */
    cfg->dac_min = 0;
    cfg->dac_max = CODE_MAX;
    cfg->limit.min_q15 = -32768;
    cfg->limit.max_q15 = 32767;
    cfg->pid.out_min_q15 = -32768;
    cfg->pid.out_max_q15 = 32767;
    cfg->notch.b0_q24 = 1 << 24; /* pass-through until configured */
}

/* The board's converters and amplifier (weak: the PIL image puts the stage
 * model's in their place). Until the converter drivers exist: 16-bit codes,
 * a 0..150 V amplifier and a 0..100 um sensor, the ranges the identity
 * registers report. */
__attribute__((weak)) void piezo_control_board(piezo_ctl_cfg_t *cfg, piezo_control_range_t *range)
{
    piezo_control_default_cfg(cfg);
    range->drive_min_mv = 0;
    range->drive_max_mv = 150000;
    range->position_min_nm = 0;
    range->position_max_nm = 100000;
}

piezo_control_range_t piezo_control_range;

int piezo_control_init(void)
{
    piezo_ctl_cfg_t cfg;
    piezo_control_board(&cfg, &piezo_control_range);
    return piezo_ctl_init(&piezo_axis, &cfg);
}

__attribute__((weak)) void piezo_adc_read(int32_t adc[2])
{
    adc[0] = CODE_ZERO;
    adc[1] = CODE_ZERO;
}

__attribute__((weak)) void piezo_dac_write(int32_t code)
{
    (void)code;
}

void piezo_control_tick(void)
{
    int32_t adc[2];
    piezo_adc_read(adc);
    piezo_dac_write(piezo_ctl_step(&piezo_axis, adc));
}

/* Tables persist in flash sectors 10 and 11 (flash_f4.c); the PIL image puts
 * RAM in their place (QEMU models no flash interface). */
__attribute__((weak)) const piezo_storage_t *piezo_control_storage(void)
{
    static piezo_storage_t io;
    io = piezo_f4_flash_storage();
    return &io;
}

/* The controller parameters in sectors 8 and 9 (flash_f4.h); the PIL image:
 * RAM. */
__attribute__((weak)) const piezo_storage_t *piezo_control_params_storage(void)
{
    static piezo_storage_t io;
    io = piezo_f4_params_storage();
    return &io;
}
