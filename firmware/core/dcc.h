/*
 * dcc.h - KP compensation operators and the direct compensation (DCC) law.
 *
 * Equations (docs/kernels-kp.md; float reference host/piezoctl/models/kp.py
 * kp_compensation_outputs / dcc_law, bit-exact golden model
 * host/piezoctl/golden/dcc.py). Compensation operator j on the grid of kp.h,
 * with xi the input and zo_j the operator's output at the last reversal of
 * the input v, and ro(x) = x - r(x):
 *
 *   v rising:   Psi_j = min(v - xi + zo_j, ro(v - n2_j) + n2_j)
 *   v falling:  Psi_j = max(v - xi + zo_j, ro(v - n1_j) + n1_j)
 *   unchanged:  Psi_j holds
 *
 * A reversal (the direction differs from the last move) first sets
 * xi = v[k-1] and zo_j = Psi_j[k-1]. With the integer ridge of kp.h this
 * gives psi_j + Psi_j == v exactly, in integers, for the KP operators driven
 * by the same input from reset: by induction, min(Psi_j[k-1] + dv, v - r) =
 * v - max(psi_j[k-1], r) (rising, the falling case alike), and the equations
 * above equal min/max(Psi_j[k-1] + dv, v - r(v - n_j)) (docs/kernels-kp.md,
 * "DCC without the reversal copy"). The kernel therefore keeps the KP
 * operators psi_j (state array psi_q15; Psi_j = v_prev - psi_j, read through
 * piezo_dcc_cpsi()) and computes the same integers as the equations;
 * tests/firmware/test_dcc.c checks the identity sample by sample.
 *
 * Work per tick (docs/kernels-kp.md, "DCC: work per tick"): only operators
 * whose thresholds lie in the band where they can move are visited, found
 * from the thresholds in order (n1 as stored when non-decreasing, n2 through
 * the order array built by init), and sum_j Psi_j c_j = v C - sum_j psi_j c_j
 * (C = sum_j c_j) is kept incrementally when the caller declares the weights
 * constant (piezo_dcc_const_weights(), e.g. a kp_dcc table); otherwise (the
 * RKP density changes every tick) the sum is formed in full every tick.
 * With constant weights (sum_j |c_j| < 2^31) on a grid in (n1, n2) order with
 * at most PIEZO_DCC_MAX_ROWS rows (init keeps each row's first index) the
 * moving operators of a row (falling) or column (rising) hold one value and
 * move as one run, (r' - r) * csum (docs/kernels-kp.md, "DCC: runs"); every
 * psi is still written. With the weights' prefix sums (csum_q24, below) a
 * line that starts to move without a run moves its operators of one value
 * (a row's at rmax, or after its first; a column's at 0) as one block, found
 * by galloping and bisection (docs/kernels-kp.md, "DCC: blocks from prefix
 * sums").
 *
 * Control law, one sample per tick (the operators see the previous drive, which
 * avoids an algebraic loop):
 *
 *   u[k] = sat_q15( g * yd[k] + sum_j Psi_j(u[k-1]) * c_j ),   c_j = g * w_j
 *
 * i.e. u = g (yd + Psi . w). The KP model is y = sum psi_j w_j = W u - Psi . w
 * with W = sum_j w_j, so g = 1/W inverts it; the host folds g into the
 * weights (c_j = g w_j) so that the kernel rounds once. yd is in the model's
 * output units (displacement expressed in drive units through the stage's
 * static gain when w was identified that way, then W is close to 1).
 *
 * Formats:
 *   yd_q15, u_q15, v       q15 (int16).
 *   Psi_j                  q15 LSB in int32: Psi_j = v - psi_j is in [v - rmax, v],
 *                          i.e. [-65535, 32767] (piezo_dcc_cpsi()).
 *   psi_q15 (state)        the KP operators psi_j in [0, rmax], int32.
 *   order (work)           init's: the operators by rising threshold n2,
 *                          n2 * 2^16 + j per entry (int32).
 *   c_q24                  g * w_j, q24 (int32), any value.
 *   g_q24                  gain g, q24, >= 1 (positive).
 *
 * Rounding: the ridge as kp.h; the output once, rshift_rnd(acc, 24) (round
 * half up). Saturation: u is clamped to q15 (piezo_sat_q15) and the clamped
 * drive is what the operators see next tick. Nothing else saturates.
 *
 * State on reset: the KP reset state seen from the compensation side: a
 * falling input that rested at nmin, v_prev = xi = u_last = nmin,
 * Psi_j = zo_j = nmin (psi_j = 0).
 *
 * Scaling and overflow: |Psi_j| <= 65535 < 2^16 and |c_j| <= 2^31, so each
 * product is below 2^47; n_ops <= 2^12 operators sum below 2^59, plus
 * |yd * g| < 2^46: the int64 accumulator (value scaled by 2^39) cannot overflow.
 * Incremental form: |C| <= 2^43 and |v| <= 2^15, so |v C| <= 2^58;
 * |sum psi_j c_j| < 2^15 * 2^31 * 2^12 = 2^58; their difference is the sum
 * above (exact in int64). The candidates v - r stay within +-2^17 in int32.
 * Runs: they are used only when sum_j |c_j| < 2^31 (piezo_dcc_const_weights
 * checks it; any real table, whose weights sum to about 1.0 = 2^24, passes;
 * otherwise the band scan below does the same work operator by operator), so
 * a run's csum, a partial sum of the weights, fits int32, and
 * |(r' - r) * csum| < 2^16 * 2^31 = 2^47; the tick's change of the kept sum
 * is the exact difference of two sums below 2^58 (int64).
 */
#ifndef PIEZO_DCC_H
#define PIEZO_DCC_H

#include <stddef.h>
#include <stdint.h>

#include "kp.h"
#include "piezo_err.h"

struct piezo_dcc_coeffs {
    struct piezo_kp_grid grid;
    const int32_t *c_q24;  /* g * w_j, n_ops entries */
    int32_t g_q24;         /* gain g = 1 / sum(w), >= 1 */
    /* Optional (NULL: none): the prefix sums of c_q24, from
     * piezo_dcc_prefix_sums(): 2 (n_ops + 1) entries, sum_{i<j} c_i in index
     * order, then the same in the n2 order (init's order array). */
    const int32_t *csum_q24;
};

/* Runs kept per direction: rows (falling) or columns (rising) of the band
 * whose moving operators are tracked as one (docs/kernels-kp.md). */
#define PIEZO_DCC_RUNS 4u

/* Rows (distinct n1) of a grid in (n1, n2) order that the runs handle; a
 * grid with more rows (a plane finer than L = 32) takes the band scan. */
#define PIEZO_DCC_MAX_ROWS 32u

/* A run: the operators of one row (falling, index order) or one column
 * (rising, order-array positions) that moved in the current monotone run of
 * the input. All of them hold the same value lvl = r(v_prev - thr): falling
 * the first k of the row, rising the last k of the column. */
struct piezo_dcc_run {
    int32_t csum;      /* sum of c_j over the k operators (|.| <= sum |c_j| < 2^31) */
    int32_t lvl;       /* their common psi */
    int16_t thr;       /* the row's n1 / the column's n2 */
    uint16_t k;        /* operators in the run (the line's own bounds come from row_start /
                        * col_start: round 14 dropped the run's copies, which nothing read) */
    uint32_t spare;    /* never written or read: 16 bytes a run, indexed by a shift */
};

/* Caller-owned instance; the coefficients may be shared, the state may not. */
struct piezo_dcc {
    const struct piezo_dcc_coeffs *coeffs;
    int32_t *psi_q15;    /* caller's state: the KP operators psi_j = v_prev - Psi_j */
    int32_t *order;      /* caller's work array: n2_j * 2^16 + j by rising n2 (init) */
    int64_t csum;        /* C = sum_j c_j (constant weights only) */
    int64_t kacc;        /* sum_j psi_j c_j (constant weights only) */
    int16_t xi_q15;      /* operator input at the last reversal */
    int16_t v_prev_q15;  /* previous operator input */
    int16_t u_last_q15;  /* previous law output: the operators' next input */
    int8_t dir;          /* last move: +1 rising, -1 falling */
    uint8_t const_w;     /* 1: c_q24 constant, sums kept incrementally */
    uint8_t n1_sorted;   /* n1 non-decreasing: the falling band is an index range */
    uint8_t n2_banded;   /* every n2 > nmin - xsat: the rising band may skip saturated ones */
    uint8_t lex_sorted;  /* (n1, n2) non-decreasing in index order: rows are index ranges
                          * with n2 ascending, the runs apply (with const_w) */
    uint8_t n_run;       /* runs of the current direction, in run[cur] by ascending thr */
    uint8_t cur;         /* which of the two run buffers is current */
    uint8_t c_abs_31;    /* sum_j |c_j| < 2^31: the runs' weight sums fit int32 */
    uint8_t n_rows;      /* lex_sorted with at most PIEZO_DCC_MAX_ROWS rows: their count; else 0 */
    uint8_t row_cur;     /* the falling band's first row at the last falling tick (a hint) */
    uint8_t n_cols;      /* columns (equal n2) in the order array, at most PIEZO_DCC_MAX_ROWS; else 0 */
    uint8_t col_cur;     /* the rising band's first column at the last rising tick (a hint) */
    uint8_t runs;        /* const_w, c_abs_31, n_rows and n_cols all non-zero: the runs apply
                          * (the Cortex-M4's falling step tests this one byte) */
    const int32_t *psum; /* coeffs->csum_q24 when checked by piezo_dcc_const_weights (else NULL):
                          * a row's (column's) operators at rmax (at 0) join in one step */
    uint16_t row_start[PIEZO_DCC_MAX_ROWS + 1u]; /* first index of each row, then n_ops */
    uint16_t col_start[PIEZO_DCC_MAX_ROWS + 1u]; /* first order position of each column, then n_ops */
    struct piezo_dcc_run run[2][PIEZO_DCC_RUNS];
};

/**
 * Bind an instance to coefficients, a state array and a work array of
 * n_state entries each (n_state >= n_ops, else PIEZO_ERANGE), check the
 * coefficients, order the operators by n2 into the work array and reset.
 * The weights are taken as changing every tick until
 * piezo_dcc_const_weights() says otherwise.
 * Errors: PIEZO_EINVAL (NULL pointer, g_q24 < 1) and the grid's errors.
 */
enum piezo_err piezo_dcc_init(struct piezo_dcc *dcc, const struct piezo_dcc_coeffs *coeffs,
                              int32_t *psi_q15, int32_t *order, size_t n_state);

/**
 * Declare the weights c_q24 constant from now on (until the next init): the
 * kernel then keeps sum_j psi_j c_j and C = sum_j c_j and updates them only
 * for the operators that move. Call it for tables whose weights never change
 * (kp_dcc); not when c_q24 is a density rewritten every tick (RKP).
 */
void piezo_dcc_const_weights(struct piezo_dcc *dcc);
/* (It also checks the coefficients' csum_q24, if any, against c_q24 and the
 * order, and uses them only if every entry matches.) */

/**
 * Fill sums (n_sums >= 2 (n_ops + 1) entries, else PIEZO_ERANGE) with the
 * prefix sums of the weights of an initialized instance, for its
 * coefficients' csum_q24: sums[j] = sum_{i<j} c_i (index order), then
 * sums[n_ops + 1 + k] = sum of c over the order array's first k entries.
 * PIEZO_EINVAL when sum_j |c_j| >= 2^31 (they would not fit int32).
 */
enum piezo_err piezo_dcc_prefix_sums(const struct piezo_dcc *dcc, int32_t *sums, size_t n_sums);

/** Reset state (see above). */
void piezo_dcc_reset(struct piezo_dcc *dcc);

/** Psi_j of the last operator update (v_prev - psi_j), j < n_ops. */
static inline int32_t piezo_dcc_cpsi(const struct piezo_dcc *dcc, uint16_t j)
{
    return (int32_t)dcc->v_prev_q15 - dcc->psi_q15[j];
}

/** Advance the compensation operators with input v (the law does this itself). */
void piezo_dcc_ops_update(struct piezo_dcc *dcc, int16_t v_q15);

/** The same with the C kernels only: on the Cortex-M4 the reference of the
 * Thumb-2 falling rows (test_dcc compares the two); elsewhere the same as
 * piezo_dcc_ops_update. */
void piezo_dcc_ops_update_c(struct piezo_dcc *dcc, int16_t v_q15);

/** One tick of the law: operators with u[k-1], then u[k] (q15, saturated). */
int16_t piezo_dcc_process(struct piezo_dcc *dcc, int16_t yd_q15);

#endif /* PIEZO_DCC_H */
