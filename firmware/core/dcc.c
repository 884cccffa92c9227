/* dcc.c - KP compensation operators and the DCC law; see dcc.h. */
#include "dcc.h"

#include "fixed_q.h"

enum piezo_err piezo_dcc_init(struct piezo_dcc *dcc, const struct piezo_dcc_coeffs *coeffs,
                              int32_t *cpsi_q15, int32_t *zo_q15, size_t n_state)
{
    if (dcc == NULL || coeffs == NULL || cpsi_q15 == NULL || zo_q15 == NULL ||
        coeffs->c_q24 == NULL) {
        return PIEZO_EINVAL;
    }
    dcc->coeffs = NULL;
    const enum piezo_err err = piezo_kp_grid_check(&coeffs->grid);
    if (err != PIEZO_OK) {
        return err;
    }
    if (n_state < coeffs->grid.n_ops) {
        return PIEZO_ERANGE;
    }
    if (coeffs->g_q24 < 1) {
        return PIEZO_EINVAL;
    }
    dcc->coeffs = coeffs;
    dcc->cpsi_q15 = cpsi_q15;
    dcc->zo_q15 = zo_q15;
    piezo_dcc_reset(dcc);
    return PIEZO_OK;
}

void piezo_dcc_reset(struct piezo_dcc *dcc)
{
    const struct piezo_kp_grid *g = &dcc->coeffs->grid;
    for (uint16_t j = 0; j < g->n_ops; j++) {
        dcc->cpsi_q15[j] = g->nmin_q15;
        dcc->zo_q15[j] = g->nmin_q15;
    }
    dcc->xi_q15 = g->nmin_q15;
    dcc->v_prev_q15 = g->nmin_q15;
    dcc->u_last_q15 = g->nmin_q15;
    dcc->dir = -1;
}

/*
 * Advance the operators with v and return sum_j Psi_j * c_j (scaled by 2^39).
 *
 * The defining equations (dcc.h) take the minimum (rising) or maximum
 * (falling) of v - xi + zo_j and v - r(v - n_j). Since v_prev - xi + zo_j
 * is Psi_j[k-1] whenever Psi_j[k-1] took that branch, and the other branch
 * only ever lowers (rising) or raises (falling) it further in the same run,
 * v - xi + zo_j may be replaced by Psi_j[k-1] + (v - v_prev) without changing
 * a single result (docs/kernels-kp.md, "DCC without the reversal copy"):
 *
 *   rising:  Psi_j = min(Psi_j + dv, v - r(v - n2_j))
 *   falling: Psi_j = max(Psi_j + dv, v - r(v - n1_j))
 *
 * so a reversal copies nothing. With psi_j = v - Psi_j in [0, rmax] the
 * ridge is needed only where it is not flat: rising, v - r(x) >= Psi_j + dv
 * for x <= 0; falling, v - rmax <= Psi_j + dv for x >= xsat.
 */
static int64_t dcc_step(struct piezo_dcc *dcc, int16_t v_q15)
{
    const struct piezo_kp_grid *g = &dcc->coeffs->grid;
    const int32_t *c = dcc->coeffs->c_q24;
    int32_t *cpsi = dcc->cpsi_q15;
    const uint16_t n = g->n_ops;
    const int32_t v = v_q15;
    const int32_t slope = g->slope_q16, xsat = g->xsat_q15;
    int64_t acc = 0;

    if (v_q15 != dcc->v_prev_q15) {
        const int32_t dv = v - dcc->v_prev_q15;
        const int8_t dir = dv > 0 ? 1 : -1;
        if (dir != dcc->dir) { /* reversal: where it happened (kept for the record) */
            dcc->xi_q15 = dcc->v_prev_q15;
            dcc->dir = dir;
        }
        if (dir > 0) {
            const int16_t *th = g->n2_q15;
            const int32_t v_top = v - g->rmax_q15;
            for (uint16_t j = 0; j < n; j++) {
                int32_t p = cpsi[j] + dv;
                const int32_t x = v - th[j];
                if (x > 0) {
                    const int32_t cand = x >= xsat ? v_top : v - ((x * slope + 32768) >> 16);
                    p = cand < p ? cand : p;
                }
                cpsi[j] = p;
                acc += (int64_t)p * c[j];
            }
        } else {
            const int16_t *th = g->n1_q15;
            for (uint16_t j = 0; j < n; j++) {
                int32_t p = cpsi[j] + dv;
                const int32_t x = v - th[j];
                if (x < xsat) {
                    const int32_t cand = x <= 0 ? v : v - ((x * slope + 32768) >> 16);
                    p = cand > p ? cand : p;
                }
                cpsi[j] = p;
                acc += (int64_t)p * c[j];
            }
        }
        dcc->v_prev_q15 = v_q15;
    } else {
        for (uint16_t j = 0; j < n; j++) {
            acc += (int64_t)cpsi[j] * c[j];
        }
    }
    return acc;
}

void piezo_dcc_ops_update(struct piezo_dcc *dcc, int16_t v_q15)
{
    (void)dcc_step(dcc, v_q15);
}

int16_t piezo_dcc_process(struct piezo_dcc *dcc, int16_t yd_q15)
{
    int64_t acc = dcc_step(dcc, dcc->u_last_q15);
    acc += (int64_t)yd_q15 * dcc->coeffs->g_q24;
    const int16_t u = piezo_sat_q15(piezo_rshift_rnd64(acc, 24u));
    dcc->u_last_q15 = u;
    return u;
}
