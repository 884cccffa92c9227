/*
 * sil_loop.h - the firmware controller against the C stage model, tick by
 * tick, in simulated time (as fast as the host runs it).
 *
 * One controller per stage axis. Each tick: every controller reads the ADC
 * codes the stage produced at the end of the previous tick (its own axis
 * first, the other axis' second), computes its DAC code, then the stage
 * advances one sample with those codes. On a two-axis stage each
 * controller's sig[PIEZO_SIG_U2] (the other axis' drive: signal u2 and the input of the
 * cross-coupling compensation) is set before the tick to the other
 * controller's drive of the previous tick (what that axis' DAC holds). The converters map the full q15 range
 * onto their codes (q15 = code - 2^(bits-1), scaled to the bit width), and the
 * physical meaning of q15 full scale follows from the stage's DAC, amplifier
 * and ADC parameters (piezo_scale_t).
 */
#ifndef PIEZO_SIL_LOOP_H
#define PIEZO_SIL_LOOP_H

#include <stdint.h>

#include "controller.h"
#include "converters.h"
#include "stage_model.h"

typedef struct {
    stage_t stage;
    int n_axes;
    piezo_ctl_t ctl[STAGE_MAX_AXES];
    piezo_scale_t scale[STAGE_MAX_AXES];
    int32_t adc[STAGE_MAX_AXES];
    int32_t dac[STAGE_MAX_AXES];
    uint64_t ticks;
} piezo_sil_t;

/** Controller configuration and scale for one axis of a stage: converter
 *  scaling from the bit widths, plausibility at the ADC rails, u_safe = 0 V,
 *  no slew limit (the amplifier has its own), PID off until configured. */
int piezo_sil_ctl_config(const stage_params *p, int axis, piezo_ctl_cfg_t *cfg, piezo_scale_t *scale);

/** Feedback tuned on the host for a SIL stage (the golden headers' PI gains
 *  and notch, piezoctl.golden.sil_tables and xcouple_sil) into cfg: the PID
 *  gains (q24, pid.h) and the notch biquad, switched on. The PID's output
 *  limits and the rest of cfg stay as they are. */
void piezo_sil_set_feedback(piezo_ctl_cfg_t *cfg, int32_t kp_q24, int32_t ki_q24, int32_t kd_q24,
                            const piezo_biquad_coef_t *notch);

/** Stage at rest (seeded noise) and one controller per axis, disarmed, no table. */
int piezo_sil_init(piezo_sil_t *s, const stage_params *p, uint64_t seed);

/** One 10 kHz tick of every controller and the stage. */
void piezo_sil_tick(piezo_sil_t *s);


#endif /* PIEZO_SIL_LOOP_H */
