/* EUPI inverse compensator (see eupi_inv.h). */
#include "eupi_inv.h"

#include "fixed_q.h"

static int64_t abs64(int64_t x) { return x < 0 ? -x : x; }

int piezo_eupi_inv_init(struct piezo_eupi_inv *c, const struct piezo_eupi_inv_coef *coef,
                        int32_t *state_q15, size_t state_len,
                        int64_t *work_q39, size_t work_len)
{
    if (c == NULL || coef == NULL || state_q15 == NULL) {
        return PIEZO_EINVAL;
    }
    if (coef->a0_inv_q24 <= 0 || coef->cpi_inv.n_a != 0u) {
        return PIEZO_EINVAL;
    }
    int rc = piezo_eupi_check_upi_poly(&coef->upi, coef->p_q24, coef->n_p);
    if (rc != PIEZO_OK) {
        return rc;
    }
    /* |G2| <= 2 sum d + sum |p| + |p0| + |k_ex|: keeps v in the wide range. */
    int64_t g2_max = abs64(coef->p0_q24) + abs64(coef->kex_q24);
    for (size_t m = 0; m < coef->n_p; m++) {
        g2_max += abs64(coef->p_q24[m]);
    }
    const size_t n_upi = PIEZO_PLAY_N_OPS(coef->upi.n_r, coef->upi.n_a);
    for (size_t k = 0; k < n_upi; k++) {
        g2_max += 2 * (int64_t)coef->upi.w_q24[k];
    }
    if (g2_max > PIEZO_EUPI_INV_G2_MAX_Q24) {
        return PIEZO_EINVAL;
    }
    rc = piezo_eupi_bind_banks(&c->cpi_inv, &coef->cpi_inv, &c->upi, &coef->upi, state_q15, state_len,
                               work_q39, work_len);
    if (rc != PIEZO_OK) {
        return rc;
    }
    c->coef = coef;
    piezo_eupi_inv_reset(c);
    return PIEZO_OK;
}

void piezo_eupi_inv_reset(struct piezo_eupi_inv *c)
{
    const struct piezo_eupi_inv_coef *k = c->coef;
    piezo_play_reset(&c->cpi_inv);
    piezo_play_reset(&c->upi);
    c->g2_q39 = piezo_eupi_poly_q39(k->p_q24, k->n_p, k->p0_q24, 0);
}

int16_t piezo_eupi_inv_process(struct piezo_eupi_inv *c, int16_t yr_q15)
{
    const struct piezo_eupi_inv_coef *k = c->coef;
    /* v = y_r - G2(k-1), q15-scaled, |v| <= 17 FS. */
    /* = y_r + rshift_rnd(-G2, 24) exactly (y_r 2^24 is whole steps), fewer
     * 64-bit operations */
    const int32_t v = yr_q15 + (int32_t)piezo_rshift_rnd64(-c->g2_q39, 24u);
    /* u = G1^{-1}[v], clamped to the drive range. */
    int64_t acc = (int64_t)k->a0_inv_q24 * v;
    acc += piezo_play_process_cpi(&c->cpi_inv, v);
    const int16_t u = piezo_sat_q15_rnd24(acc);
    /* G2(k) = G_UPI[u] + P(u) - k_ex u, kept in Q39 for the next sample. */
    /* P(u) - k_ex u = p0 2^15 + (hu - k_ex) u exactly: two SMLALs onto the
     * bank's sum instead of forming p0 2^15 and k_ex u apart (round 16);
     * |hu - k_ex| <= sum |p| + n_p + |k_ex| < 2^31 by the G2 bound of init. */
    int64_t g2 = piezo_play_process_upi(&c->upi, u);
    g2 = piezo_mlal(g2, k->p0_q24, (int32_t)PIEZO_Q15_ONE);
    g2 = piezo_mlal(g2, piezo_eupi_poly_hu_q24(k->p_q24, k->n_p, u) - k->kex_q24, u);
    c->g2_q39 = g2;
    return u;
}
