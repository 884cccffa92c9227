/*
 * pid.h - PI/PID feedback with anti-windup, followed by an optional notch
 * (biquad) that keeps the loop from exciting the stage's first resonance.
 *
 * Per tick, with e = r - y (q15):
 *     integ += ki_q24 * e                 (only when the output is not pushed
 *                                          further into saturation: anti-windup)
 *     v = rshift_rnd(kp_q24 * e + integ + kd_q24 * (e - e_prev), 24)
 *     u = clamp(v, out_min_q15, out_max_q15)
 * ki is the integral gain per tick (Ki * Ts), kd the derivative gain divided
 * by Ts, both in q24. The integrator itself is clamped to
 * [out_min, out_max] * 2^24 (q39) so it can never hold more than full output.
 *
 * Notch (biquad, direct form I, coefficients q24 with |c| < 4, a0 = 1):
 *     y31 = rshift_rnd((b0 x + b1 x1 + b2 x2) * 2^16 - a1 y1_31 - a2 y2_31, 24)
 *     y   = sat_q15(rshift_rnd(y31, 16))
 * The output history is kept in Q0.31 (16 bits below q15): with q15 history a
 * low-frequency notch's poles amplify the output rounding by 1 / (1 + a1 + a2)
 * (about 1300 at 140 Hz, 10 kHz), a DC error of tens of LSB. y31 saturates to
 * [-1, 1). The host designs the filter (scipy.signal.iirnotch) and quantizes
 * with the rounding rule.
 *
 * Scaling and overflow: PID products are q15 x q24 = q39 in int64, at most 3
 * terms of |x| < 2^46; the integrator is bounded by its clamp. Biquad terms are
 * at most 2^26 * 2^15 * 2^16 = 2^57 (x side) and 2^26 * 2^31 (y side), five
 * terms < 2^60. Outputs saturate to q15 (and to the PID limits).
 */
#ifndef PIEZO_PID_H
#define PIEZO_PID_H

#include <stdint.h>

typedef struct {
    int32_t kp_q24;
    int32_t ki_q24;        /* Ki * Ts */
    int32_t kd_q24;        /* Kd / Ts */
    int16_t out_min_q15;
    int16_t out_max_q15;
} piezo_pid_coef_t;

typedef struct {
    const piezo_pid_coef_t *coef;
    int64_t integ_q39;
    int16_t e_prev_q15;
    int16_t out_q15;
    uint8_t saturated;     /* last output was clamped */
} piezo_pid_t;

typedef struct {
    int32_t b0_q24, b1_q24, b2_q24;
    int32_t a1_q24, a2_q24;
} piezo_biquad_coef_t;

typedef struct {
    const piezo_biquad_coef_t *coef;
    int16_t x1_q15, x2_q15;
    int32_t y1_q31, y2_q31;
} piezo_biquad_t;

int piezo_pid_init(piezo_pid_t *p, const piezo_pid_coef_t *coef);
void piezo_pid_reset(piezo_pid_t *p);
/** One tick of the controller on error e (q15); returns the clamped output. */
int16_t piezo_pid_process(piezo_pid_t *p, int16_t e_q15);

int piezo_biquad_init(piezo_biquad_t *f, const piezo_biquad_coef_t *coef);
void piezo_biquad_reset(piezo_biquad_t *f);
int16_t piezo_biquad_process(piezo_biquad_t *f, int16_t x_q15);

/*
 * Output stage: clamp to [min, max], then limit the change per tick to
 * max_step_q15 (a slew-rate limit; 0 = no limit). `flags` reports bit 0
 * clamped, bit 1 slew-limited for the tick.
 */
typedef struct {
    int16_t min_q15;
    int16_t max_q15;
    int16_t max_step_q15;
} piezo_limit_coef_t;

typedef struct {
    const piezo_limit_coef_t *coef;
    int16_t prev_q15;
    uint8_t flags;
} piezo_limit_t;

#define PIEZO_LIMIT_CLAMPED 1u
#define PIEZO_LIMIT_SLEWED 2u

int piezo_limit_init(piezo_limit_t *l, const piezo_limit_coef_t *coef, int16_t start_q15);
void piezo_limit_reset(piezo_limit_t *l, int16_t start_q15);
int16_t piezo_limit_process(piezo_limit_t *l, int16_t u_q15);

/* The clamp and slew limit's body, inline: the controller's tick
 * (controller.c) runs it without a call (issue 15, round 14: 2 instructions
 * fewer per tick); piezo_limit_process is the same code out of line. */
static inline int16_t piezo_limit_step(piezo_limit_t *l, int16_t u_q15)
{
    const piezo_limit_coef_t *c = l->coef;
    int32_t u = u_q15;
    l->flags = 0u;
    if (u > c->max_q15) {
        u = c->max_q15;
        l->flags |= PIEZO_LIMIT_CLAMPED;
    } else if (u < c->min_q15) {
        u = c->min_q15;
        l->flags |= PIEZO_LIMIT_CLAMPED;
    }
    if (c->max_step_q15 > 0) {
        int32_t d = u - l->prev_q15;
        if (d > c->max_step_q15) {
            u = l->prev_q15 + c->max_step_q15;
            l->flags |= PIEZO_LIMIT_SLEWED;
        } else if (d < -c->max_step_q15) {
            u = l->prev_q15 - c->max_step_q15;
            l->flags |= PIEZO_LIMIT_SLEWED;
        }
    }
    l->prev_q15 = (int16_t)u;
    return (int16_t)u;
}

#endif /* PIEZO_PID_H */
