/*
 * play.h - a bank of classical (CPI) or unparallel (UPI) play operators with
 * their weighted sum, one sample per call.
 *
 * Operator (threshold r >= 0, upper-branch slope a > 0; a = 1 is the
 * classical play operator):
 *
 *     F(k) = max(u(k) - r, min(a * (u(k) + r), F(k-1)))
 *
 * the minimum taken first, exactly as written. A bank is either
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
 * Rounding: the upper branch a * (u + r) is rounded in two separable halves,
 *     hi = piezo_rshift_rnd64(a * u, 24) + c,   c = piezo_rshift_rnd64(a * r, 24),
 * within one LSB of rounding a (u + r) once (docs/fixed-point.md, "Play
 * operators"); the golden model does the same. A classical operator's
 * upper branch u + r is exact (a = 1: A(u) = u, c = r). The lower branch is
 * exact. The weighted sum is exact.
 *
 * Saturation: none; nothing can overflow within the documented ranges.
 *
 * Work per sample: the memory stack (docs/kernels-pi.md, "Play banks by their
 * memory stack"). The results are those of the formula applied to every
 * operator, but the bank keeps, per slope (column, thresholds ascending), its
 * outputs as a stack of segments of consecutive operators, each given by one
 * past input e in closed form: LO(e), F_i = e - r_i; HI(h), F_i = h + c_i
 * with h = A(e); ZERO, F_i = 0 (after reset). This is the wiping-out property:
 * the newest segment holds the smallest thresholds, and a sample replaces the
 * top segments it wipes out (rising: F_i + r_i < u; falling: F_i - c_i > A(u),
 * both monotone in i within a segment) with at most two new ones (rising:
 * LO(u); falling: LO(u) where r_i + c_i <= u - A(u), then HI(A(u))). The
 * column's weighted sum is kept and each segment's share is a closed form on
 * prefix sums of w, w r and w c (computed by init, int64 modulo 2^64: every
 * true sum fits int64, so the modular differences are exact):
 *     LO(e) on [b, e'): e (W[e'] - W[b]) - (WR[e'] - WR[b])
 *     HI(h) on [b, e'): h (W[e'] - W[b]) + (WC[e'] - WC[b]).
 * A sample costs O(1 + segments popped + operators that cross a segment's
 * edge + the move of the LO/HI edge) per column. Worst case, a jump across
 * the whole range after a history with a segment per operator: every segment
 * popped, O(n_r) per column, O(n_ops) in all (measured: tools/bench-target,
 * docs/target-cortex-m4.md "Round 10").
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

/* Columns of a bank: its slopes, or one for a classical bank. */
#define PIEZO_PLAY_N_COLS(n_a) ((n_a) ? (size_t)(n_a) : 1u)

/* Entries of the caller's int32 state (per column: n_r segment values, n_r
 * segment words, n_r keys r_i + c_i, the n_r + 1 prefix sums of w) and
 * int64 work array (per column: three column words, the n_r + 1 prefix
 * sums of w r and, unparallel, of w c). */
#define PIEZO_PLAY_STATE_LEN(n_r, n_a) (PIEZO_PLAY_N_COLS(n_a) * (4u * (size_t)(n_r) + 1u))
#define PIEZO_PLAY_WORK_LEN(n_r, n_a) \
    (PIEZO_PLAY_N_COLS(n_a) * (((n_a) ? 2u : 1u) * ((size_t)(n_r) + 1u) + 3u))

/* Instance: caller-owned; the arrays are the caller's too. */
struct piezo_play {
    const struct piezo_play_coef *coef;
    int32_t *state;        /* per column: segments (stack, bottom first), keys, sums of w */
    int64_t *work;         /* per column: column words, sums of w r and w c */
    size_t n_ops;
    uint32_t stride32;     /* int32 entries per column in state */
    uint32_t stride64;     /* int64 entries per column in work */
    int64_t acc_q39;       /* sum_k w_k F_k of the current outputs */
    int32_t u_prev_q15;    /* input of the last sample */
};

/*
 * Check the coefficients, bind the caller's arrays, compute the prefix sums
 * and reset. state needs PIEZO_PLAY_STATE_LEN(n_r, n_a) entries, work
 * PIEZO_PLAY_WORK_LEN(n_r, n_a).
 * Returns PIEZO_OK, PIEZO_EINVAL (NULL pointer, r < 0 or r > WIDE_MAX,
 * a <= 0), PIEZO_EORDER (thresholds decreasing) or PIEZO_ERANGE (more than
 * PIEZO_PLAY_MAX_OPS operators, or an array too short).
 */
int piezo_play_init(struct piezo_play *p, const struct piezo_play_coef *coef,
                    int32_t *state, size_t state_len, int64_t *work, size_t work_len);

/* Every operator output back to 0. */
void piezo_play_reset(struct piezo_play *p);

/*
 * One sample: update every operator with u_q15 (|u_q15| <= WIDE_MAX) and
 * return sum_k w_q24[k] * F_k in Q39. The outputs stay readable through
 * piezo_play_output().
 */
int64_t piezo_play_process(struct piezo_play *p, int32_t u_q15);

/* Output F_k of operator k = i * n_a + j (row-major, as the weights), from
 * the column's segments (a walk of its stack: for tests and inspection). */
int32_t piezo_play_output(const struct piezo_play *p, size_t k);

#endif /* PIEZO_PLAY_H */
