#include "sil_loop.h"

#include <math.h>
#include <string.h>

#include "piezo_err.h"

int piezo_sil_ctl_config(const stage_params *p, int axis, piezo_ctl_cfg_t *cfg, piezo_scale_t *scale)
{
    const stage_axis_params *a;
    int db, ab;
    if (p == NULL || cfg == NULL || scale == NULL || axis < 0 || axis >= p->num_axes) {
        return PIEZO_EINVAL;
    }
    a = &p->axis[axis];
    db = a->dac.bits;
    ab = a->adc.bits;
    if (piezo_converter_cfg(cfg, db, ab) != PIEZO_OK) {
        return PIEZO_ERANGE;
    }
    scale->drive_min_v = a->amp.gain * a->dac.v_min + a->amp.offset_v;
    scale->drive_max_v = a->amp.gain * a->dac.v_max + a->amp.offset_v;
    scale->position_min_um = a->adc.y_min_um;
    scale->position_max_um = a->adc.y_max_um;
    cfg->u_safe_q15 = piezo_scale_volts_to_q15(scale, 0.0);
    cfg->limit.min_q15 = cfg->u_safe_q15 < 0 ? cfg->u_safe_q15 : -32768;
    return PIEZO_OK;
}

void piezo_sil_set_feedback(piezo_ctl_cfg_t *cfg, int32_t kp_q24, int32_t ki_q24, int32_t kd_q24,
                            const piezo_biquad_coef_t *notch)
{
    cfg->pid.kp_q24 = kp_q24;
    cfg->pid.ki_q24 = ki_q24;
    cfg->pid.kd_q24 = kd_q24;
    cfg->notch = *notch;
    cfg->notch_on = 1u;
}

int piezo_sil_init(piezo_sil_t *s, const stage_params *p, uint64_t seed)
{
    int rc;
    if (s == NULL || p == NULL || stage_init(&s->stage, p, seed) != STAGE_OK) {
        return PIEZO_EINVAL;
    }
    s->n_axes = p->num_axes;
    s->ticks = 0u;
    for (int i = 0; i < s->n_axes; i++) {
        piezo_ctl_cfg_t cfg;
        if ((rc = piezo_sil_ctl_config(p, i, &cfg, &s->scale[i])) != PIEZO_OK ||
            (rc = piezo_ctl_init(&s->ctl[i], &cfg)) != PIEZO_OK) {
            return rc;
        }
        s->dac[i] = cfg.dac_zero + (int32_t)(((int64_t)cfg.u_safe_q15 * cfg.dac_gain_q16) >> 16);
    }
    /* the sensor's first reading: the stage at rest under the safe drive */
    stage_step(&s->stage, s->dac, s->adc);
    return PIEZO_OK;
}

void piezo_sil_tick(piezo_sil_t *s)
{
    if (s->n_axes > 1) {
        /* each controller sees the other's drive of the previous tick (before
         * either ticks: the same lag for both axes) */
        int16_t u0 = s->ctl[0].sig[PIEZO_SIG_U], u1 = s->ctl[1].sig[PIEZO_SIG_U];
        s->ctl[0].sig[PIEZO_SIG_U2] = u1;
        s->ctl[1].sig[PIEZO_SIG_U2] = u0;
    }
    for (int i = 0; i < s->n_axes; i++) {
        int32_t in[2] = {s->adc[i], s->n_axes > 1 ? s->adc[1 - i] : 0};
        piezo_ctl_tick(&s->ctl[i], in, &s->dac[i]);
    }
    stage_step(&s->stage, s->dac, s->adc);
    s->ticks++;
}
