/* kp.c - KP operators and the KP model; see kp.h and docs/kernels-kp.md. */
#include "kp.h"

#include "fixed_q.h"

enum piezo_err piezo_kp_grid_check(const struct piezo_kp_grid *g)
{
    if (g == NULL || g->n1_q15 == NULL || g->n2_q15 == NULL) {
        return PIEZO_EINVAL;
    }
    if (g->n_ops == 0u || g->n_ops > PIEZO_KP_MAX_OPS) {
        return PIEZO_ERANGE;
    }
    for (uint16_t j = 0; j < g->n_ops; j++) {
        if (g->n1_q15[j] > g->n2_q15[j]) {
            return PIEZO_EORDER;
        }
    }
    if (g->rmax_q15 < 1 || g->slope_q16 < 1 || g->xsat_q15 < 1) {
        return PIEZO_EINVAL;
    }
    /* xsat is the first x >= 1 whose rounded ridge reaches rmax. */
    const int64_t rmax = g->rmax_q15;
    const int64_t at = piezo_rshift_rnd64((int64_t)g->xsat_q15 * g->slope_q16, 16u);
    const int64_t below = piezo_rshift_rnd64((int64_t)(g->xsat_q15 - 1) * g->slope_q16, 16u);
    if (at < rmax || (g->xsat_q15 > 1 && below >= rmax)) {
        return PIEZO_EINVAL;
    }
    return PIEZO_OK;
}

enum piezo_err piezo_kp_init(struct piezo_kp *kp, const struct piezo_kp_coeffs *coeffs,
                             int16_t *psi_q15, size_t n_state)
{
    if (kp == NULL || coeffs == NULL || psi_q15 == NULL || coeffs->w_q24 == NULL) {
        return PIEZO_EINVAL;
    }
    kp->coeffs = NULL;
    const enum piezo_err err = piezo_kp_grid_check(&coeffs->grid);
    if (err != PIEZO_OK) {
        return err;
    }
    if (n_state < coeffs->grid.n_ops) {
        return PIEZO_ERANGE;
    }
    kp->coeffs = coeffs;
    kp->psi_q15 = psi_q15;
    piezo_kp_reset(kp);
    return PIEZO_OK;
}

void piezo_kp_reset(struct piezo_kp *kp)
{
    const struct piezo_kp_grid *g = &kp->coeffs->grid;
    for (uint16_t j = 0; j < g->n_ops; j++) {
        kp->psi_q15[j] = 0;
    }
    kp->u_prev_q15 = g->nmin_q15;
    kp->acc = 0;
}

int64_t piezo_kp_step(const struct piezo_kp_grid *g, int16_t *psi_q15, int16_t u_q15,
                      int16_t u_prev_q15, const int32_t *w_q24)
{
    const uint16_t n = g->n_ops;
    const int32_t u = u_q15;
    const int32_t slope = g->slope_q16, xsat = g->xsat_q15, rmax = g->rmax_q15;
    int64_t acc = 0;
    /* The direction is decided once per tick; each loop is branch-light. */
    if (u_q15 > u_prev_q15) {
        const int16_t *th = g->n2_q15;
        for (uint16_t j = 0; j < n; j++) {
            const int32_t r = piezo_kp_ridge_k(u - th[j], slope, xsat, rmax);
            int32_t p = psi_q15[j];
            if (r > p) {
                p = r;
                psi_q15[j] = (int16_t)p;
            }
            acc += (int64_t)p * w_q24[j];
        }
    } else if (u_q15 < u_prev_q15) {
        const int16_t *th = g->n1_q15;
        for (uint16_t j = 0; j < n; j++) {
            const int32_t r = piezo_kp_ridge_k(u - th[j], slope, xsat, rmax);
            int32_t p = psi_q15[j];
            if (r < p) {
                p = r;
                psi_q15[j] = (int16_t)p;
            }
            acc += (int64_t)p * w_q24[j];
        }
    } else {
        for (uint16_t j = 0; j < n; j++) {
            acc += (int64_t)psi_q15[j] * w_q24[j];
        }
    }
    return acc;
}

int16_t piezo_kp_process(struct piezo_kp *kp, int16_t u_q15)
{
    const struct piezo_kp_coeffs *c = kp->coeffs;
    const struct piezo_kp_grid *g = &c->grid;
    const int32_t *w = c->w_q24;
    int16_t *psi = kp->psi_q15;
    const uint16_t n = g->n_ops;
    const int32_t u = u_q15;
    const int32_t slope = g->slope_q16, xsat = g->xsat_q15, rmax = g->rmax_q15;
    int64_t acc = kp->acc;
    if (u_q15 > kp->u_prev_q15) {
        /* psi = max(psi, r(u - n2)): r = 0 for u <= n2, nothing above rmax */
        const int16_t *th = g->n2_q15;
        for (uint16_t j = 0; j < n; j++) {
            const int32_t x = u - th[j];
            if (x <= 0) {
                continue;
            }
            const int32_t p = psi[j];
            if (p >= rmax) {
                continue;
            }
            const int32_t r = x >= xsat ? rmax : (x * slope + 32768) >> 16;
            if (r > p) {
                psi[j] = (int16_t)r;
                acc += (int64_t)(r - p) * w[j];
            }
        }
    } else if (u_q15 < kp->u_prev_q15) {
        /* psi = min(psi, r(u - n1)): r = rmax for u - n1 >= xsat, nothing below 0 */
        const int16_t *th = g->n1_q15;
        for (uint16_t j = 0; j < n; j++) {
            const int32_t x = u - th[j];
            if (x >= xsat) {
                continue;
            }
            const int32_t p = psi[j];
            if (p == 0) {
                continue;
            }
            const int32_t r = x <= 0 ? 0 : (x * slope + 32768) >> 16;
            if (r < p) {
                psi[j] = (int16_t)r;
                acc += (int64_t)(r - p) * w[j];
            }
        }
    }
    kp->acc = acc;
    kp->u_prev_q15 = u_q15;
    return piezo_sat_q15_rnd24(acc);
}
