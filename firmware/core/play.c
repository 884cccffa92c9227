/* A bank of CPI/UPI play operators and their weighted sum, kept as a memory
 * stack of segments per column (see play.h). */
#include "play.h"

#include <stddef.h>

#include "fixed_q.h"

/* Segment kinds (the segment word's bits 16 and up; bits 0-15: its first
 * operator). A segment runs from its first operator to the next deeper
 * segment's first (or n_r); the stack's bottom (index 0) holds the largest
 * thresholds. */
#define SEG_LO 0u    /* F_i = v - r_i  (v: a past input) */
#define SEG_HI 1u    /* F_i = v + c_i  (v: A(e) of a past input e) */
#define SEG_ZERO 2u  /* F_i = 0 (reset) */
#define SEG_WORD(first, kind) ((uint32_t)(first) | ((uint32_t)(kind) << 16))

#define HALF24 ((int64_t)1 << 23)

/* A column's block in the int32 state: segment values [n_r], segment words
 * [n_r], keys r_i + c_i [n_r], prefix sums of w [n_r + 1]; in the int64
 * work: the column words, then the prefix sums of w r and (unparallel) w c. */
#define COL_BELOW 0 /* sum_i w_i F_i over the segments below the fresh ones (modulo 2^64) */
#define COL_TOP 1   /* the same over the fresh ones (the last sample's) */
#define COL_PACK 2  /* segments | LO/HI edge << 16 | fresh << 32 | last rising << 40 */
#define COL_WORDS 3u

/* c = rshift_rnd(a r, 24): the per-operator half of the upper branch. */
static inline int32_t c_of(int32_t a_q24, int32_t r_q15)
{
    return (int32_t)(((int64_t)a_q24 * r_q15 + HALF24) >> 24);
}

/* A column's constants. */
struct col {
    const int32_t *r;
    const int32_t *key;     /* r_i + c_i, non-decreasing */
    const int32_t *W;       /* prefix sums of w: |W| < 2^31 (checked by init) */
    const int64_t *WR, *WC; /* prefix sums of w r, w c (classical: WC = WR) */
    int32_t a;
    uint32_t n_r;
};

/* sum_i w_i F_i over operators [b, e) of a segment, modulo 2^64. */
static inline uint64_t seg_sum(const struct col *k, uint32_t kind, int32_t v, uint32_t b, uint32_t e)
{
    if (kind == SEG_ZERO) {
        return 0u;
    }
    const uint64_t s = (uint64_t)((int64_t)v * (k->W[e] - k->W[b]));
    return kind == SEG_LO ? s - ((uint64_t)k->WR[e] - (uint64_t)k->WR[b])
                          : s + ((uint64_t)k->WC[e] - (uint64_t)k->WC[b]);
}

/*
 * One sample on one column: pop the segments the input wipes out, trim the
 * one it stops in, push the new top; returns the column's new sum. Rising
 * (u > u_prev) an operator moves iff F_i + r_i < u, falling iff
 * F_i - c_i > A(u); both are monotone in i (F + r non-decreasing, F - c
 * non-increasing along the column), so the movers are a prefix.
 *
 * The segments the last sample pushed (fresh: LO(u_prev), or LO(u_prev) and
 * HI(A(u_prev))) keep their sum apart (COL_TOP). A sample that goes on in
 * the same direction re-describes all of them (each of their operators
 * either moves or already equals the new formula: rising u - r_i > u_prev -
 * r_i; falling u_prev - r_i and A(u_prev) + c_i are >= the new branch, equal
 * only where the new formula gives the same value), so they are dropped
 * without a sum; a reversal adds their sum to the rest (COL_BELOW) and walks
 * them as any other segment.
 */
static inline __attribute__((always_inline)) int64_t col_step(const struct col *k, int32_t *v, uint32_t *m,
                                                              int64_t *cw, int32_t u, int rising,
                                                              int classical)
{
    uint64_t below = (uint64_t)cw[COL_BELOW];
    const uint64_t pack = (uint64_t)cw[COL_PACK];
    uint32_t n = (uint32_t)pack & 0xFFFFu;
    uint32_t q = (uint32_t)(pack >> 16) & 0xFFFFu;
    const uint32_t nf = (uint32_t)(pack >> 32) & 0xFFu;
    const uint32_t last_rising = (uint32_t)(pack >> 40) & 1u;
    const uint32_t n_r = k->n_r;
    const int32_t au = rising ? 0 : classical ? u : (int32_t)piezo_rshift_rnd64((int64_t)k->a * u, 24u);
    if (nf != 0u) {
        if ((uint32_t)rising == last_rising) {
            n -= nf; /* re-described by the new top */
        } else {
            below += (uint64_t)cw[COL_TOP];
        }
    }
    uint32_t stop; /* first operator that does not move */
    for (;;) {
        if (n == 0u) {
            stop = n_r;
            break;
        }
        const uint32_t s = n - 1u;
        const uint32_t b = m[s] & 0xFFFFu, kind = m[s] >> 16;
        const uint32_t e = s ? (m[s - 1u] & 0xFFFFu) : n_r;
        const int32_t val = v[s];
        uint32_t i = b;
        if (rising) {
            if (kind == SEG_LO) {
                i = val < u ? e : b;
            } else if (kind == SEG_HI) {
                const int32_t lim = u - val;
                while (i < e && k->key[i] < lim) {
                    i++;
                }
            } else {
                while (i < e && k->r[i] < u) {
                    i++;
                }
            }
        } else {
            if (kind == SEG_HI) {
                i = val > au ? e : b;
            } else if (kind == SEG_LO) {
                const int32_t lim = val - au;
                while (i < e && k->key[i] < lim) {
                    i++;
                }
            } else {
                while (i < e && k->key[i] - k->r[i] < -au) { /* c_i */
                    i++;
                }
            }
        }
        if (i == e) { /* wiped out */
            below -= seg_sum(k, kind, val, b, e);
            n--;
            continue;
        }
        if (i > b) { /* its first operators move */
            below -= seg_sum(k, kind, val, b, i);
            m[s] = SEG_WORD(i, kind);
        }
        stop = i;
        break;
    }
    uint64_t top;
    uint32_t n_new = 0u;
    if (rising) {
        /* LO(u) on [0, stop) */
        top = (uint64_t)((int64_t)u * k->W[stop]) - (uint64_t)k->WR[stop];
        if (stop > 0u) {
            v[n] = u;
            m[n] = SEG_WORD(0u, SEG_LO);
            n_new = 1u;
        }
    } else {
        /* LO(u) where r_i + c_i <= u - A(u), HI(A(u)) after: the edge from
         * the last fall's */
        const int32_t lim = u - au;
        q = q < stop ? q : stop;
        while (q > 0u && k->key[q - 1u] > lim) {
            q--;
        }
        while (q < stop && k->key[q] <= lim) {
            q++;
        }
        const int32_t wq = k->W[q];
        top = (uint64_t)((int64_t)u * wq + (int64_t)au * (k->W[stop] - wq)) - (uint64_t)k->WR[q] +
              ((uint64_t)k->WC[stop] - (uint64_t)k->WC[q]);
        if (q < stop) {
            v[n] = au;
            m[n] = SEG_WORD(q, SEG_HI);
            n_new = 1u;
        }
        if (q > 0u) {
            v[n + n_new] = u;
            m[n + n_new] = SEG_WORD(0u, SEG_LO);
            n_new++;
        }
    }
    cw[COL_BELOW] = (int64_t)below;
    cw[COL_TOP] = (int64_t)top;
    cw[COL_PACK] = (int64_t)((uint64_t)(n + n_new) | ((uint64_t)q << 16) | ((uint64_t)n_new << 32) |
                             ((uint64_t)(rising != 0) << 40));
    return (int64_t)(below + top);
}

static inline __attribute__((always_inline)) void col_bind(const struct piezo_play *p, size_t j, struct col *k,
                                                          int32_t **v, uint32_t **m, int64_t **cw)
{
    const struct piezo_play_coef *c = p->coef;
    const size_t n_r = c->n_r;
    int32_t *b32 = p->state + j * p->stride32;
    int64_t *b64 = p->work + j * p->stride64;
    k->r = c->r_q15;
    k->n_r = (uint32_t)n_r;
    k->a = c->n_a ? c->a_q24[j] : PIEZO_Q24_ONE;
    k->key = b32 + 2u * n_r;
    k->W = b32 + 3u * n_r;
    k->WR = b64 + COL_WORDS;
    k->WC = c->n_a ? k->WR + n_r + 1u : k->WR; /* classical: c = r */
    *v = b32;
    *m = (uint32_t *)(void *)(b32 + n_r);
    *cw = b64;
}

int piezo_play_init(struct piezo_play *p, const struct piezo_play_coef *coef,
                    int32_t *state, size_t state_len, int64_t *work, size_t work_len)
{
    if (p == NULL || coef == NULL || state == NULL || work == NULL) {
        return PIEZO_EINVAL;
    }
    const size_t n_ops = PIEZO_PLAY_N_OPS(coef->n_r, coef->n_a);
    if (n_ops > PIEZO_PLAY_MAX_OPS || state_len < PIEZO_PLAY_STATE_LEN(coef->n_r, coef->n_a) ||
        work_len < PIEZO_PLAY_WORK_LEN(coef->n_r, coef->n_a)) {
        return PIEZO_ERANGE;
    }
    if (n_ops > 0u && (coef->r_q15 == NULL || coef->w_q24 == NULL)) {
        return PIEZO_EINVAL;
    }
    if (coef->n_a > 0u) {
        if (coef->a_q24 == NULL) {
            return PIEZO_EINVAL;
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
    /* The prefix sums of w are int32: every column's sum of |w| < 2^31. */
    const size_t n_a = coef->n_a, n_cols = PIEZO_PLAY_N_COLS(n_a);
    for (size_t j = 0; j < n_cols; j++) {
        int64_t sum = 0;
        for (size_t i = 0; i < coef->n_r; i++) {
            const int64_t w = coef->w_q24[n_a ? i * n_a + j : i];
            sum += w < 0 ? -w : w;
        }
        if (sum > INT32_MAX) {
            return PIEZO_ERANGE;
        }
    }
    p->coef = coef;
    p->state = state;
    p->work = work;
    p->n_ops = n_ops;
    p->stride32 = (uint32_t)(PIEZO_PLAY_STATE_LEN(coef->n_r, 0u));
    p->stride64 = (uint32_t)(PIEZO_PLAY_WORK_LEN(coef->n_r, 1u) - (n_a ? 0u : coef->n_r + 1u));
    /* Keys and prefix sums of w, w r and w c per column (the last two
     * modulo 2^64, see play.h). */
    for (size_t j = 0; j < n_cols; j++) {
        struct col k;
        int32_t *v;
        uint32_t *m;
        int64_t *cw;
        col_bind(p, j, &k, &v, &m, &cw);
        int32_t *key = (int32_t *)(uintptr_t)k.key, *W = (int32_t *)(uintptr_t)k.W;
        int64_t *WR = (int64_t *)(uintptr_t)k.WR, *WC = (int64_t *)(uintptr_t)k.WC;
        W[0] = 0;
        WR[0] = WC[0] = 0;
        for (size_t i = 0; i < coef->n_r; i++) {
            const int64_t w = coef->w_q24[n_a ? i * n_a + j : i];
            const int32_t r = coef->r_q15[i];
            const int32_t cc = n_a ? c_of(k.a, r) : r;
            key[i] = r + cc;
            W[i + 1u] = (int32_t)(W[i] + w);
            WR[i + 1u] = (int64_t)((uint64_t)WR[i] + (uint64_t)(w * r));
            if (n_a) {
                WC[i + 1u] = (int64_t)((uint64_t)WC[i] + (uint64_t)(w * cc));
            }
        }
    }
    piezo_play_reset(p);
    return PIEZO_OK;
}

void piezo_play_reset(struct piezo_play *p)
{
    const size_t n_cols = PIEZO_PLAY_N_COLS(p->coef->n_a);
    for (size_t j = 0; j < n_cols; j++) {
        struct col k;
        int32_t *v;
        uint32_t *m;
        int64_t *cw;
        col_bind(p, j, &k, &v, &m, &cw);
        if (k.n_r > 0u) { /* one segment: every operator at 0 */
            v[0] = 0;
            m[0] = SEG_WORD(0u, SEG_ZERO);
        }
        cw[COL_BELOW] = 0;
        cw[COL_TOP] = 0;
        cw[COL_PACK] = k.n_r > 0u ? 1 : 0;
    }
    p->acc_q39 = 0;
    p->u_prev_q15 = 0;
}

int32_t piezo_play_output(const struct piezo_play *p, size_t k_op)
{
    const struct piezo_play_coef *c = p->coef;
    const size_t n_cols = PIEZO_PLAY_N_COLS(c->n_a);
    size_t j = k_op; /* k_op = i n_cols + j, without a division (none in the core) */
    uint32_t i = 0;
    while (j >= n_cols) {
        j -= n_cols;
        i++;
    }
    struct col k;
    int32_t *v;
    uint32_t *m;
    int64_t *cw;
    col_bind(p, j, &k, &v, &m, &cw);
    const uint32_t n = (uint32_t)((uint64_t)cw[COL_PACK] & 0xFFFFu);
    uint32_t s = 0;
    while (s + 1u < n && (m[s] & 0xFFFFu) > i) { /* from the bottom: first segment starting at or before i */
        s++;
    }
    const uint32_t kind = m[s] >> 16;
    return kind == SEG_ZERO ? 0 : kind == SEG_LO ? v[s] - k.r[i] : v[s] + (k.key[i] - k.r[i]);
}

/* The columns in turn, the column's constants walked by pointer (the
 * direction and the bank's kind are constants of each loop). */
static inline __attribute__((always_inline)) int64_t cols_step(const struct piezo_play *p, int32_t u, int rising,
                                                               int classical)
{
    const struct piezo_play_coef *c = p->coef;
    const uint32_t n_r = c->n_r;
    const size_t n_cols = PIEZO_PLAY_N_COLS(c->n_a);
    const uint32_t s32 = p->stride32, s64 = p->stride64;
    const int32_t *a = c->a_q24;
    int32_t *b32 = p->state;
    int64_t *b64 = p->work;
    uint64_t acc = 0u;
    struct col k;
    k.r = c->r_q15;
    k.n_r = n_r;
    k.a = PIEZO_Q24_ONE;
    for (size_t j = n_cols; j != 0u; j--) {
        if (!classical) {
            k.a = *a++;
        }
        k.key = b32 + 2u * n_r;
        k.W = b32 + 3u * n_r;
        k.WR = b64 + COL_WORDS;
        k.WC = classical ? k.WR : k.WR + n_r + 1u;
        acc += (uint64_t)col_step(&k, b32, (uint32_t *)(void *)(b32 + n_r), b64, u, rising, classical);
        b32 += s32;
        b64 += s64;
    }
    return (int64_t)acc;
}

static __attribute__((noinline)) int64_t bank_step(struct piezo_play *p, int32_t u, int rising)
{
    if (p->coef->n_a == 0u) {
        return rising ? cols_step(p, u, 1, 1) : cols_step(p, u, 0, 1);
    }
    return rising ? cols_step(p, u, 1, 0) : cols_step(p, u, 0, 0);
}

int64_t piezo_play_process(struct piezo_play *p, int32_t u_q15)
{
    const int32_t u_prev = p->u_prev_q15;
    if (u_q15 == u_prev) {
        return p->acc_q39; /* the update is idempotent */
    }
    p->u_prev_q15 = u_q15;
    p->acc_q39 = bank_step(p, u_q15, u_q15 > u_prev);
    return p->acc_q39;
}
