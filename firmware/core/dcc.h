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
 * xi = v[k-1] and zo_j = Psi_j[k-1]. The kernel computes the same integers
 * as min/max(Psi_j[k-1] + v - v[k-1], v - r(v - n_j)), which needs no copy at
 * a reversal (docs/kernels-kp.md, "DCC without the reversal copy"): it keeps
 * xi and dir, and leaves zo_q15 at its reset value.
 * With the integer ridge of kp.h this gives
 * psi_j + Psi_j == v exactly, in integers, for the KP operators driven by the
 * same input from reset (tests/firmware/test_dcc.c proves it sample by sample).
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
 *   cpsi_q15, zo_q15       Psi_j and (equations) its value at the last reversal, q15 LSB
 *                          in int32: Psi_j = v - psi_j is in [v - rmax, v],
 *                          i.e. [-65535, 32767].
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
 * v - xi + zo_j and the candidates stay within +-2^17 in int32.
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
};

/* Caller-owned instance; the coefficients may be shared, the state may not. */
struct piezo_dcc {
    const struct piezo_dcc_coeffs *coeffs;
    int32_t *cpsi_q15;   /* caller's state: Psi_j, n_ops entries */
    int32_t *zo_q15;     /* caller's array, n_ops entries: nmin (reset); unused by the kernel */
    int16_t xi_q15;      /* operator input at the last reversal */
    int16_t v_prev_q15;  /* previous operator input */
    int16_t u_last_q15;  /* previous law output: the operators' next input */
    int8_t dir;          /* last move: +1 rising, -1 falling */
};

/**
 * Bind an instance to coefficients and two state arrays of n_state entries
 * (n_state >= n_ops, else PIEZO_ERANGE), check the coefficients and reset.
 * Errors: PIEZO_EINVAL (NULL pointer, g_q24 < 1) and the grid's errors.
 */
enum piezo_err piezo_dcc_init(struct piezo_dcc *dcc, const struct piezo_dcc_coeffs *coeffs,
                              int32_t *cpsi_q15, int32_t *zo_q15, size_t n_state);

/** Reset state (see above). */
void piezo_dcc_reset(struct piezo_dcc *dcc);

/** Advance the compensation operators with input v (the law does this itself). */
void piezo_dcc_ops_update(struct piezo_dcc *dcc, int16_t v_q15);

/** One tick of the law: operators with u[k-1], then u[k] (q15, saturated). */
int16_t piezo_dcc_process(struct piezo_dcc *dcc, int16_t yd_q15);

#endif /* PIEZO_DCC_H */
