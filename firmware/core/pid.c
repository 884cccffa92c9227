#include "pid.h"

#include <stddef.h>

#include "fixed_q.h"
#include "piezo_err.h"

int piezo_pid_init(piezo_pid_t *p, const piezo_pid_coef_t *coef)
{
    if (p == NULL || coef == NULL || coef->out_min_q15 > coef->out_max_q15) {
        return PIEZO_EINVAL;
    }
    p->coef = coef;
    piezo_pid_reset(p);
    return PIEZO_OK;
}

void piezo_pid_reset(piezo_pid_t *p)
{
    p->integ_q39 = 0;
    p->e_prev_q15 = 0;
    p->out_q15 = 0;
    p->saturated = 0u;
}

int16_t piezo_pid_process(piezo_pid_t *p, int16_t e_q15)
{
    const piezo_pid_coef_t *c = p->coef;
    const int32_t out_max = c->out_max_q15, out_min = c->out_min_q15;
    int64_t integ = p->integ_q39;
    int32_t v;
    /* the output's rounding constant (2^23) and the proportional and
     * derivative terms first: gcc then forms each product with one SMLAL.
     * The derivative only with kd != 0 (its product is 0 otherwise): round
     * 17, 2 instructions fewer with kd = 0 (the reference's PI), 1 more
     * with kd != 0; the same integers */
    int64_t pd = ((int64_t)1 << 23) + (int64_t)c->kp_q24 * e_q15;
    if (c->kd_q24 != 0) {
        pd += (int64_t)c->kd_q24 * ((int32_t)e_q15 - p->e_prev_q15);
    }
    /* anti-windup: hold the integrator while the last output sat at a limit
     * and the error would push it further out */
    if (!(p->saturated && ((p->out_q15 >= out_max && e_q15 > 0) ||
                           (p->out_q15 <= out_min && e_q15 < 0)))) {
        integ += (int64_t)c->ki_q24 * e_q15;
        /* clamp to [out_min, out_max] * 2^24 by the bits above the fraction:
         * floor(integ / 2^24) >= out_max iff integ >= out_max 2^24 (at equality
         * the clamp changes nothing), and < out_min iff integ < out_min 2^24;
         * |integ| < 2^39 + 2^46 before the clamp, so the quotient fits int32 */
        if ((int32_t)(integ >> 24) >= out_max) {
            integ = (int64_t)out_max * PIEZO_Q24_ONE;
        } else if ((int32_t)(integ >> 24) < out_min) {
            integ = (int64_t)out_min * PIEZO_Q24_ONE;
        }
    }
    /* |pd + integ| < 2^49: the rounded q15 value fits int32 (pd holds the
     * rounding constant) */
    v = (int32_t)((pd + integ) >> 24);
    p->saturated = (uint8_t)(v > out_max || v < out_min);
    p->out_q15 = (int16_t)(v > out_max ? out_max : (v < out_min ? out_min : v));
    p->integ_q39 = integ;
    p->e_prev_q15 = e_q15;
    return p->out_q15;
}

int piezo_biquad_init(piezo_biquad_t *f, const piezo_biquad_coef_t *coef)
{
    const int32_t lim = 4 * (int32_t)PIEZO_Q24_ONE;
    if (f == NULL || coef == NULL) {
        return PIEZO_EINVAL;
    }
    if (coef->b0_q24 <= -lim || coef->b0_q24 >= lim || coef->b1_q24 <= -lim || coef->b1_q24 >= lim ||
        coef->b2_q24 <= -lim || coef->b2_q24 >= lim || coef->a1_q24 <= -lim || coef->a1_q24 >= lim ||
        coef->a2_q24 <= -lim || coef->a2_q24 >= lim) {
        return PIEZO_ERANGE;
    }
    f->coef = coef;
    piezo_biquad_reset(f);
    return PIEZO_OK;
}

void piezo_biquad_reset(piezo_biquad_t *f)
{
    f->x1_q15 = f->x2_q15 = 0;
    f->y1_q31 = f->y2_q31 = 0;
}

int16_t piezo_biquad_process(piezo_biquad_t *f, int16_t x_q15)
{
    const piezo_biquad_coef_t *c = f->coef;
    /* - a1 y1 - a2 y2 as products of -a1 and -a2, each one multiply-accumulate
     * (SMLAL) instead of a multiply and a 64-bit subtraction: the same
     * integer, since init (and the register map's check before any write)
     * holds |a1|, |a2| < 4 * 2^24, so their negatives fit int32 */
    /* round 17: the output's rounding constant (2^23) starts the sum, and
     * the b part's 2^16 goes on x (a q15 x times 2^16 fits int32), so every
     * term is one SMLAL onto it (no shift of the b part's word pair, no
     * 64-bit add of the constant at the end): |b x 2^16|, |a y| < 2^26 2^31
     * each (init's bound), the sum exact in int64, the same integer */
    int64_t acc = (int64_t)1 << 23;
    acc += (int64_t)c->b0_q24 * ((int32_t)x_q15 * 65536);
    acc += (int64_t)c->b1_q24 * ((int32_t)f->x1_q15 * 65536);
    acc += (int64_t)c->b2_q24 * ((int32_t)f->x2_q15 * 65536);
    acc += (int64_t)(-c->a1_q24) * f->y1_q31;
    acc += (int64_t)(-c->a2_q24) * f->y2_q31;
    int32_t y31 = piezo_sat_i32(acc >> 24);
    f->x2_q15 = f->x1_q15;
    f->x1_q15 = x_q15;
    f->y2_q31 = f->y1_q31;
    f->y1_q31 = y31;
    /* rshift_rnd(y31, 16) in int32: floor((y + 2^15) / 2^16) is y >> 16 plus
     * bit 15 of y (y31 + 2^15 itself could overflow int32); it lies in
     * [-32768, 32768], so only the top can saturate */
    {
        const int32_t y = (y31 >> 16) + ((y31 >> 15) & 1);
        return (int16_t)(y > PIEZO_Q15_MAX ? PIEZO_Q15_MAX : y);
    }
}

int piezo_limit_init(piezo_limit_t *l, const piezo_limit_coef_t *coef, int16_t start_q15)
{
    if (l == NULL || coef == NULL || coef->min_q15 > coef->max_q15 || coef->max_step_q15 < 0) {
        return PIEZO_EINVAL;
    }
    l->coef = coef;
    piezo_limit_reset(l, start_q15);
    return PIEZO_OK;
}

void piezo_limit_reset(piezo_limit_t *l, int16_t start_q15)
{
    l->prev_q15 = start_q15;
    l->flags = 0u;
}

int16_t piezo_limit_process(piezo_limit_t *l, int16_t u_q15)
{
    return piezo_limit_step(l, u_q15);
}
