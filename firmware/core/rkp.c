/* rkp.c - rate-dependent KP model; see rkp.h and docs/kernels-kp.md. */
#include "rkp.h"

#include "fixed_q.h"
#include "piezo_interface.h"

/* The LUT spans [0, zmax] in 256 steps of 2^-6, i.e. 2^10 in q16. */
#define GAUSS_STEP_SHIFT 10u
typedef char piezo_rkp_lut_step_check_t[
    ((((int64_t)PIEZO_GAUSS_LUT_N - 1) << GAUSS_STEP_SHIFT) == PIEZO_GAUSS_ZMAX_Q16) ? 1 : -1];

int16_t piezo_rkp_gauss_q15(int32_t z_q16)
{
    if (z_q16 >= PIEZO_GAUSS_ZMAX_Q16) {
        return 0;
    }
    const uint32_t i = (uint32_t)z_q16 >> GAUSS_STEP_SHIFT;
    const int32_t f = z_q16 & ((1 << GAUSS_STEP_SHIFT) - 1);
    const int32_t a = piezo_gauss_lut_q15[i];
    const int32_t b = piezo_gauss_lut_q15[i + 1u];
    return (int16_t)(a + piezo_rshift_rnd32((b - a) * f, GAUSS_STEP_SHIFT));
}

enum piezo_err piezo_rkp_init(struct piezo_rkp *rkp, const struct piezo_rkp_coeffs *coeffs,
                              int16_t *psi_q15, int32_t *w_q24, size_t n_state)
{
    if (rkp == NULL || coeffs == NULL || psi_q15 == NULL || w_q24 == NULL ||
        coeffs->theta_q24 == NULL || coeffs->center_q24 == NULL ||
        coeffs->inv_width_q16 == NULL) {
        return PIEZO_EINVAL;
    }
    rkp->coeffs = NULL;
    const enum piezo_err err = piezo_kp_grid_check(&coeffs->grid);
    if (err != PIEZO_OK) {
        return err;
    }
    const uint16_t n = coeffs->grid.n_ops;
    if (n_state < n || coeffs->n_rbf == 0u || coeffs->n_rbf > PIEZO_RKP_MAX_RBF) {
        return PIEZO_ERANGE;
    }
    if (coeffs->alpha_q16 < 1 || coeffs->alpha_q16 > PIEZO_Q16_ONE) {
        return PIEZO_EINVAL;
    }
    for (uint16_t m = 0; m < coeffs->n_rbf; m++) {
        const int32_t c = coeffs->center_q24[m];
        if (c > PIEZO_RKP_MAX_CENTER_Q24 || c < -PIEZO_RKP_MAX_CENTER_Q24 ||
            coeffs->inv_width_q16[m] < 1) {
            return PIEZO_EINVAL;
        }
    }
    for (uint16_t j = 0; j < n; j++) {
        int64_t sum = 0;
        for (uint16_t m = 0; m < coeffs->n_rbf; m++) {
            const int64_t t = coeffs->theta_q24[(size_t)m * n + j];
            sum += t < 0 ? -t : t;
        }
        if (sum > INT32_MAX) {
            return PIEZO_EINVAL;
        }
    }
    rkp->coeffs = coeffs;
    rkp->psi_q15 = psi_q15;
    rkp->w_q24 = w_q24;
    piezo_rkp_reset(rkp);
    return PIEZO_OK;
}

void piezo_rkp_reset(struct piezo_rkp *rkp)
{
    const struct piezo_kp_grid *g = &rkp->coeffs->grid;
    for (uint16_t j = 0; j < g->n_ops; j++) {
        rkp->psi_q15[j] = 0;
        rkp->w_q24[j] = 0;
    }
    rkp->rate_q24 = 0;
    rkp->u_prev_q15 = g->nmin_q15;
}

int16_t piezo_rkp_process(struct piezo_rkp *rkp, int16_t u_q15)
{
    const struct piezo_rkp_coeffs *c = rkp->coeffs;
    const uint16_t n = c->grid.n_ops;

    /* 1. rate: low-pass of the per-sample difference, in q24 */
    const int32_t d_q24 = ((int32_t)u_q15 - rkp->u_prev_q15) * (1 << 9);
    rkp->rate_q24 += (int32_t)piezo_rshift_rnd64(
        (int64_t)(d_q24 - rkp->rate_q24) * c->alpha_q16, 16u);

    /* 2. features: keep only the non-zero ones */
    int32_t f_act[PIEZO_RKP_MAX_RBF];
    const int32_t *t_act[PIEZO_RKP_MAX_RBF];
    unsigned n_act = 0;
    for (uint16_t m = 0; m < c->n_rbf; m++) {
        int64_t dz = (int64_t)rkp->rate_q24 - c->center_q24[m];
        if (dz < 0) {
            dz = -dz;
        }
        const int64_t z = piezo_rshift_rnd64(dz * c->inv_width_q16[m], 24u);
        if (z < PIEZO_GAUSS_ZMAX_Q16) {
            const int16_t f = piezo_rkp_gauss_q15((int32_t)z);
            if (f != 0) {
                f_act[n_act] = f;
                t_act[n_act] = &c->theta_q24[(size_t)m * n];
                n_act++;
            }
        }
    }

    /* 3. density w_j = sum_m Theta_jm F_m, q39 -> q24 */
    int32_t *w = rkp->w_q24;
    for (uint16_t j = 0; j < n; j++) {
        int64_t acc = 0;
        for (unsigned a = 0; a < n_act; a++) {
            acc += (int64_t)t_act[a][j] * f_act[a];
        }
        w[j] = (int32_t)piezo_rshift_rnd64(acc, 15u);
    }

    /* 4. operators and output */
    const int64_t acc = piezo_kp_step(&c->grid, rkp->psi_q15, u_q15, rkp->u_prev_q15, w);
    rkp->u_prev_q15 = u_q15;
    return piezo_sat_q15_rnd24(acc);
}
