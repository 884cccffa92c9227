/*
 * eupi.h - extended unparallel Prandtl-Ishlinskii (EUPI) hysteresis model,
 * one sample per call.
 *
 *     y = H[u] = G_CPI[u] + G_UPI[u] + P(u)
 *     G_CPI[u] = a0 * u + sum_i b_i * F_{r_i,1}[u]          (classical bank)
 *     G_UPI[u] = sum_i sum_j d_ij * F_{rU_i,a_j}[u]          (unparallel grid)
 *     P(u)     = p0 + sum_{m=2..Np} p_m * u^m                (Horner)
 *
 * with the play operators of play.h.
 *
 * Formats and ranges (checked by init):
 *   u_q15, y_q15      int16_t q15, full scale [-1, 1).
 *   a0_q24            int32_t Q7.24, > 0.
 *   cpi               classical bank (n_a == 0): r_q15 thresholds in
 *                     [0, 32767], non-decreasing; w_q24 = b_i >= 0.
 *   upi               unparallel grid (n_a >= 1 unless n_r == 0): r_q15 in
 *                     [0, 32767], non-decreasing; a_q24 = a_j > 0;
 *                     w_q24 = d_ij >= 0, row-major (i, j).
 *   p_q24[n_p]        Q7.24 coefficients of u^2 .. u^(n_p + 1),
 *                     n_p <= PIEZO_EUPI_MAX_POLY, sum |p_m| < 64 (strict,
 *                     round 18: sum |p_m| <= 2^30 - 1 in Q7.24).
 *   p0_q24            Q7.24 constant term.
 *
 * Rounding: the play operators as in play.h; each Horner step rounds to Q7.24
 * with piezo_rshift_rnd64(h * u, 15) (computed as the rounded high word of
 * (2 h) (u 2^16), the same integer while |h| < 2^30: see
 * piezo_eupi_poly_hu_q24); the output rounds the Q39 sum once with
 * piezo_rshift_rnd64(acc, 24).
 *
 * Saturation: the output is clamped to q15 by piezo_sat_q15() (the golden model
 * clamps at the same points); nothing else saturates.
 *
 * Initial state: all operator outputs 0 (init and reset).
 *
 * Scaling and overflow: with |u| <= 1 and thresholds in [0, 1), classical
 * outputs stay in [-1, 1) and unparallel outputs in [-2, 1), i.e. below 2^16
 * in q15 units. A weight is below 2^31 in Q7.24, so each product of the Q39
 * accumulator is below 2^47 and a0 * u below 2^46; the Horner value h stays
 * within sum |p_m| <= 2^30 - 1 (a rounded h u 2^-15 is at most |h| for
 * |u| <= 1), so 2 h fits int32, and P is below 2^46 in Q39.
 * With at most 2 * 256 operators the sum stays below 2^57: the int64
 * accumulator cannot overflow.
 */
#ifndef PIEZO_EUPI_H
#define PIEZO_EUPI_H

#include <stddef.h>
#include <stdint.h>

#include "fixed_q.h"
#include "piezo_err.h"
#include "play.h"

#define PIEZO_EUPI_MAX_POLY 8u                      /* powers u^2 .. u^9 */
/* sum |p_m| must stay below this (strict): |h| < 2^30, so the Horner step's
 * 2 h fits int32 (one SMMULR, piezo_eupi_poly_hu_q24). */
#define PIEZO_EUPI_POLY_SUM_MAX_Q24 ((int64_t)64 << 24)

/* Entries of the caller's state (int32) and work (int64) arrays. */
#define PIEZO_EUPI_STATE_LEN(n_cpi, n_upi_r, n_upi_a) \
    ((size_t)(n_cpi) + (size_t)(n_upi_r) * (size_t)(n_upi_a))
#define PIEZO_EUPI_WORK_LEN(n_upi_r, n_upi_a) PIEZO_PLAY_WORK_LEN(n_upi_r, n_upi_a)

/* Coefficients: constant, may be shared. */
struct piezo_eupi_coef {
    struct piezo_play_coef cpi;  /* b_i on r_i, classical */
    struct piezo_play_coef upi;  /* d_ij on (rU_i, a_j) */
    const int32_t *p_q24;        /* [n_p] coefficients of u^2 .. u^(n_p+1) */
    int32_t a0_q24;              /* linear gain, > 0 */
    int32_t p0_q24;              /* constant term */
    uint16_t n_p;
};

struct piezo_eupi {
    const struct piezo_eupi_coef *coef;
    struct piezo_play cpi;
    struct piezo_play upi;
};

/*
 * Check the coefficients, bind the caller's arrays and reset.
 * state_q15: PIEZO_EUPI_STATE_LEN(cpi.n_r, upi.n_r, upi.n_a) entries;
 * work_q39: PIEZO_EUPI_WORK_LEN(upi.n_r, upi.n_a) entries (may be NULL if 0).
 * Returns PIEZO_OK, PIEZO_EINVAL, PIEZO_EORDER or PIEZO_ERANGE (play.h, plus:
 * a0 <= 0, a threshold >= 1, a negative weight, sum |p_m| >= 64, a classical
 * bank with slopes or a UPI grid without, n_p > PIEZO_EUPI_MAX_POLY).
 */
int piezo_eupi_init(struct piezo_eupi *m, const struct piezo_eupi_coef *coef,
                    int32_t *state_q15, size_t state_len,
                    int64_t *work_q39, size_t work_len);

void piezo_eupi_reset(struct piezo_eupi *m);

/* One sample: y_q15 = sat_q15(H[u](k)). */
int16_t piezo_eupi_process(struct piezo_eupi *m, int16_t u_q15);

/* Shared with eupi_inv.c. */

/* P(u) in Q39 by Horner (see Rounding above); exact for n_p == 0. */
int64_t piezo_eupi_poly_q39(const int32_t *p_q24, uint16_t n_p, int32_t p0_q24,
                            int16_t u_q15);
/* The same, inline: the inverse's sample (eupi_inv.c) runs it without a call
 * (issue 15, round 14: the call, its register saves and argument moves cost
 * about as much as the polynomial's own multiplies). */
/* The polynomial's part above its constant, hu = rshift_rnd(h u, 15) in
 * Q24 with h by Horner, so that P(u) = p0 2^15 + hu u (Q39); 0 for n_p == 0.
 * |h|, |hu| <= sum |p_m| < 2^30 (init's strict bound; a rounded h u 2^-15
 * is at most |h| for |u| <= 1).
 *
 * Each step is one SMMULR on the Cortex-M4 (round 18): rshift_rnd(h u, 15)
 * = (h u 2^17 + 2^31) >> 32, the rounded high word of (2 h) (u 2^16); 2 h
 * fits int32 because |h| < 2^30 and u 2^16 because u is q15 (-2^31 at
 * u = -1). The same integers as the 64-bit product, shift and round (5
 * instructions per step); the add of p_m is folded into it (SMMLAR). At
 * h = 2^30 exactly (sum |p_m| = 64, refused
 * since round 18) 2 h would wrap. */
static inline int32_t piezo_eupi_poly_hu_q24(const int32_t *p_q24, uint16_t n_p, int16_t u_q15)
{
    /* h = p_Np; h = h * u + p_m down to m = 2; hu = h * u. Unrolled (round
     * 18): one jump on n_p to the first term's load, then the steps fall
     * through to the last, no loop counter or end test per step (3
     * instructions per step, one SMMLAR each). u 2^16 as a product: no left
     * shift of a negative value. */
    const int32_t u16 = (int32_t)u_q15 * 65536;
    int32_t h;
    switch (n_p) {
    case 1u: h = p_q24[0]; goto s0;
    case 2u: h = p_q24[1]; goto s1;
    case 3u: h = p_q24[2]; goto s2;
    case 4u: h = p_q24[3]; goto s3;
    case 5u: h = p_q24[4]; goto s4;
    case 6u: h = p_q24[5]; goto s5;
    case 7u: h = p_q24[6]; goto s6;
    case 8u: h = p_q24[7]; break; /* PIEZO_EUPI_MAX_POLY */
    default: return 0;            /* n_p == 0 (init refuses n_p > 8) */
    }
    h = piezo_mul_hi_rnd_add(2 * h, u16, p_q24[6]);
s6: h = piezo_mul_hi_rnd_add(2 * h, u16, p_q24[5]);
s5: h = piezo_mul_hi_rnd_add(2 * h, u16, p_q24[4]);
s4: h = piezo_mul_hi_rnd_add(2 * h, u16, p_q24[3]);
s3: h = piezo_mul_hi_rnd_add(2 * h, u16, p_q24[2]);
s2: h = piezo_mul_hi_rnd_add(2 * h, u16, p_q24[1]);
s1: h = piezo_mul_hi_rnd_add(2 * h, u16, p_q24[0]);
s0: return piezo_mul_hi_rnd(2 * h, u16);
}

/* P(u) in Q39, inline: the same integers as piezo_eupi_poly_q39. */
static inline int64_t piezo_eupi_poly_q39_inline(const int32_t *p_q24, uint16_t n_p, int32_t p0_q24,
                                                 int16_t u_q15)
{
    const int64_t c0 = (int64_t)p0_q24 * PIEZO_Q15_ONE; /* Q39; no << of a negative */
    /* (no 64 x 64 multiply: fixed_q.h; hu = 0 for n_p == 0) */
    return piezo_mlal(c0, piezo_eupi_poly_hu_q24(p_q24, n_p, u_q15), u_q15);
}

/* Checks of the G_UPI + P part common to the model and its inverse. */
int piezo_eupi_check_upi_poly(const struct piezo_play_coef *upi,
                              const int32_t *p_q24, uint16_t n_p);

/* Binds a classical bank (its n_r operators at the start of state_q15) and a
 * UPI bank (the rest of state_q15, work_q39) on the caller's arrays; neither
 * instance is written unless both bind. Returns the play.h codes. */
int piezo_eupi_bind_banks(struct piezo_play *cpi, const struct piezo_play_coef *cpi_coef,
                          struct piezo_play *upi, const struct piezo_play_coef *upi_coef,
                          int32_t *state_q15, size_t state_len, int64_t *work_q39, size_t work_len);

/* Checks that a bank's thresholds are q15 signals (< 1) and weights >= 0. */
int piezo_eupi_check_bank_q15(const struct piezo_play_coef *bank);

#endif /* PIEZO_EUPI_H */
