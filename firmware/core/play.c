/* A bank of CPI/UPI play operators and their weighted sum (see play.h). */
#include "play.h"

#include "fixed_q.h"

int piezo_play_init(struct piezo_play *p, const struct piezo_play_coef *coef,
                    int32_t *f_q15, size_t f_len, int64_t *off_q39, size_t off_len)
{
    if (p == NULL || coef == NULL || f_q15 == NULL) {
        return PIEZO_EINVAL;
    }
    const size_t n_ops = PIEZO_PLAY_N_OPS(coef->n_r, coef->n_a);
    if (n_ops > PIEZO_PLAY_MAX_OPS || f_len < n_ops) {
        return PIEZO_ERANGE;
    }
    if (n_ops > 0u && (coef->r_q15 == NULL || coef->w_q24 == NULL)) {
        return PIEZO_EINVAL;
    }
    if (coef->n_a > 0u) {
        if (coef->a_q24 == NULL || off_q39 == NULL) {
            return PIEZO_EINVAL;
        }
        if (off_len < n_ops) {
            return PIEZO_ERANGE;
        }
        for (size_t j = 0; j < coef->n_a; j++) {
            if (coef->a_q24[j] <= 0) {
                return PIEZO_EINVAL;
            }
        }
    }
    for (size_t i = 0; i < coef->n_r; i++) {
        const int32_t r = coef->r_q15[i];
        if (r < 0 || r > PIEZO_PLAY_WIDE_MAX_Q15) {
            return PIEZO_EINVAL;
        }
        if (i > 0u && r < coef->r_q15[i - 1u]) {
            return PIEZO_EORDER;
        }
    }
    p->coef = coef;
    p->f_q15 = f_q15;
    p->off_q39 = coef->n_a > 0u ? off_q39 : NULL;
    p->n_ops = n_ops;
    /* Constants of the upper branch: a_j * r_i with the rounding half folded
     * in, so that (off + a * u) >> 24 == piezo_rshift_rnd64(a * (u + r), 24). */
    for (size_t i = 0; i < coef->n_r && coef->n_a > 0u; i++) {
        for (size_t j = 0; j < coef->n_a; j++) {
            off_q39[i * coef->n_a + j] =
                (int64_t)coef->a_q24[j] * coef->r_q15[i] + ((int64_t)1 << 23);
        }
    }
    piezo_play_reset(p);
    return PIEZO_OK;
}

void piezo_play_reset(struct piezo_play *p)
{
    for (size_t k = 0; k < p->n_ops; k++) {
        p->f_q15[k] = 0;
    }
}

int64_t piezo_play_process(struct piezo_play *p, int32_t u_q15)
{
    const struct piezo_play_coef *c = p->coef;
    const int32_t *r = c->r_q15;
    const int32_t *w = c->w_q24;
    int32_t *f = p->f_q15;
    int64_t acc = 0;

    if (c->n_a == 0u) {
        /* Classical: F = max(u - r, min(u + r, F)), exact. */
        for (size_t i = 0; i < c->n_r; i++) {
            const int32_t lo = u_q15 - r[i];
            const int32_t hi = u_q15 + r[i];
            int32_t y = f[i];
            y = y < hi ? y : hi;
            y = y > lo ? y : lo;
            f[i] = y;
            acc += (int64_t)w[i] * y;
        }
        return acc;
    }

    /* Unparallel: F = max(u - r_i, min(round(a_j * (u + r_i)), F)). */
    const int32_t *a = c->a_q24;
    const int64_t *off = p->off_q39;
    const size_t n_a = c->n_a;
    size_t k = 0;
    for (size_t i = 0; i < c->n_r; i++) {
        const int32_t lo = u_q15 - r[i];
        for (size_t j = 0; j < n_a; j++, k++) {
            const int32_t hi = (int32_t)((off[k] + (int64_t)a[j] * u_q15) >> 24);
            int32_t y = f[k];
            y = y < hi ? y : hi;
            y = y > lo ? y : lo;
            f[k] = y;
            acc += (int64_t)w[k] * y;
        }
    }
    return acc;
}
