/* EUPI hysteresis model (see eupi.h). */
#include "eupi.h"

#include "fixed_q.h"

int piezo_eupi_check_bank_q15(const struct piezo_play_coef *bank)
{
    const size_t n_ops = PIEZO_PLAY_N_OPS(bank->n_r, bank->n_a);
    if (n_ops > PIEZO_PLAY_MAX_OPS) {
        return PIEZO_ERANGE;
    }
    if (n_ops > 0u && (bank->r_q15 == NULL || bank->w_q24 == NULL)) {
        return PIEZO_EINVAL;
    }
    for (size_t i = 0; i < bank->n_r; i++) {
        if (bank->r_q15[i] > PIEZO_Q15_MAX) {
            return PIEZO_EINVAL;
        }
    }
    for (size_t k = 0; k < n_ops; k++) {
        if (bank->w_q24[k] < 0) {
            return PIEZO_EINVAL;
        }
    }
    return PIEZO_OK;
}

int piezo_eupi_check_upi_poly(const struct piezo_play_coef *upi,
                              const int32_t *p_q24, uint16_t n_p)
{
    if (upi->n_r > 0u && upi->n_a == 0u) {
        return PIEZO_EINVAL; /* a UPI grid needs its slopes */
    }
    const int rc = piezo_eupi_check_bank_q15(upi);
    if (rc != PIEZO_OK) {
        return rc;
    }
    if (n_p > PIEZO_EUPI_MAX_POLY) {
        return PIEZO_ERANGE;
    }
    if (n_p > 0u && p_q24 == NULL) {
        return PIEZO_EINVAL;
    }
    int64_t sum = 0;
    for (size_t m = 0; m < n_p; m++) {
        sum += p_q24[m] < 0 ? -(int64_t)p_q24[m] : (int64_t)p_q24[m];
    }
    /* strict: sum |p_m| = 64 lets h reach 2^30, and 2 h wraps (eupi.h) */
    return sum >= PIEZO_EUPI_POLY_SUM_MAX_Q24 ? PIEZO_EINVAL : PIEZO_OK;
}

int piezo_eupi_init(struct piezo_eupi *m, const struct piezo_eupi_coef *coef,
                    int32_t *state_q15, size_t state_len,
                    int64_t *work_q39, size_t work_len)
{
    if (m == NULL || coef == NULL || state_q15 == NULL) {
        return PIEZO_EINVAL;
    }
    if (coef->a0_q24 <= 0 || coef->cpi.n_a != 0u) {
        return PIEZO_EINVAL;
    }
    int rc = piezo_eupi_check_bank_q15(&coef->cpi);
    if (rc == PIEZO_OK) {
        rc = piezo_eupi_check_upi_poly(&coef->upi, coef->p_q24, coef->n_p);
    }
    if (rc != PIEZO_OK) {
        return rc;
    }
    rc = piezo_eupi_bind_banks(&m->cpi, &coef->cpi, &m->upi, &coef->upi, state_q15, state_len,
                               work_q39, work_len);
    if (rc != PIEZO_OK) {
        return rc;
    }
    m->coef = coef;
    return PIEZO_OK;
}

int piezo_eupi_bind_banks(struct piezo_play *cpi, const struct piezo_play_coef *cpi_coef,
                          struct piezo_play *upi, const struct piezo_play_coef *upi_coef,
                          int32_t *state_q15, size_t state_len, int64_t *work_q39, size_t work_len)
{
    const size_t n_cpi = cpi_coef->n_r;
    struct piezo_play c, u;
    int rc;
    if (n_cpi > PIEZO_PLAY_MAX_OPS || state_len < n_cpi) {
        return PIEZO_ERANGE;
    }
    rc = piezo_play_init(&c, cpi_coef, state_q15, n_cpi, NULL, 0u);
    if (rc == PIEZO_OK) {
        rc = piezo_play_init(&u, upi_coef, state_q15 + n_cpi, state_len - n_cpi, work_q39,
                             work_q39 == NULL ? 0u : work_len);
    }
    if (rc != PIEZO_OK) {
        return rc;
    }
    *cpi = c;
    *upi = u;
    return PIEZO_OK;
}

void piezo_eupi_reset(struct piezo_eupi *m)
{
    piezo_play_reset(&m->cpi);
    piezo_play_reset(&m->upi);
}

int64_t piezo_eupi_poly_q39(const int32_t *p_q24, uint16_t n_p, int32_t p0_q24,
                            int16_t u_q15)
{
    return piezo_eupi_poly_q39_inline(p_q24, n_p, p0_q24, u_q15);
}

int16_t piezo_eupi_process(struct piezo_eupi *m, int16_t u_q15)
{
    const struct piezo_eupi_coef *c = m->coef;
    int64_t acc = (int64_t)c->a0_q24 * u_q15;
    acc += piezo_play_process_cpi(&m->cpi, u_q15);
    acc += piezo_play_process_upi(&m->upi, u_q15);
    acc += piezo_eupi_poly_q39(c->p_q24, c->n_p, c->p0_q24, u_q15);
    return piezo_sat_q15_rnd24(acc);
}
