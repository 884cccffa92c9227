/*
 * eupi_inv.h - inverse compensator of the EUPI model (eupi.h), one sample per
 * call:
 *
 *     v(k) = y_r(k) - G2(k-1)
 *     u(k) = sat_q15( G1^{-1}[v](k) )
 *     G2(k) = G_UPI[u](k) + P(u(k)) - k_ex * u(k)
 *
 * where G1 = G_CPI + k_ex * u is a classical PI model and its inverse is again
 * one, computed on the host (host/piezoctl/models/eupi.py,
 * cpi_inverse_params()):
 *
 *     G1^{-1}[v] = a0' * v + sum_i b'_i * F_{r'_i,1}[v]
 *     A_0 = a0 + k_ex,  A_i = A_0 + sum_{j<=i} b_j
 *     a0' = 1 / A_0,  b'_i = 1 / A_i - 1 / A_{i-1} (<= 0),
 *     r'_i = A_0 r_i + sum_{j<i} b_j (r_i - r_j).
 *
 * The host accepts a table only if the small-gain condition
 * a0 + k_ex > max |d(G_UPI + P - k_ex u)/du| holds over the drive range (the
 * compensator is then a contraction); the firmware does not re-check it.
 *
 * Formats and ranges (checked by init):
 *   yr_q15, u_q15    int16_t q15.
 *   a0_inv_q24       Q7.24, > 0.
 *   cpi_inv          classical bank (n_a == 0): r_q15 = r'_i in
 *                    [0, PIEZO_PLAY_WIDE_MAX_Q15] (q15-scaled int32, may exceed
 *                    1.0), non-decreasing; w_q24 = b'_i of any sign.
 *   upi, p_q24, n_p, p0_q24
 *                    as in eupi.h (thresholds < 1, d_ij >= 0, sum |p_m| < 64;
 *                    the G2 bound below keeps it <= 16).
 *   kex_q24          Q7.24, any sign.
 *   Bound on G2:     2 * sum d_ij + sum |p_m| + |p0| + |k_ex| <= 16
 *                    (PIEZO_EUPI_INV_G2_MAX_Q24).
 *
 * Rounding: v = piezo_rshift_rnd64((y_r << 24) - G2_q39, 24) (q15-scaled
 * int32); u = piezo_rshift_rnd64(a0' v + sum b'_i F'_i, 24); G2 is kept in
 * Q39 unrounded between samples. Play operators and P as in play.h / eupi.h.
 *
 * Saturation: u is clamped to q15 by piezo_sat_q15() (the golden model does
 * the same). The clamped u is what enters G_UPI and P, i.e. what the stage
 * receives; the inverse CPI operators keep their state for the unclamped
 * v. While y_r asks for more than the stage can give, the operators of G1^{-1}
 * move beyond the drive range, and the memory they keep differs from the
 * stage's until the next reversal that wipes it out.
 *
 * Initial state: all operators 0, G2(-1) = P(0) = p0 (u(-1) = 0); init and
 * reset.
 *
 * Scaling and overflow: |G2| <= 16 FS by the checked bound (|F_UPI| <= 2), so
 * |v| <= 17 FS < 2^20 q15 units, inside the play bank's wide range; then the
 * inverse operators have |F'| <= 2^21, each product |b' F'| < 2^52 and
 * |a0' v| < 2^51, and 256 operators stay below 2^60 in the int64 Q39
 * accumulator. G2 is below 2^44 in Q39 (16 FS), the UPI/P sums as in eupi.h.
 */
#ifndef PIEZO_EUPI_INV_H
#define PIEZO_EUPI_INV_H

#include <stddef.h>
#include <stdint.h>

#include "eupi.h"
#include "piezo_err.h"
#include "play.h"

#define PIEZO_EUPI_INV_G2_MAX_Q24 ((int64_t)16 << 24)  /* bound on |G2|: 16 FS */

/* Entries of the caller's state (int32) and work (int64) arrays. */
#define PIEZO_EUPI_INV_STATE_LEN(n_cpi, n_upi_r, n_upi_a) \
    PIEZO_EUPI_STATE_LEN(n_cpi, n_upi_r, n_upi_a)
#define PIEZO_EUPI_INV_WORK_LEN(n_upi_r, n_upi_a) PIEZO_EUPI_WORK_LEN(n_upi_r, n_upi_a)

/* Coefficients: constant, may be shared. */
struct piezo_eupi_inv_coef {
    struct piezo_play_coef cpi_inv;  /* b'_i on r'_i, classical, wide thresholds */
    struct piezo_play_coef upi;      /* d_ij on (rU_i, a_j), as in the model */
    const int32_t *p_q24;            /* [n_p] coefficients of u^2 .. u^(n_p+1) */
    int32_t a0_inv_q24;              /* 1 / (a0 + k_ex), > 0 */
    int32_t kex_q24;                 /* k_ex */
    int32_t p0_q24;
    uint16_t n_p;
};

struct piezo_eupi_inv {
    const struct piezo_eupi_inv_coef *coef;
    struct piezo_play cpi_inv;
    struct piezo_play upi;
    int64_t g2_q39;                  /* G2 at the previous sample */
};

/*
 * Check the coefficients, bind the caller's arrays and reset. Array sizes as
 * PIEZO_EUPI_INV_STATE_LEN(cpi_inv.n_r, upi.n_r, upi.n_a) and
 * PIEZO_EUPI_INV_WORK_LEN(upi.n_r, upi.n_a). Returns PIEZO_OK, PIEZO_EINVAL,
 * PIEZO_EORDER or PIEZO_ERANGE (see play.h and eupi.h, plus: a0' <= 0,
 * the bound on G2 exceeded).
 */
int piezo_eupi_inv_init(struct piezo_eupi_inv *c, const struct piezo_eupi_inv_coef *coef,
                        int32_t *state_q15, size_t state_len,
                        int64_t *work_q39, size_t work_len);

void piezo_eupi_inv_reset(struct piezo_eupi_inv *c);

/* One sample: the drive u_q15 for the desired displacement yr_q15. */
int16_t piezo_eupi_inv_process(struct piezo_eupi_inv *c, int16_t yr_q15);

#endif /* PIEZO_EUPI_INV_H */
