/* A bank of CPI/UPI play operators and their weighted sum (see play.h). */
#include "play.h"

#include "fixed_q.h"

/*
 * The upper branch (off + a u) >> 24 in three instructions: a value x is
 * split into its high part x >> 24 (int32) and its low 24 bits shifted to the
 * top of a word, stored as one int64 (high part in the upper word). Then
 * (x + y) >> 24 = xh + yh + carry of the 32-bit sum xl + yl.
 */
static int64_t split24(int64_t x)
{
    const uint32_t lo = ((uint32_t)x & 0xFFFFFFu) << 8;
    const int32_t hi = (int32_t)(x >> 24);
    return (int64_t)(((uint64_t)(uint32_t)hi << 32) | lo);
}

static inline int32_t upper(int64_t off_split, uint32_t au_lo, int32_t au_hi)
{
    const uint32_t ol = (uint32_t)off_split;
    const int32_t oh = (int32_t)(off_split >> 32);
    const uint32_t sum = ol + au_lo;
    return oh + au_hi + (int32_t)(sum < ol);
}

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
    /* Constants of the upper branch: off = a_j * r_i with the rounding half
     * folded in, so that (off + a * u) >> 24 == piezo_rshift_rnd64(a * (u + r), 24),
     * stored split (see upper()) and column by column: slot j * n_r + i. */
    for (size_t i = 0; i < coef->n_r && coef->n_a > 0u; i++) {
        for (size_t j = 0; j < coef->n_a; j++) {
            off_q39[j * coef->n_r + i] =
                split24((int64_t)coef->a_q24[j] * coef->r_q15[i] + ((int64_t)1 << 23));
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
    p->acc_q39 = 0;
    p->u_prev_q15 = 0;
    p->primed = 0u;
}

/* The formula on every operator, the sum from scratch (first sample). */
static int64_t play_full(struct piezo_play *p, int32_t u_q15)
{
    const struct piezo_play_coef *c = p->coef;
    const int32_t *r = c->r_q15;
    const int32_t *w = c->w_q24;
    int32_t *f = p->f_q15;
    const size_t n_a = c->n_a, n_r = c->n_r;
    int64_t acc = 0;
    if (n_a == 0u) {
        for (size_t i = 0; i < n_r; i++) {
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
    for (size_t j = 0; j < n_a; j++) {
        const int64_t au = split24((int64_t)c->a_q24[j] * u_q15);
        const int64_t *off = p->off_q39 + j * n_r;
        int32_t *fc = f + j * n_r; /* column j, outputs column by column */
        for (size_t i = 0, k = j; i < n_r; i++, k += n_a) {
            const int32_t hi = upper(off[i], (uint32_t)au, (int32_t)(au >> 32));
            const int32_t lo = u_q15 - r[i];
            int32_t y = fc[i];
            y = y < hi ? y : hi;
            y = y > lo ? y : lo;
            fc[i] = y;
            acc += (int64_t)w[k] * y;
        }
    }
    return acc;
}

int64_t piezo_play_process(struct piezo_play *p, int32_t u_q15)
{
    if (!p->primed) {
        p->primed = 1u;
        p->u_prev_q15 = u_q15;
        p->acc_q39 = play_full(p, u_q15);
        return p->acc_q39;
    }
    const int32_t u_prev = p->u_prev_q15;
    if (u_q15 == u_prev) {
        return p->acc_q39; /* the update is idempotent */
    }
    p->u_prev_q15 = u_q15;

    const struct piezo_play_coef *c = p->coef;
    const int32_t *r = c->r_q15;
    const int32_t *w = c->w_q24;
    int32_t *f = p->f_q15;
    const size_t n_r = c->n_r;
    int64_t acc = p->acc_q39;

    if (c->n_a == 0u) {
        /* Classical: rising F = max(u - r, F), falling F = min(u + r, F);
         * the operators that move are a prefix in both directions. */
        if (u_q15 > u_prev) {
            for (size_t i = 0; i < n_r; i++) {
                const int32_t lo = u_q15 - r[i];
                const int32_t y = f[i];
                if (lo <= y) {
                    break;
                }
                f[i] = lo;
                acc += (int64_t)w[i] * (lo - y);
            }
        } else {
            for (size_t i = 0; i < n_r; i++) {
                const int32_t hi = u_q15 + r[i];
                const int32_t y = f[i];
                if (hi >= y) {
                    break;
                }
                f[i] = hi;
                acc += (int64_t)w[i] * (hi - y);
            }
        }
        p->acc_q39 = acc;
        return acc;
    }

    /* Unparallel, column by column (slope a_j, thresholds ascending); the
     * outputs are stored column by column too (slot j * n_r + i), so that a
     * column's outputs, thresholds and branch constants are walked in step;
     * only the weights (row-major, as given) are read with a stride. */
    const size_t n_a = c->n_a;
    if (u_q15 > u_prev) {
        /* F = max(u - r_i, F): the upper branch cannot bind while rising. */
        for (size_t j = 0; j < n_a; j++) {
            int32_t *fc = f + j * n_r;
            const int32_t *wk = w + j;
            for (size_t i = 0; i < n_r; i++, wk += n_a) {
                const int32_t lo = u_q15 - r[i];
                const int32_t y = fc[i];
                if (lo <= y) {
                    break;
                }
                fc[i] = lo;
                acc += (int64_t)*wk * (lo - y);
            }
        }
    } else {
        /* F moves iff F > hi, to max(u - r_i, hi); stop at F - hi <= -1. */
        for (size_t j = 0; j < n_a; j++) {
            const int64_t au = split24((int64_t)c->a_q24[j] * u_q15);
            const uint32_t au_lo = (uint32_t)au;
            const int32_t au_hi = (int32_t)(au >> 32);
            const int64_t *op = p->off_q39 + j * n_r;
            int32_t *fp = f + j * n_r;
            const int32_t *rp = r;
            const int32_t *wp = w + j;
            /* F == hi goes through the update too: F >= u - r while
             * falling, so then max(hi, u - r) == F and nothing changes.
             * The lower branch cannot win when a <= 1 and u <= 0 or
             * a >= 1 and u >= 0: u - r - hi <= u (1 - a) - r (1 + a) + 1/2
             * (hi rounded half up), which is then below 1 (an integer <= 0);
             * the scan then skips u - r and the max. */
            const int32_t a_j = c->a_q24[j];
            if (a_j <= PIEZO_Q24_ONE ? u_q15 <= 0 : u_q15 >= 0) {
                for (size_t i = n_r; i != 0u; i--) {
                    const int32_t hi = upper(*op++, au_lo, au_hi);
                    const int32_t y = *fp;
                    if (y < hi) {
                        break;
                    }
                    *fp++ = hi;
                    acc += (int64_t)*wp * (hi - y);
                    wp += n_a;
                }
                continue;
            }
            for (size_t i = n_r; i != 0u; i--) {
                const int32_t hi = upper(*op++, au_lo, au_hi);
                const int32_t y = *fp;
                if (y < hi) {
                    break;
                }
                const int32_t lo = u_q15 - *rp++;
                const int32_t v = hi > lo ? hi : lo;
                *fp++ = v;
                acc += (int64_t)*wp * (v - y);
                wp += n_a;
            }
        }
    }
    p->acc_q39 = acc;
    return acc;
}
