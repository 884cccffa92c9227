/*
 * kp.h - Krasnosel'skii-Pokrovskii (KP) operators and the KP hysteresis model.
 *
 * Model (docs/kernels-kp.md; float reference host/piezoctl/models/kp.py,
 * bit-exact golden model host/piezoctl/golden/kp.py):
 *
 *   y[k] = sum_j psi_j[k] * w_j
 *
 * One operator per cell of the discretized Preisach plane, thresholds
 * n1_j <= n2_j, ridge r(x) = 0 (x <= 0), rmax * x / s (0 < x < s), rmax (x >= s):
 *
 *   u[k] > u[k-1]:  psi_j[k] = max(psi_j[k-1], r(u[k] - n2_j))
 *   u[k] < u[k-1]:  psi_j[k] = min(psi_j[k-1], r(u[k] - n1_j))
 *   otherwise:      psi_j[k] = psi_j[k-1]
 *
 * Cell convention (the host builds the thresholds): levels
 * n_i = nmin + (nmax - nmin)(i - 1)/L, i = 1..L+1; cell (i, j), i <= j, uses
 * the midpoints n1 = nmin + (i - 1/2) h, n2 = nmin + (j - 1/2) h, h = (nmax - nmin)/L,
 * numbered row by row. The kernel itself accepts any thresholds with n1 <= n2.
 *
 * Formats:
 *   u_q15, n1_q15, n2_q15, psi_q15, y_q15   q15 (int16), full scale [-1, 1).
 *   rmax_q15     ridge height (nmax), 1..32767; a plane up to nmax = 1.0 stores
 *                32767 (the q15 top, 1 - 2^-15).
 *   slope_q16    ridge slope rmax / s in q16 (the host computes it: no division
 *                on the target), 1..INT32_MAX.
 *   xsat_q15     where the ridge saturates: the smallest x >= 1 with
 *                rshift_rnd(x * slope_q16, 16) >= rmax_q15 (host computes it,
 *                init verifies it).
 *   w_q24        density, q24 (int32, Q7.24), any value.
 *
 * Ridge in integers, for x = u - n (int32, |x| <= 65535):
 *   r(x) = 0 for x <= 0; rmax for x >= xsat; else rshift_rnd(x * slope, 16),
 * i.e. min(rmax, rshift_rnd(max(x, 0) * slope, 16)); non-decreasing in x.
 * Below xsat the product x * slope < rmax * 2^16 < 2^31 fits int32.
 *
 * Rounding: one rule, piezo_rshift_rnd (round half up), in the ridge and in the
 * output shift. Saturation: only y is clamped to q15 (piezo_sat_q15); operator
 * outputs stay in [0, rmax] by construction.
 *
 * State on reset: psi_j = 0 for all j and u_prev = nmin_q15 (the input has
 * rested at the bottom of the plane, where every operator is 0). The first
 * sample above nmin is a rising step from nmin.
 *
 * Scaling and overflow: psi_j in [0, 32767] < 2^15, |w_j| <= 2^31, so each
 * product is below 2^46 in magnitude; with n_ops <= PIEZO_KP_MAX_OPS = 2^12
 * the int64 accumulator (Q24.39 in value) stays below 2^58: it cannot
 * overflow for any input and any coefficient. y = sat_q15(rshift_rnd(acc, 24)).
 */
#ifndef PIEZO_KP_H
#define PIEZO_KP_H

#include <stddef.h>
#include <stdint.h>

#include "piezo_err.h"

/* Largest number of operators (L = 90 gives 4095); bounds the accumulators. */
#define PIEZO_KP_MAX_OPS 4096u

/* The discretized plane shared by the KP, RKP and DCC kernels. */
struct piezo_kp_grid {
    const int16_t *n1_q15;  /* falling thresholds, n_ops entries */
    const int16_t *n2_q15;  /* rising thresholds, n_ops entries, n1 <= n2 */
    uint16_t n_ops;         /* number of operators, 1..PIEZO_KP_MAX_OPS */
    int16_t nmin_q15;       /* bottom of the plane: the input after reset */
    int16_t rmax_q15;       /* ridge height, 1..32767 */
    int32_t slope_q16;      /* ridge slope rmax / s, >= 1 */
    int32_t xsat_q15;       /* smallest x >= 1 with rshift_rnd(x*slope, 16) >= rmax */
};

struct piezo_kp_coeffs {
    struct piezo_kp_grid grid;
    const int32_t *w_q24;   /* density, n_ops entries */
};

/* Caller-owned instance; the coefficients may be shared, the state may not. */
struct piezo_kp {
    const struct piezo_kp_coeffs *coeffs;
    int16_t *psi_q15;       /* caller's state array, n_ops entries */
    int64_t acc;            /* sum_j psi_j * w_j of the current state */
    int16_t u_prev_q15;     /* previous input */
};

/** The ridge with its constants passed in (loops keep them in registers). */
static inline int32_t piezo_kp_ridge_k(int32_t x, int32_t slope_q16, int32_t xsat_q15,
                                       int32_t rmax_q15)
{
    if (x <= 0) {
        return 0;
    }
    if (x >= xsat_q15) {
        return rmax_q15;
    }
    return (x * slope_q16 + 32768) >> 16; /* rshift_rnd(x*slope, 16); < 2^31 */
}

/** The ridge r(x) of a grid, x = input - threshold (|x| <= 65535). */
static inline int32_t piezo_kp_ridge_q15(const struct piezo_kp_grid *g, int32_t x)
{
    return piezo_kp_ridge_k(x, g->slope_q16, g->xsat_q15, g->rmax_q15);
}

/**
 * Check a grid: non-NULL thresholds, 1 <= n_ops <= PIEZO_KP_MAX_OPS (else
 * PIEZO_ERANGE), n1 <= n2 for every operator (else PIEZO_EORDER), rmax >= 1,
 * slope >= 1 and xsat exactly as defined above (else PIEZO_EINVAL).
 */
enum piezo_err piezo_kp_grid_check(const struct piezo_kp_grid *g);

/**
 * Bind an instance to coefficients and a state array of n_state entries
 * (n_state >= n_ops, else PIEZO_ERANGE), check the coefficients and reset.
 * Returns PIEZO_OK, or an error and leaves the instance unusable.
 */
enum piezo_err piezo_kp_init(struct piezo_kp *kp, const struct piezo_kp_coeffs *coeffs,
                             int16_t *psi_q15, size_t n_state);

/** Reset state: psi = 0, u_prev = nmin. */
void piezo_kp_reset(struct piezo_kp *kp);

/**
 * One sample: advance the operators with u and return y (q15, saturated).
 * The same integers as the equations on every operator; the work is spent
 * only where an operator can move (docs/kernels-kp.md, "Work per tick"):
 * rising, operators with u > n2 below rmax; falling, operators with
 * u - n1 < xsat above 0. The sum is kept in the instance and changed by
 * w_j (psi_new - psi_old); an unchanged input returns it at once.
 */
int16_t piezo_kp_process(struct piezo_kp *kp, int16_t u_q15);

/**
 * Building block shared with the RKP kernel: advance the operators psi of grid
 * g from input u_prev to u and return sum_j psi_j * w_j (int64, value scaled
 * by 2^39). Never overflows (see "Scaling and overflow").
 */
int64_t piezo_kp_step(const struct piezo_kp_grid *g, int16_t *psi_q15, int16_t u_q15,
                      int16_t u_prev_q15, const int32_t *w_q24);

#endif /* PIEZO_KP_H */
