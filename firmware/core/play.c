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

/*
 * A run: the operators of one column (one slope; the classical bank has one
 * column) that moved at every sample since the last reversal. They are the
 * first k of the column in threshold order (play.h), and while the run lasts
 * their outputs are not stored: each equals its branch at the last input,
 * u - r_i for the first m of them (lower branch) and the upper branch for the
 * others (m == k while rising; the classical bank's falling branch is
 * u + r_i). The run keeps the sums that give their weighted sum in closed
 * form. Five int64 words per column (PIEZO_PLAY_RUN_WORDS): the sums are
 * kept modulo 2^64 (uint64 arithmetic, no undefined overflow); the closed
 * form adds up to the exact weighted sum, which fits int64 (play.h).
 */
enum {
    RUN_W_LO,   /* sum w_i over i < m */
    RUN_WR_LO,  /* sum w_i r_i over i < m */
    RUN_W_HI,   /* sum w_i over m <= i < k */
    RUN_WH_HI,  /* sum w_i H_i over m <= i < k, H_i the high part of off_i */
    RUN_KM,     /* k | m << 16 */
};

static int64_t *run_of(struct piezo_play *p, size_t j)
{
    return p->run_q39 != NULL ? p->run_q39 + j * PIEZO_PLAY_RUN_WORDS : p->run0_q39;
}

static const int64_t *run_of_c(const struct piezo_play *p, size_t j)
{
    return p->run_q39 != NULL ? p->run_q39 + j * PIEZO_PLAY_RUN_WORDS : p->run0_q39;
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
        if (off_len < PIEZO_PLAY_WORK_LEN(coef->n_r, coef->n_a)) {
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
    p->run_q39 = coef->n_a > 0u ? off_q39 + n_ops : NULL;
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

static void runs_clear(struct piezo_play *p)
{
    const size_t n_col = p->coef->n_a ? p->coef->n_a : 1u;
    for (size_t j = 0; j < n_col; j++) {
        int64_t *run = run_of(p, j);
        for (size_t q = 0; q < PIEZO_PLAY_RUN_WORDS; q++) {
            run[q] = 0;
        }
    }
}

void piezo_play_reset(struct piezo_play *p)
{
    for (size_t k = 0; k < p->n_ops; k++) {
        p->f_q15[k] = 0;
    }
    runs_clear(p);
    p->acc_q39 = 0;
    p->rest_q39 = 0;
    p->u_prev_q15 = 0;
    p->dir = 0;
    p->primed = 0u;
}

/* Output of operator i of column j, a member of the column's run (i < k),
 * at the last input u. */
static int32_t run_member(const struct piezo_play *p, size_t j, size_t i, size_t m)
{
    const int32_t u = p->u_prev_q15;
    const int32_t r = p->coef->r_q15[i];
    if (p->dir > 0 || i < m) {
        return u - r;
    }
    if (p->coef->n_a == 0u) {
        return u + r;
    }
    const int64_t au = split24((int64_t)p->coef->a_q24[j] * u);
    return upper(p->off_q39[j * p->coef->n_r + i], (uint32_t)au, (int32_t)(au >> 32));
}

int32_t piezo_play_output(const struct piezo_play *p, size_t k)
{
    const size_t n_a = p->coef->n_a;
    const size_t n_r = p->coef->n_r;
    /* i = k / n_a, j = k % n_a without a division (the core has none) */
    size_t i = k, j = 0u;
    if (n_a != 0u) {
        for (i = 0u, j = k; j >= n_a; j -= n_a) {
            i++;
        }
    }
    const uint32_t km = (uint32_t)run_of_c(p, j)[RUN_KM];
    if (i < (km & 0xFFFFu)) {
        return run_member(p, j, i, km >> 16);
    }
    return p->f_q15[j * n_r + i];
}

/* End every run: store its members' outputs at the last input and fold their
 * weighted sum (part of acc_q39) into the stored operators' sum. At most one
 * store per operator (two instructions on the lower branch, five on the
 * upper); a reversal costs this once. */
static void runs_end(struct piezo_play *p)
{
    const struct piezo_play_coef *c = p->coef;
    const size_t n_col = c->n_a ? c->n_a : 1u;
    const size_t n_r = c->n_r;
    const int32_t u = p->u_prev_q15;
    const int32_t *r = c->r_q15;
    for (size_t j = 0; j < n_col; j++) {
        int64_t *run = run_of(p, j);
        const uint32_t km = (uint32_t)run[RUN_KM];
        const size_t k = km & 0xFFFFu;
        size_t i = 0;
        int32_t *fc = p->f_q15 + j * n_r;
        if (p->dir > 0 || c->n_a != 0u) {
            /* rising (every member) or unparallel falling (the first m) */
            const size_t m = p->dir > 0 ? k : km >> 16;
            for (; i < m; i++) {
                fc[i] = u - r[i];
            }
        }
        if (c->n_a == 0u) {
            for (; i < k; i++) {
                fc[i] = u + r[i];
            }
        } else if (i < k) {
            const int64_t au = split24((int64_t)c->a_q24[j] * u);
            const uint32_t au_lo = (uint32_t)au;
            const int32_t au_hi = (int32_t)(au >> 32);
            const int64_t *off = p->off_q39 + j * n_r;
            for (; i < k; i++) {
                fc[i] = upper(off[i], au_lo, au_hi);
            }
        }
        run[RUN_W_LO] = run[RUN_WR_LO] = run[RUN_W_HI] = run[RUN_WH_HI] = run[RUN_KM] = 0;
    }
    p->rest_q39 = p->acc_q39;
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

/* Unsigned (modulo 2^64) products and sums of the run's closed form. */
static inline uint64_t mul_u64(int64_t a, int32_t b) { return (uint64_t)a * (uint64_t)(int64_t)b; }
static inline uint64_t w_u64(int32_t w) { return (uint64_t)(int64_t)w; }

/* One rising or classical column: the run's members all on one branch,
 * u - r_i (rising) or u + r_i (classical, falling). Returns the run's
 * weighted sum (mod 2^64); joins update rest, the stored operators' sum. */
static uint64_t column_straight(int64_t *run, const int32_t *r, const int32_t *w, size_t w_stride,
                                const int32_t *fc, size_t n_r, int32_t u, int rising, uint64_t *rest)
{
    uint32_t k = (uint32_t)run[RUN_KM] & 0xFFFFu;
    uint64_t sw = (uint64_t)run[RUN_W_LO], swr = (uint64_t)run[RUN_WR_LO];
    const uint32_t k0 = k;
    /* joins: rising, F = max(u - r, F) moves iff u - r > F; classical falling,
     * F = min(u + r, F) iff u + r < F; the movers are a prefix (play.h) */
    while (k < n_r) {
        const int32_t b = rising ? u - r[k] : u + r[k];
        const int32_t y = fc[k];
        if (rising ? b <= y : b >= y) {
            break;
        }
        const int32_t wk = w[k * w_stride];
        *rest -= mul_u64(y, wk);
        sw += w_u64(wk);
        swr += mul_u64(r[k], wk);
        k++;
    }
    if (k != k0) {
        run[RUN_W_LO] = (int64_t)sw;
        run[RUN_WR_LO] = (int64_t)swr;
        run[RUN_KM] = (int64_t)(k | (rising ? k : 0u) << 16);
    }
    const uint64_t uw = mul_u64((int64_t)sw, u);
    return rising ? uw - swr : uw + swr;
}

/* One unparallel column, falling: members i < m on the lower branch u - r_i,
 * the others on the upper branch H_i + (a u >> 24) + carry_i. */
static uint64_t column_falling(int64_t *run, const int32_t *r, const int32_t *w, size_t w_stride,
                               const int64_t *off, const int32_t *fc, size_t n_r, int32_t a_q24,
                               int32_t u, uint64_t *rest)
{
    const int64_t au = split24((int64_t)a_q24 * u);
    const uint32_t au_lo = (uint32_t)au;
    const int32_t au_hi = (int32_t)(au >> 32);
    const uint32_t km0 = (uint32_t)run[RUN_KM];
    uint32_t k = km0 & 0xFFFFu, m = km0 >> 16;
    uint64_t wl = (uint64_t)run[RUN_W_LO], wrl = (uint64_t)run[RUN_WR_LO];
    uint64_t wh = (uint64_t)run[RUN_W_HI], whh = (uint64_t)run[RUN_WH_HI];

    /* m, the members on the lower branch: u - r_i > hi_i is a prefix in i
     * (u - r_i - hi_i does not increase with r_i); while falling it shrinks
     * for a <= 1 and grows for a > 1 */
    while (m > 0u && u - r[m - 1u] <= upper(off[m - 1u], au_lo, au_hi)) {
        m--;
        const int32_t wm = w[m * w_stride];
        wl -= w_u64(wm);
        wrl -= mul_u64(r[m], wm);
        wh += w_u64(wm);
        whh += mul_u64((int32_t)(off[m] >> 32), wm);
    }
    while (m < k && u - r[m] > upper(off[m], au_lo, au_hi)) {
        const int32_t wm = w[m * w_stride];
        wh -= w_u64(wm);
        whh -= mul_u64((int32_t)(off[m] >> 32), wm);
        wl += w_u64(wm);
        wrl += mul_u64(r[m], wm);
        m++;
    }
    /* joins: F moves iff F > hi (F == hi joins too: its update leaves it) */
    while (k < n_r) {
        const int32_t hi = upper(off[k], au_lo, au_hi);
        const int32_t y = fc[k];
        if (y < hi) {
            break;
        }
        const int32_t wk = w[k * w_stride];
        *rest -= mul_u64(y, wk);
        if (m == k && u - r[k] > hi) {
            wl += w_u64(wk);
            wrl += mul_u64(r[k], wk);
            m++;
        } else {
            wh += w_u64(wk);
            whh += mul_u64((int32_t)(off[k] >> 32), wk);
        }
        k++;
    }
    if ((k | m << 16) != km0) {
        run[RUN_W_LO] = (int64_t)wl;
        run[RUN_WR_LO] = (int64_t)wrl;
        run[RUN_W_HI] = (int64_t)wh;
        run[RUN_WH_HI] = (int64_t)whh;
        run[RUN_KM] = (int64_t)(k | m << 16);
    }
    /* the carries of the upper branch, one per member on it */
    uint64_t carry = 0;
    const int32_t *wp = w + m * w_stride;
    for (uint32_t i = m; i < k; i++, wp += w_stride) {
        if ((uint32_t)off[i] + au_lo < (uint32_t)off[i]) {
            carry += w_u64(*wp);
        }
    }
    return mul_u64((int64_t)wl, u) - wrl + mul_u64((int64_t)wh, au_hi) + whh + carry;
}

int64_t piezo_play_process(struct piezo_play *p, int32_t u_q15)
{
    if (!p->primed) {
        p->primed = 1u;
        p->u_prev_q15 = u_q15;
        p->acc_q39 = play_full(p, u_q15);
        p->rest_q39 = p->acc_q39;
        return p->acc_q39;
    }
    const int32_t u_prev = p->u_prev_q15;
    if (u_q15 == u_prev) {
        return p->acc_q39; /* the update is idempotent */
    }
    const int8_t dir = u_q15 > u_prev ? 1 : -1;
    if (dir != p->dir) {
        runs_end(p); /* a reversal: the runs' members stored at u_prev */
        p->dir = dir;
    }
    p->u_prev_q15 = u_q15;

    const struct piezo_play_coef *c = p->coef;
    const int32_t *r = c->r_q15;
    const int32_t *w = c->w_q24;
    const size_t n_r = c->n_r;
    uint64_t rest = (uint64_t)p->rest_q39;
    uint64_t acc;

    if (c->n_a == 0u) {
        acc = column_straight(p->run0_q39, r, w, 1u, p->f_q15, n_r, u_q15, dir > 0, &rest);
    } else {
        /* Unparallel, column by column (slope a_j, thresholds ascending); the
         * outputs are stored column by column too (slot j * n_r + i); only
         * the weights (row-major, as given) are read with a stride. */
        const size_t n_a = c->n_a;
        acc = 0;
        for (size_t j = 0; j < n_a; j++) {
            int64_t *run = p->run_q39 + j * PIEZO_PLAY_RUN_WORDS;
            const int32_t *fc = p->f_q15 + j * n_r;
            if (dir > 0) {
                /* F = max(u - r_i, F): the upper branch cannot bind while rising. */
                acc += column_straight(run, r, w + j, n_a, fc, n_r, u_q15, 1, &rest);
            } else {
                acc += column_falling(run, r, w + j, n_a, p->off_q39 + j * n_r, fc, n_r,
                                      c->a_q24[j], u_q15, &rest);
            }
        }
    }
    p->rest_q39 = (int64_t)rest;
    p->acc_q39 = (int64_t)(acc + rest);
    return p->acc_q39;
}
