/*
 * board_converters.c - the firmware image's converters (piezoctl-fw only;
 * the PIL image has the stage model in their place): the reference design of
 * converters_spi.h behind the control loop's seams.
 *
 * Scaling: the AD5791 spans 0..+10 V (VREFP = 10 V, VREFN = 0 V, offset
 * binary) into a x15 piezo amplifier: drive 0..150 V, q15 -1..+1 onto codes
 * 0..2^20 - 1. The controller's drive is q15, so the DAC's 20 bits carry 16
 * bits of it (code = 16 x (q15 + 32768)); the 4 lower bits stay 0 (the
 * part's INL of 1 LSB and its low noise remain). The AD7980 spans 0..5 V
 * (REF = 5 V) from a capacitive sensor's 0..100 um: position q15 -1..+1
 * onto codes 0..65535. Safe drive: 0 V (code 0), also the power-on output.
 */
#include "control.h"
#include "converters_spi.h"

#define DAC_BITS 20
#define DAC_MAX ((1 << DAC_BITS) - 1)

void piezo_conv_board_init(void);

void piezo_control_board(piezo_ctl_cfg_t *cfg, piezo_control_range_t *range)
{
    piezo_control_default_cfg(cfg); /* 16-bit ADC codes, mid-scale zero */
    cfg->dac_zero = 1 << (DAC_BITS - 1);
    cfg->dac_gain_q16 = 1 << DAC_BITS; /* 16 codes per q15 LSB, q16 */
    cfg->dac_min = 0;
    cfg->dac_max = DAC_MAX;
    cfg->u_safe_q15 = -32768; /* 0 V */
    range->drive_min_mv = 0;
    range->drive_max_mv = 150000;
    range->position_min_nm = 0;
    range->position_max_nm = 100000;
    piezo_conv_board_init();
    piezo_conv_init(0u);
}

void piezo_adc_read(int32_t adc[2])
{
    piezo_conv_tick_edge(); /* the previous tick's DAC code out, the sample taken: now */
    adc[0] = (int32_t)piezo_ad7980_read();
    adc[1] = 0;
}

void piezo_dac_write(int32_t code)
{
    piezo_ad5791_write((uint32_t)code);
}
