#include "converters.h"

#include <math.h>
#include <string.h>

#include "piezo_err.h"

static int16_t to_q15(double x, double lo, double hi)
{
    double q = floor((x - lo) / (hi - lo) * 65536.0 - 32768.0 + 0.5);
    return (int16_t)(q < -32768.0 ? -32768.0 : (q > 32767.0 ? 32767.0 : q));
}

int16_t piezo_scale_volts_to_q15(const piezo_scale_t *sc, double volts)
{
    return to_q15(volts, sc->drive_min_v, sc->drive_max_v);
}

int16_t piezo_scale_um_to_q15(const piezo_scale_t *sc, double um)
{
    return to_q15(um, sc->position_min_um, sc->position_max_um);
}

double piezo_scale_q15_to_um(const piezo_scale_t *sc, int32_t q15)
{
    return sc->position_min_um + ((double)q15 + 32768.0) / 65536.0 * (sc->position_max_um - sc->position_min_um);
}

int piezo_converter_cfg(piezo_ctl_cfg_t *cfg, int dac_bits, int adc_bits)
{
    if (cfg == NULL) {
        return PIEZO_EINVAL;
    }
    if (dac_bits < 1 || dac_bits > 16 || adc_bits < 1 || adc_bits > 16) {
        return PIEZO_ERANGE; /* q15 carries at most 16 bits */
    }
    memset(cfg, 0, sizeof *cfg);
    cfg->dac_zero = 1 << (dac_bits - 1);
    cfg->dac_gain_q16 = 1 << dac_bits;
    cfg->dac_min = 0;
    cfg->dac_max = (1 << dac_bits) - 1;
    cfg->adc_zero = 1 << (adc_bits - 1);
    cfg->sensor_gain_q16 = (int32_t)(1L << (32 - adc_bits));
    cfg->adc_min_ok = 1;
    cfg->adc_max_ok = (1 << adc_bits) - 2;
    cfg->max_jump_q15 = 16384;
    cfg->bad_limit = 3;
    cfg->overrun_limit = 100;
    cfg->limit.min_q15 = -32768;
    cfg->limit.max_q15 = 32767;
    cfg->pid.out_min_q15 = -32768;
    cfg->pid.out_max_q15 = 32767;
    cfg->notch.b0_q24 = 1 << 24;
    return PIEZO_OK;
}
