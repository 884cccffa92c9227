/*
 * play.h - a bank of classical (CPI) or unparallel (UPI) play operators with
 * their weighted sum, one sample per call.
 *
 * Operator (threshold r >= 0, upper-branch slope a > 0; a = 1 is the
 * classical play operator):
 *
 *     F(k) = max(u(k) - r, min(a * (u(k) + r), F(k-1)))
 *
 * the minimum taken first, exactly as written (the unparallel upper branch
 * rounded as below). A bank is either
 *   - classical (n_a == 0): n_r operators F_{r_i,1}, no multiplication; or
 *   - unparallel (n_a >= 1): the n_r x n_a grid F_{r_i,a_j}, stored row-major
 *     (operator k = i * n_a + j).
 * process() updates every operator and returns sum_k w_k * F_k.
 *
 * Formats:
 *   u_q15, r_q15, f_q15  int32_t holding q15-scaled values (Q16.15): 32768 is
 *                        1.0 full scale. The container is wide because the
 *                        inverse compensator feeds a bank with inputs and
 *                        thresholds beyond [-1, 1) and because UPI outputs
 *                        reach [-1 - r, 1) for inputs in [-1, 1).
 *                        Range: |u| <= PIEZO_PLAY_WIDE_MAX_Q15 (32.0 FS),
 *                        0 <= r <= PIEZO_PLAY_WIDE_MAX_Q15.
 *   a_q24, w_q24         int32_t Q7.24; a > 0, w any sign.
 *   return value         int64_t Q39 (q15 * q24), not rounded.
 *
 * Rounding (since round 17): the unparallel upper branch a * (u + r) is
 *
 *     hi_ij(u) = rshift_rnd(a_j * u, 24) + c_ij,  c_ij = rshift_rnd(a_j * r_i, 24)
 *
 * (rshift_rnd = piezo_rshift_rnd64, round half up): two roundings, one per
 * slope and sample and one per operator at init, instead of
 * rshift_rnd(a (u + r), 24) before round 17. The two differ by at most one
 * LSB (the sum of two rounding errors in (-1/2, 1/2] less a third is an
 * integer in (-3/2, 3/2); test_play checks it), hi stays non-decreasing in u
 * and in r, and a column's upper branch moves by the one step
 * rshift_rnd(a_j u, 24) - rshift_rnd(a_j u_prev, 24) for every operator.
 * c_ij is q15-scaled in an int32 (|c| < 2^27 for a < 2^31, r <= 2^20),
 * computed by init into the caller's work array (c2_q15). The lower branch
 * and the classical upper branch u +- r are exact. The weighted sum is exact.
 *
 * Saturation: none; nothing can overflow within the documented ranges.
 *
 * Work per sample (docs/kernels-pi.md, "Operators that move"): the results
 * are those of the formula applied to every operator, but process() touches
 * only the operators that can change and keeps the weighted sum up to date
 * by w_k * (F_new - F_old). With the thresholds non-decreasing, for each
 * slope (column) the operators that move form a prefix in threshold order:
 * rising input, F = max(u - r, F) moves iff u - r > F, and F + r is
 * non-decreasing in r; falling input, F moves iff F > hi (then
 * F = max(u - r, hi)), and F - hi = (F - c) - rshift_rnd(a u, 24) is
 * non-increasing in r along a column (F - c is a play operator's output
 * with the lower threshold r + c, non-decreasing in r), so the scan stops
 * at the first F < hi. An unchanged
 * input changes nothing (the update is idempotent). The first sample after
 * init or reset updates every operator. Worst case (every operator moves):
 * linear in the operator count.
 *
 * Classical banks keep the run of the last sample: the operators that moved
 * then, 0..run_n-1, hold u_prev - r_i (rising) or u_prev + r_i (falling). A
 * sample that goes on in the same direction moves each of them by exactly
 * d = u - u_prev (u - r_i > u_prev - r_i = F_i rising, the mirror falling),
 * so their part of the sum is d * run_w (run_w = sum of their weights, kept
 * in int64: |run_w| < 2^8 * 2^31 = 2^39 and |d| <= 2^21, so
 * |d * run_w| < 2^60; the new sum is the exact one, within the bound below) and they are only stored; the scan goes on
 * from operator run_n. A reversal starts the run anew from operator 0.
 * Unparallel banks keep the rising runs the same way, one per column (the
 * operators 0..m_j-1 that moved hold u_prev - r_i; 4 (n_r - m_j) in the work array
 * after the constants, run_w the sum over all columns); a falling sample
 * ends them (run_dir = -1).
 *
 * Initial state: every operator output is 0 after init and reset (relaxed,
 * demagnetized actuator at u = 0).
 *
 * Scaling and overflow: for |u| <= 2^20 and 0 <= r <= 2^20 (q15-scaled), an
 * operator output satisfies u - r <= F <= max over past samples of (u - r),
 * so |F| <= 2^21. The upper branch |a * (u + r)| < 2^31 * 2^21 = 2^52 before
 * the shift and < 2^28 after it (fits int32). Each weighted term is
 * |w * F| < 2^31 * 2^21 = 2^52, and at most PIEZO_PLAY_MAX_OPS = 256 = 2^8
 * terms give |sum| < 2^60: the int64 accumulator has 3 guard bits left.
 * Inputs in [-1, 1) with thresholds in [0, 1) (the EUPI model) keep
 * |F| <= 2^16 and |sum| < 2^55.
 */
#ifndef PIEZO_PLAY_H
#define PIEZO_PLAY_H

#include <stddef.h>
#include <stdint.h>

#include "piezo_err.h"

#define PIEZO_PLAY_MAX_OPS 256u                       /* operators per bank */
#define PIEZO_PLAY_WIDE_MAX_Q15 ((int32_t)1 << 20)    /* 32.0 FS: |u| and r bound */

/* Operators in a bank of n_r thresholds and n_a slopes (n_a = 0: classical). */
#define PIEZO_PLAY_N_OPS(n_r, n_a) ((size_t)(n_r) * ((n_a) ? (size_t)(n_a) : 1u))

/* Coefficients: constant, may be shared by several instances. */
struct piezo_play_coef {
    const int32_t *r_q15;  /* [n_r] thresholds, 0 <= r <= WIDE_MAX, non-decreasing */
    const int32_t *a_q24;  /* [n_a] upper-branch slopes, > 0; unused if n_a == 0 */
    const int32_t *w_q24;  /* [PIEZO_PLAY_N_OPS(n_r, n_a)] weights, row-major (i, j) */
    uint16_t n_r;          /* thresholds */
    uint16_t n_a;          /* slopes; 0 = classical play operators (a = 1) */
};

/* Instance: caller-owned; the arrays are the caller's too. */
/* int64 entries of an unparallel bank's work array (piezo_play_init): one
 * per operator (its constant c_ij and a copy of its weight), then the
 * columns' rest counts (uint16 each) of the rising runs; 0 for a bank
 * without operators or slopes. */
#define PIEZO_PLAY_WORK_LEN(n_r, n_a)                                                              \
    ((size_t)(n_r) * (size_t)(n_a) == 0u ? (size_t)0                                               \
                                         : (size_t)(n_r) * (size_t)(n_a) + ((size_t)(n_a) + 3u) / 4u)

struct piezo_play {
    const struct piezo_play_coef *coef;
    int32_t *f_q15;        /* [n_ops] operator outputs (state); UPI banks store
                            * them column by column: read them with
                            * piezo_play_output() */
    int64_t *c2_q15;       /* the caller's work array (UPI banks only): the
                            * constants c_ij = rshift_rnd(a_j r_i, 24), q15
                            * in int32, two per int64 word (an int32 array
                            * laid in it), column by column: constant
                            * j * n_r + i */
    size_t n_ops;
    int64_t acc_q39;       /* sum_k w_k F_k of the current outputs */
    int32_t u_prev_q15;    /* input of the last sample */
    uint8_t primed;        /* 0 after reset: the next sample updates every operator */
    int8_t run_dir;        /* +1 the last sample rose, -1 fell, 0 none (reset) */
    uint16_t run_n;        /* classical banks: operators 0..run_n-1 hold u_prev -+ r_i */
    int64_t run_w_q24;     /* classical banks: sum of w_i over those run_n operators;
                            * unparallel banks after a rise: sum of w_ij over every
                            * column's rising run (play.c, upi_rise) */
};

/*
 * Check the coefficients, bind the caller's arrays and reset.
 * f_q15 needs f_len >= PIEZO_PLAY_N_OPS(n_r, n_a) entries; work (int64) needs
 * PIEZO_PLAY_WORK_LEN(n_r, n_a) for an unparallel bank and may be NULL (work_len
 * 0) for a classical one. The weights are copied into work: init again after
 * changing coef's.
 * Returns PIEZO_OK, PIEZO_EINVAL (NULL pointer, r < 0 or r > WIDE_MAX,
 * a <= 0), PIEZO_EORDER (thresholds decreasing) or PIEZO_ERANGE (more than
 * PIEZO_PLAY_MAX_OPS operators, or an array too short).
 */
int piezo_play_init(struct piezo_play *p, const struct piezo_play_coef *coef,
                    int32_t *f_q15, size_t f_len, int64_t *work, size_t work_len);

/* Every operator output back to 0. */
void piezo_play_reset(struct piezo_play *p);

/*
 * One sample: update every operator with u_q15 (|u_q15| <= WIDE_MAX) and
 * return sum_k w_q24[k] * F_k in Q39. The outputs stay readable through
 * piezo_play_output().
 */
int64_t piezo_play_process(struct piezo_play *p, int32_t u_q15);

/*
 * The same sample for a bank whose kind the caller knows (the EUPI model and
 * its inverse: init checked it), without the dispatch: _cpi for a classical
 * bank (n_a == 0), _upi for an unparallel one (n_a >= 1) or an empty one
 * (n_r == 0).
 */
int64_t piezo_play_process_cpi(struct piezo_play *p, int32_t u_q15);
int64_t piezo_play_process_upi(struct piezo_play *p, int32_t u_q15);
/* The classical bank with the C step only: on the Cortex-M4 the reference of
 * the Thumb-2 step (test_play compares the two); elsewhere the same as
 * piezo_play_process_cpi. */
int64_t piezo_play_process_cpi_c(struct piezo_play *p, int32_t u_q15);
/* The unparallel bank with the C steps only: on the Cortex-M4 the reference
 * of the Thumb-2 upi_fall_m4 and rise_m4 (test_play compares them); elsewhere
 * the same as piezo_play_process_upi. */
int64_t piezo_play_process_upi_c(struct piezo_play *p, int32_t u_q15);

/* Output F_k of operator k = i * n_a + j (row-major, as the weights). */
static inline int32_t piezo_play_output(const struct piezo_play *p, size_t k)
{
    const size_t n_a = p->coef->n_a;
    return n_a == 0u ? p->f_q15[k] : p->f_q15[(k % n_a) * p->coef->n_r + k / n_a];
}

#endif /* PIEZO_PLAY_H */
