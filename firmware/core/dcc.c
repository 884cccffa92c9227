/* dcc.c - KP compensation operators and the DCC law; see dcc.h. */
#include "dcc.h"

#include "fixed_q.h"

#include <string.h>

/* The order entries: n2 in the upper half, the operator index in the lower
 * (n_ops <= 4096 < 2^16); as signed integers they sort by n2 first. */
/* The operator index of an order entry (its low 16 bits). On a
 * little-endian core they are the entry's first two bytes: one halfword load
 * (ldrh, post-indexed in a loop) instead of a load and a zero extension; the
 * same value either way. */
static inline uint32_t order_index(const int32_t *entry)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    uint16_t j;
    memcpy(&j, entry, sizeof j);
    return j;
#else
    return (uint16_t)*entry;
#endif
}

static int32_t order_entry(int16_t n2, uint16_t j)
{
    return (int32_t)((uint32_t)(uint16_t)n2 << 16 | j);
}

/* Heap sort of the order entries (init only; no recursion, no allocation). */
static void sift_down(int32_t *a, size_t i, size_t n)
{
    const int32_t x = a[i];
    for (size_t c = 2u * i + 1u; c < n; c = 2u * i + 1u) {
        if (c + 1u < n && a[c + 1u] > a[c]) {
            c++;
        }
        if (a[c] <= x) {
            break;
        }
        a[i] = a[c];
        i = c;
    }
    a[i] = x;
}

static void sort_entries(int32_t *a, size_t n)
{
    for (size_t i = n / 2u; i-- > 0u;) {
        sift_down(a, i, n);
    }
    for (size_t m = n; m-- > 1u;) {
        const int32_t t = a[0];
        a[0] = a[m];
        a[m] = t;
        sift_down(a, 0u, m);
    }
}

enum piezo_err piezo_dcc_init(struct piezo_dcc *dcc, const struct piezo_dcc_coeffs *coeffs,
                              int32_t *psi_q15, int32_t *order, size_t n_state)
{
    if (dcc == NULL || coeffs == NULL || psi_q15 == NULL || order == NULL ||
        coeffs->c_q24 == NULL) {
        return PIEZO_EINVAL;
    }
    dcc->coeffs = NULL;
    const struct piezo_kp_grid *g = &coeffs->grid;
    const enum piezo_err err = piezo_kp_grid_check(g);
    if (err != PIEZO_OK) {
        return err;
    }
    if (n_state < g->n_ops) {
        return PIEZO_ERANGE;
    }
    if (coeffs->g_q24 < 1) {
        return PIEZO_EINVAL;
    }
    dcc->coeffs = coeffs;
    dcc->psum = NULL;
    dcc->psi_q15 = psi_q15;
    dcc->order = order;
    dcc->const_w = 0u;
    dcc->runs = 0u;
    dcc->c_abs_31 = 0u;
    dcc->csum = 0;
    dcc->n1_sorted = 1u;
    dcc->n2_banded = 1u;
    dcc->lex_sorted = 1u;
    for (uint16_t j = 0; j < g->n_ops; j++) {
        order[j] = order_entry(g->n2_q15[j], j);
        if (j > 0u && g->n1_q15[j] < g->n1_q15[j - 1u]) {
            dcc->n1_sorted = 0u;
        }
        if (j > 0u && (g->n1_q15[j] < g->n1_q15[j - 1u] ||
                       (g->n1_q15[j] == g->n1_q15[j - 1u] && g->n2_q15[j] < g->n2_q15[j - 1u]))) {
            dcc->lex_sorted = 0u;
        }
        if ((int32_t)g->n2_q15[j] <= (int32_t)g->nmin_q15 - g->xsat_q15) {
            dcc->n2_banded = 0u;
        }
    }
    sort_entries(order, g->n_ops);
    /* the rows of a grid in (n1, n2) order, for the runs: their first
     * indices (none when there are more than PIEZO_DCC_MAX_ROWS) */
    dcc->n_rows = 0u;
    if (dcc->lex_sorted) {
        uint16_t nr = 0u;
        for (uint16_t j = 0; j < g->n_ops && nr <= PIEZO_DCC_MAX_ROWS; j++) {
            if (j == 0u || g->n1_q15[j] != g->n1_q15[j - 1u]) {
                if (nr < PIEZO_DCC_MAX_ROWS) {
                    dcc->row_start[nr] = j;
                }
                nr++;
            }
        }
        if (nr <= PIEZO_DCC_MAX_ROWS) {
            dcc->row_start[nr] = g->n_ops;
            dcc->n_rows = (uint8_t)nr;
        }
    }
    /* the columns (equal n2) of the order array alike, for the rising runs */
    dcc->n_cols = 0u;
    {
        uint16_t nc = 0u;
        for (uint16_t k = 0; k < g->n_ops && nc <= PIEZO_DCC_MAX_ROWS; k++) {
            if (k == 0u || (order[k] >> 16) != (order[k - 1u] >> 16)) {
                if (nc < PIEZO_DCC_MAX_ROWS) {
                    dcc->col_start[nc] = k;
                }
                nc++;
            }
        }
        if (nc <= PIEZO_DCC_MAX_ROWS) {
            dcc->col_start[nc] = g->n_ops;
            dcc->n_cols = (uint8_t)nc;
        }
    }
    piezo_dcc_reset(dcc);
    return PIEZO_OK;
}

void piezo_dcc_const_weights(struct piezo_dcc *dcc)
{
    const struct piezo_dcc_coeffs *c = dcc->coeffs;
    int64_t csum = 0, kacc = 0, cabs = 0;
    for (uint16_t j = 0; j < c->grid.n_ops; j++) {
        csum += c->c_q24[j];
        cabs += c->c_q24[j] < 0 ? -(int64_t)c->c_q24[j] : c->c_q24[j];
        kacc += (int64_t)dcc->psi_q15[j] * c->c_q24[j];
    }
    dcc->csum = csum;
    /* the runs sum weights in int32: every partial sum of c is at most
     * sum |c_j| in magnitude, so that bound below 2^31 proves it */
    dcc->c_abs_31 = (uint8_t)(cabs <= INT32_MAX);
    dcc->kacc = kacc;
    dcc->const_w = 1u;
    dcc->runs = (uint8_t)(dcc->c_abs_31 && dcc->n_rows != 0u && dcc->n_cols != 0u);
    dcc->n_run = 0u;
    /* the prefix sums, only if every entry is the one these weights give */
    dcc->psum = NULL;
    const int32_t *ps = c->csum_q24;
    if (ps != NULL && dcc->c_abs_31 && dcc->n_rows != 0u && dcc->n_cols != 0u) {
        const uint16_t n = c->grid.n_ops;
        int32_t a = 0, b = 0;
        int ok = ps[0] == 0 && ps[n + 1u] == 0;
        for (uint16_t j = 0; j < n && ok; j++) {
            a += c->c_q24[j];
            b += c->c_q24[(uint16_t)dcc->order[j]];
            ok = ps[j + 1u] == a && ps[n + 2u + j] == b;
        }
        if (ok) {
            dcc->psum = ps;
        }
    }
}

enum piezo_err piezo_dcc_prefix_sums(const struct piezo_dcc *dcc, int32_t *sums, size_t n_sums)
{
    if (dcc == NULL || dcc->coeffs == NULL || sums == NULL) {
        return PIEZO_EINVAL;
    }
    const int32_t *c = dcc->coeffs->c_q24;
    const uint16_t n = dcc->coeffs->grid.n_ops;
    if (n_sums < 2u * ((size_t)n + 1u)) {
        return PIEZO_ERANGE;
    }
    int64_t cabs = 0;
    for (uint16_t j = 0; j < n; j++) {
        cabs += c[j] < 0 ? -(int64_t)c[j] : c[j];
    }
    if (cabs > INT32_MAX) {
        return PIEZO_EINVAL; /* a partial sum could leave int32 */
    }
    int32_t a = 0, b = 0;
    sums[0] = 0;
    sums[n + 1u] = 0;
    for (uint16_t j = 0; j < n; j++) {
        a += c[j];
        b += c[(uint16_t)dcc->order[j]];
        sums[j + 1u] = a;
        sums[n + 2u + j] = b;
    }
    return PIEZO_OK;
}

void piezo_dcc_reset(struct piezo_dcc *dcc)
{
    const struct piezo_kp_grid *g = &dcc->coeffs->grid;
    for (uint16_t j = 0; j < g->n_ops; j++) {
        dcc->psi_q15[j] = 0;
    }
    dcc->kacc = 0;
    dcc->xi_q15 = g->nmin_q15;
    dcc->v_prev_q15 = g->nmin_q15;
    dcc->u_last_q15 = g->nmin_q15;
    dcc->dir = -1;
    dcc->n_run = 0u;
    dcc->cur = 0u;
    dcc->row_cur = 0u;
    dcc->col_cur = 0u;
}

/* First index in [lo, n) of a non-decreasing key whose key exceeds t. */
static uint16_t first_n1_above(const int16_t *key, uint16_t n, int32_t t)
{
    uint16_t lo = 0u, hi = n;
    while (lo < hi) {
        const uint16_t mid = (uint16_t)((lo + hi) >> 1);
        if (key[mid] > t) {
            hi = mid;
        } else {
            lo = (uint16_t)(mid + 1u);
        }
    }
    return lo;
}

static uint16_t first_n2_above(const int32_t *order, uint16_t n, int32_t t)
{
    uint16_t lo = 0u, hi = n;
    while (lo < hi) {
        const uint16_t mid = (uint16_t)((lo + hi) >> 1);
        if ((order[mid] >> 16) > t) {
            hi = mid;
        } else {
            lo = (uint16_t)(mid + 1u);
        }
    }
    return lo;
}

/* First row in [0, n_rows) whose n1 (the key at its first index) exceeds t.
 * From the last tick's row *cur: the input moves less than a row's spacing
 * per tick on a smooth drive, so that row or the one before or after it is
 * the answer (two or three compares); otherwise a binary search over the
 * rows. The same row either way. */
static int32_t first_row_above(const int16_t *key, const uint16_t *row_start, int32_t n_rows, int32_t t,
                               uint8_t *cur)
{
    int32_t k = *cur;
    const int below_ok = k == 0 || key[row_start[k - 1]] <= t;
    const int above_ok = k == n_rows || key[row_start[k]] > t;
    if (below_ok && above_ok) {
        return k;
    }
    if (!below_ok && (k == 1 || key[row_start[k - 2]] <= t)) {
        k--; /* one row down: row k - 1 exceeds t, row k - 2 does not */
    } else if (!above_ok && (k + 1 == n_rows || key[row_start[k + 1]] > t)) {
        k++; /* one row up */
    } else {
        int32_t lo = 0, hi = n_rows;
        while (lo < hi) {
            const int32_t mid = (lo + hi) >> 1;
            if (key[row_start[mid]] > t) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        k = lo;
    }
    *cur = (uint8_t)k;
    return k;
}

/* The same for the columns: the first column (a group of equal n2 in the
 * order array) whose n2 exceeds t, from the last rising tick's column. */
static int32_t first_col_above(const int32_t *order, const uint16_t *col_start, int32_t n_cols, int32_t t,
                               uint8_t *cur)
{
    int32_t k = *cur;
    const int below_ok = k == 0 || (order[col_start[k - 1]] >> 16) <= t;
    const int above_ok = k == n_cols || (order[col_start[k]] >> 16) > t;
    if (below_ok && above_ok) {
        return k;
    }
    if (!below_ok && (k == 1 || (order[col_start[k - 2]] >> 16) <= t)) {
        k--;
    } else if (!above_ok && (k + 1 == n_cols || (order[col_start[k + 1]] >> 16) > t)) {
        k++;
    } else {
        int32_t lo = 0, hi = n_cols;
        while (lo < hi) {
            const int32_t mid = (lo + hi) >> 1;
            if ((order[col_start[mid]] >> 16) > t) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        k = lo;
    }
    *cur = (uint8_t)k;
    return k;
}

/* Store r into [p, end): a run's operators taking its new level. On
 * Thumb-2 two per instruction (strd of r twice; gcc splits it into two str
 * and a loop of seven instructions per pair), four per pass of the loop
 * (round 13: one instruction per operator instead of 1.5), elsewhere one by
 * one. */
static inline void fill_i32(int32_t *p, int32_t *end, int32_t r)
{
#if defined(__thumb2__)
    if (end - p >= 4) {
        int32_t *const last4 = end - 3; /* four fit while p < end - 3 */
        __asm__ volatile("1:\n\t"
                         "strd  %[r], %[r], [%[p]], #8\n\t"
                         "strd  %[r], %[r], [%[p]], #8\n\t"
                         "cmp   %[p], %[l]\n\t"
                         "blo   1b"
                         : [p] "+r"(p)
                         : [r] "r"(r), [l] "r"(last4)
                         : "cc", "memory");
    }
    if (end - p >= 2) { /* at most one pair left */
        __asm__ volatile("strd  %[r], %[r], [%[p]], #8" : [p] "+r"(p) : [r] "r"(r) : "memory");
    }
    if (p < end) {
        *p = r;
    }
#else
    for (; p < end; p++) {
        *p = r;
    }
#endif
}

/* Store r into the operators of order entries [p, end): a rising column's
 * run or block taking its new level. On little-endian Thumb-2 two per pass
 * (the indices by ldrh, post-indexed: three instructions per operator),
 * elsewhere one by one. */
static inline void scatter_i32(int32_t *psi, const int32_t *p, const int32_t *end, int32_t r)
{
#if defined(__thumb2__) && defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    if (end - p >= 2) {
        const int32_t *const last2 = end - 1; /* a pair fits while p < end - 1 */
        uint32_t t0, t1;
        __asm__ volatile("1:\n\t"
                         "ldrh  %[t0], [%[p]], #4\n\t"
                         "ldrh  %[t1], [%[p]], #4\n\t"
                         "str   %[r], [%[psi], %[t0], lsl #2]\n\t"
                         "str   %[r], [%[psi], %[t1], lsl #2]\n\t"
                         "cmp   %[p], %[l]\n\t"
                         "blo   1b"
                         : [p] "+r"(p), [t0] "=&r"(t0), [t1] "=&r"(t1)
                         : [r] "r"(r), [psi] "r"(psi), [l] "r"(last2)
                         : "cc", "memory");
    }
    if (p < end) {
        psi[order_index(p)] = r;
    }
#else
    for (; p < end; p++) {
        psi[order_index(p)] = r;
    }
#endif
}

/* The end of the block of operators equal to b that starts at p in a row
 * (psi[p] == b; psi is non-increasing along the row, so the block is
 * [p, end of it) and everything after it is below b). After a rise most of
 * a row is at one value, so gallop from the row's end (steps 1, 2, 4, ...)
 * to an operator of the block, then bisect the last step. */
static inline int32_t row_block_end(const int32_t *psi, int32_t p, int32_t end, int32_t b)
{
    if (psi[end - 1] == b) {
        return end;
    }
    int32_t hi = end - 1, lo; /* psi[hi] < b = psi[lo] from here on */
    for (int32_t step = 1;; step <<= 1) {
        lo = hi - step;
        if (lo <= p) {
            lo = p;
            break;
        }
        if (psi[lo] == b) {
            break;
        }
        hi = lo;
    }
    for (lo++; lo < hi;) {
        const int32_t mid = (lo + hi) >> 1;
        if (psi[mid] == b) {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    return lo;
}

#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/* The law's output u = sat_q15(rshift_rnd(v C - kacc + yd g, 24)) from the
 * new kacc in r7:r8, v in r4, yd in r1, the instance in ip (round 18: the
 * steps end with it, so the law's tick reads kacc once and needs no frame
 * of its own); u in r0 and u_last_q15. The rounding constant starts the sum
 * (2^23 - kacc, both products by SMLAL); |v C|, |kacc| and |yd g| are each
 * below 2^46 (|C| <= sum |c_j| < 2^31, c_abs_31), so the rounded value fits
 * an int32 and SSAT alone clamps it. Clobbers r2, r3, r5, r6. */
#define DCC_LAW_OUT_MACRO                                                                          \
    "    .macro dcc_law_out\n"                                                                     \
    "    ldr    r5, [ip, #16]\n"         /* C (its low word) */                                    \
    "    ldr    r6, [ip, #0]\n"                                                                    \
    "    rsbs   r2, r7, #0x800000\n"                                                              \
    "    sbc    r3, r8, r8, lsl #1\n"    /* 2^23 - kacc */                                         \
    "    ldr    r6, [r6, #28]\n"         /* g */                                                   \
    "    smlal  r2, r3, r4, r5\n"                                                                  \
    "    smlal  r2, r3, r1, r6\n"                                                                  \
    "    lsrs   r2, r2, #24\n"                                                                    \
    "    orr    r2, r2, r3, lsl #8\n"    /* acc >> 24 */                                           \
    "    ssat   r0, #16, r2\n"                                                                    \
    "    strh   r0, [ip, #36]\n"         /* u_last */                                              \
    "    .endm\n"

/* The band's first line (first_row_above, first_col_above: the first of the
 * lines whose key exceeds t), shared by the falling and the rising step
 * (round 18; the same instructions the two open-coded copies of round 17
 * had): from the last tick's line (the hint, byte \hint of the instance
 * in r0), up to two lines either way one by one, beyond them a bisection
 * over the lines left (at most 5 halvings for 32 lines, where round 16
 * walked a line at a time, 8 instructions a line). r4 the lines' start
 * table, r3 their count, r6 t; \key turns a line's start (a register) into
 * its key. The answer in r2 and the hint; clobbers r3, r9 and \tmp. */
#define DCC_LINE_SEARCH_MACRO                                                                      \
    "    .macro dcc_line_search key, tmp, hint\n"                                                   \
    "    ldrb   r2, [r0, #\\hint]\n"     /* k = the hint */                                          \
    "    cbz    r2, 11f\n"                                                                         \
    "    add    r9, r4, r2, lsl #1\n"                                                              \
    "    ldrh   r9, [r9, #-2]\n"                                                                   \
    "    \\key   r9\n"                                                                              \
    "    cmp    r9, r6\n"                                                                          \
    "    ble    11f\n"                                                                             \
    "    subs   r2, r2, #1\n"            /* line k - 1 exceeds t: the answer is at most k - 1 */   \
    "    beq    12f\n"                                                                             \
    "    add    r9, r4, r2, lsl #1\n"                                                              \
    "    ldrh   r9, [r9, #-2]\n"                                                                   \
    "    \\key   r9\n"                                                                              \
    "    cmp    r9, r6\n"                                                                          \
    "    ble    12f\n"                   /* line k - 2 does not: one line down */                  \
    "    subs   r2, r2, #1\n"                                                                      \
    "    beq    12f\n"                                                                             \
    "    add    r9, r4, r2, lsl #1\n"                                                              \
    "    ldrh   r9, [r9, #-2]\n"                                                                   \
    "    \\key   r9\n"                                                                              \
    "    cmp    r9, r6\n"                                                                          \
    "    ble    12f\n"                   /* two lines down */                                      \
    "    subs   r3, r2, #1\n"            /* line k - 3 exceeds t: bisect over [0, k - 3] */        \
    "    movs   r2, #0\n"                                                                          \
    "    b      14f\n"                                                                             \
    "11: cmp    r2, r3\n"                                                                          \
    "    bge    12f\n"                                                                             \
    "    ldrh   r9, [r4, r2, lsl #1]\n"                                                            \
    "    \\key   r9\n"                                                                              \
    "    cmp    r9, r6\n"                                                                          \
    "    bgt    12f\n"                   /* the hint's line */                                     \
    "    adds   r2, r2, #1\n"            /* line k does not exceed t */                            \
    "    cmp    r2, r3\n"                                                                          \
    "    bge    12f\n"                                                                             \
    "    ldrh   r9, [r4, r2, lsl #1]\n"                                                            \
    "    \\key   r9\n"                                                                              \
    "    cmp    r9, r6\n"                                                                          \
    "    bgt    12f\n"                   /* one line up */                                         \
    "    adds   r2, r2, #1\n"            /* nor k + 1 */                                           \
    "    cmp    r2, r3\n"                                                                          \
    "    bge    12f\n"                                                                             \
    "    ldrh   r9, [r4, r2, lsl #1]\n"                                                            \
    "    \\key   r9\n"                                                                              \
    "    cmp    r9, r6\n"                                                                          \
    "    bgt    12f\n"                   /* two lines up */                                        \
    "    adds   r2, r2, #1\n"            /* nor k + 2: bisect over [k + 3, n] */                   \
    "    b      14f\n"                                                                             \
    "13: add    r9, r2, r3\n"            /* the first line in [r2, r3] exceeding t (line r3 does, \
                                         * or r3 = n) */                                          \
    "    lsrs   r9, r9, #1\n"                                                                      \
    "    ldrh   \\tmp, [r4, r9, lsl #1]\n"                                                         \
    "    \\key   \\tmp\n"                                                                           \
    "    cmp    \\tmp, r6\n"                                                                       \
    "    ite    gt\n"                                                                              \
    "    movgt  r3, r9\n"                                                                          \
    "    addle  r2, r9, #1\n"                                                                      \
    "14: cmp    r2, r3\n"                                                                          \
    "    blt    13b\n"                                                                             \
    "12: strb   r2, [r0, #\\hint]\n"                                                               \
    "    .endm\n"
#endif

/*
 * Falling to v with runs (const_w, n_rows, c_abs_31; docs/kernels-kp.md, "DCC:
 * runs"). In a row (one n1, index order = n2 order) psi is non-increasing
 * in n2, so the operators that move, psi > r(v - n1), are a prefix of the
 * row, and after the update they all hold r: a run. Next tick the run moves
 * as one, (r' - r) * csum, and the operators after it join while psi > r'.
 * Every psi is still written (one store per operator of the run), so
 * readers and the other direction see the state as it is. The rows come
 * from init's row table (row_start): the band's first row by a binary search
 * over the rows, each row's end without scanning its thresholds.
 */
static int64_t dcc_fall_runs(struct piezo_dcc *dcc, int32_t v, int32_t dv)
{
    const struct piezo_kp_grid *g = &dcc->coeffs->grid;
    const int32_t *c = dcc->coeffs->c_q24;
    const int16_t *th = g->n1_q15;
    const uint16_t *rs = dcc->row_start;
    int32_t *psi = dcc->psi_q15;
    const int32_t n_rows = dcc->n_rows;
    const int32_t slope = g->slope_q16, xsat = g->xsat_q15, rmax = g->rmax_q15;
    const struct piezo_dcc_run *old = dcc->run[dcc->cur];
    const struct piezo_dcc_run *old_end = old + dcc->n_run;
    struct piezo_dcc_run *out = dcc->run[dcc->cur ^ 1u];
    struct piezo_dcc_run *out_end = out + PIEZO_DCC_RUNS, *o = out;
    int64_t dk = 0;
    for (int32_t k = first_row_above(th, rs, n_rows, v - xsat, &dcc->row_cur); k < n_rows; k++) {
        const int32_t j = rs[k], end = rs[k + 1];
        const int32_t n1 = th[j];
        const int32_t x = v - n1;
        if (x <= dv) {
            break; /* n1 >= v_prev: psi = 0 by (A) */
        }
        const int32_t r = x >= xsat ? rmax : x <= 0 ? 0 : (x * slope + 32768) >> 16;
        while (old < old_end && old->thr < n1) {
            old++;
        }
        int32_t p = j;
        int32_t csum = 0;
        if (old < old_end && old->thr == n1) {
            /* the run moves as one, then its row's next operators join */
            csum = old->csum;
            p = j + old->k;
            if (r != old->lvl) {
                dk += (int64_t)(r - old->lvl) * csum;
                fill_i32(psi + j, psi + p, r);
            }
            old++;
        } else if (dcc->psum != NULL && psi[j] == rmax) {
            /* a row entering the band (r < rmax here: x < xsat) with its
             * first operators at rmax: they move to r as one block */
            const int32_t e = row_block_end(psi, j, end, rmax);
            csum = dcc->psum[e] - dcc->psum[j];
            dk += (int64_t)(r - rmax) * csum;
            fill_i32(psi + j, psi + e, r);
            p = e;
        } else if (dcc->psum != NULL && end - j >= 3 && psi[j + 1] > r && psi[j + 1] == psi[j + 2]) {
            /* the fall resuming after a short rise, which raised only the
             * row's first operator (its diagonal cell, n1 = n2) above the
             * level the last fall left: the first moves alone, then the
             * block equal to the next as one */
            const int32_t b = psi[j + 1];
            dk += (int64_t)(r - psi[j]) * c[j];
            psi[j] = r;
            const int32_t e = row_block_end(psi, j + 1, end, b);
            csum = dcc->psum[e] - dcc->psum[j];
            dk += (int64_t)(r - b) * (dcc->psum[e] - dcc->psum[j + 1]);
            fill_i32(psi + j + 1, psi + e, r);
            p = e;
        }
        for (; p < end; p++) {
            const int32_t d = r - psi[p]; /* (the int32 difference the sum used already) */
            if (d >= 0) {
                break; /* psi <= r: the rest of the row stays (by its sign: one subs) */
            }
            dk += (int64_t)d * c[p];
            csum += c[p];
            psi[p] = r;
        }
        if (p > j && o < out_end) {
            o->csum = csum; /* field by field: the spare is left alone */
            o->lvl = r;
            o->thr = (int16_t)n1;
            o->k = (uint16_t)(p - j);
            o++;
        }
    }
    dcc->cur ^= 1u;
    dcc->n_run = (uint8_t)(o - out);
    return dk;
}

#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/*
 * Cortex-M4: dcc_fall_runs' row loop in Thumb-2 (round 15), the same
 * integers as the C loop below, which other targets compile and which
 * piezo_dcc_ops_update_c keeps on this one for test_dcc (random walks on
 * L = 10, 20, 30, with and without the prefix sums, both forms compared
 * operator by operator and in the kept sum every tick). gcc's loop keeps
 * about a dozen of the row's values on the stack and reloads them (40 to
 * 60 instructions per row visited, round 14); here the row's state lives
 * in registers and the per-tick constants in a frame of their own, one
 * load each where a row uses them. It does the whole falling step of
 * dcc_ops with runs after the reversal's bookkeeping (piezo_dcc_process,
 * below, jumps here with v in r3 and yd in r1): the band's first row
 * (first_row_above's answer by dcc_line_search: the hint's row or up to
 * two rows below or above it, two to four compares, else a bisection over
 * the rows left, at most 5 halvings for n_rows <= 32, where round 16 walked
 * a row at a time, 8 instructions a row, after a user's step), the rows,
 * the runs out, kacc and v_prev, then the law's output (dcc_law_out, round
 * 18), returned in r0.
 *
 * r4 &row_start[k + 1] once a row is read, r5 psi, r7:r8 kacc (round 18:
 * the moves' products added to it as they are made, no 64-bit add at the
 * end), r9 the old run, r10 the next run out, r11 c; in a row r0 j then p, r1 end, r2 n1,
 * r3 r, lr the run's weight sum; r6, ip scratch.
 * Frame: [sp] th (n1), #4 v_prev, #8 v, #12 xsat, #16 slope, #20 rmax
 * (a row's first five words in one LDM: four in round 16, slope too since round 18),
 * #24 old_end, #28 out, #32 psum, #36 &row_start[n_rows], #40 out_end,
 * #44 th again (the pairs stored by one STRD each, out_end and th read by
 * one LDRD where a run is recorded; round 18),
 * #48 dcc, #52 yd (pushed r0, r1: the step ends with the law's output).
 */
typedef char piezo_dcc_fall_m4_layout_check_t[
    (offsetof(struct piezo_dcc, coeffs) == 0u && offsetof(struct piezo_dcc, psi_q15) == 4u &&
     offsetof(struct piezo_dcc, v_prev_q15) == 34u && offsetof(struct piezo_dcc, n_run) == 43u &&
     offsetof(struct piezo_dcc, cur) == 44u && offsetof(struct piezo_dcc, n_rows) == 46u &&
     offsetof(struct piezo_dcc, kacc) == 24u && offsetof(struct piezo_dcc, row_cur) == 47u &&
     offsetof(struct piezo_dcc, psum) == 52u && offsetof(struct piezo_dcc, row_start) == 56u &&
     offsetof(struct piezo_dcc, run) == 188u && sizeof(struct piezo_dcc_run) == 16u &&
     offsetof(struct piezo_dcc_run, csum) == 0u && offsetof(struct piezo_dcc_run, lvl) == 4u &&
     offsetof(struct piezo_dcc_run, thr) == 8u && offsetof(struct piezo_dcc_run, k) == 10u &&
     PIEZO_DCC_RUNS == 4u && offsetof(struct piezo_dcc_coeffs, grid) == 0u &&
     offsetof(struct piezo_kp_grid, n1_q15) == 0u && offsetof(struct piezo_kp_grid, rmax_q15) == 12u &&
     offsetof(struct piezo_kp_grid, slope_q16) == 16u && offsetof(struct piezo_kp_grid, xsat_q15) == 20u &&
     offsetof(struct piezo_dcc_coeffs, c_q24) == 24u) ? 1 : -1];

static __attribute__((naked, noinline, used)) void dcc_fall_m4(void)
{
    __asm__ volatile(
        DCC_LAW_OUT_MACRO
        DCC_LINE_SEARCH_MACRO
        /* a row's key: n1 at its first index (th in r1) */
        "    .macro dcc_key_n1 reg\n"
        "    ldrsh  \\reg, [r1, \\reg, lsl #1]\n"
        "    .endm\n"
        /* psi[r0 .. r2) = r3 (index bounds, r0 <= r2; four per pass, as
         * fill_i32): the count in r6 (round 18: counted down, the last
         * one to three by the count's two low bits in the flags, 9
         * instructions besides the passes where the end pointer's
         * compares took 11 or 12); clobbers r0, r6 */
        "    .macro dcc_fill\n"
        "    sub    r6, r2, r0\n"
        "    add    r0, r5, r0, lsl #2\n"
        "    subs   r6, r6, #4\n"
        "    blo    2f\n"
        "1:  strd   r3, r3, [r0], #8\n"
        "    strd   r3, r3, [r0], #8\n"
        "    subs   r6, r6, #4\n"
        "    bhs    1b\n"
        "2:  lsls   r6, r6, #31\n"         /* bit 1 of the count to C, bit 0 to N */
        "    it     cs\n"
        "    strdcs r3, r3, [r0], #8\n"
        "    it     mi\n"
        "    strmi  r3, [r0]\n"
        "    .endm\n"
        /* r2 = row_block_end(psi, r0, r1, r6): gallop from the row's end,
         * then bisect; clobbers ip (hi), lr (step, mid) and r1 (round 18:
         * the row's end, read back from row_start after it, one LDRH, where
         * r10 was spilled and reloaded around it) */
        "    .macro dcc_block_end\n"
        "    sub    ip, r1, #1\n"
        "    mov    r2, r1\n"
        "    ldr    r1, [r5, ip, lsl #2]\n"
        "    cmp    r1, r6\n"
        "    beq    9f\n"
        "    mov    lr, #1\n"
        "4:  sub    r2, ip, lr\n"
        "    cmp    r2, r0\n"
        "    ble    5f\n"
        "    ldr    r1, [r5, r2, lsl #2]\n"
        "    cmp    r1, r6\n"
        "    beq    6f\n"
        "    mov    ip, r2\n"
        "    lsl    lr, lr, #1\n"
        "    b      4b\n"
        "5:  mov    r2, r0\n"
        "6:  add    r2, r2, #1\n"
        "7:  cmp    r2, ip\n"
        "    bge    9f\n"
        "    add    lr, r2, ip\n"
        "    asr    lr, lr, #1\n"
        "    ldr    r1, [r5, lr, lsl #2]\n"
        "    cmp    r1, r6\n"
        "    ite    eq\n"
        "    addeq  r2, lr, #1\n"
        "    movne  ip, lr\n"
        "    b      7b\n"
        "9:\n"
        "    .endm\n"

        "    push   {r0, r1, r4-r11, lr}\n"  /* dcc, yd kept for the output */
        "    sub    sp, #48\n"
        "    ldm    r0, {r4, r5}\n"          /* coeffs, psi in one (round 18) */
        "    ldr    r1, [r4, #0]\n"          /* n1 */
        "    ldrsh  r2, [r0, #34]\n"         /* v_prev */
        "    ldr    r6, [r4, #20]\n"         /* xsat */
        "    ldr    r7, [r4, #16]\n"         /* slope */
        "    ldrsh  r8, [r4, #12]\n"         /* rmax */
        "    stm    sp, {r1, r2, r3, r6, r7, r8}\n" /* the frame's first six words in one (v in r3) */
        "    sub    r6, r3, r6\n"            /* t = v - xsat */
        "    ldr    r11, [r4, #24]\n"        /* c */
        "    ldr    r9, [r0, #52]\n"         /* psum */
        "    add    r4, r0, #56\n"           /* row_start */
        "    ldrb   r3, [r0, #46]\n"         /* n_rows */
        "    add    r10, r4, r3, lsl #1\n"
        "    strd   r9, r10, [sp, #32]\n"
        /* the band's first row (first_row_above: the first whose n1 exceeds
         * v - xsat), from the last falling tick's: up to two rows either
         * way one by one, beyond them a bisection (round 17) */
        "    dcc_line_search dcc_key_n1, r7, 47\n" /* k = row_cur, then the answer */
        "    add    r4, r4, r2, lsl #1\n"    /* &row_start[k] */
        "    cmp    r4, r10\n"               /* k = n_rows: no row moves (the flags kept to the test
                                             * below: nothing between sets them; round 18) */
        "    ldrb   r3, [r0, #44]\n"         /* cur */
        "    add    r9, r0, #188\n"
        "    eor    r2, r3, #1\n"
        "    strb   r2, [r0, #44]\n"         /* cur ^= 1 now (round 18: the step reads it no more) */
        "    add    r10, r9, r2, lsl #6\n"   /* out = run[cur ^ 1] */
        "    add    r9, r9, r3, lsl #6\n"    /* old = run[cur] */
        "    add    r2, r10, #64\n"          /* out_end */
        "    ldrb   r3, [r0, #43]\n"         /* n_run */
        "    add    r3, r9, r3, lsl #4\n"    /* old_end */
        "    strd   r3, r10, [sp, #24]\n"    /* old_end, out */
        "    strd   r2, r1, [sp, #40]\n"     /* out_end, th: both by one LDRD where a run is recorded (round 18) */
        "    ldrd   r7, r8, [r0, #24]\n"     /* kacc: the moves add to it (round 18) */
        "    bhs    .Ldf_done\n"

        ".Ldf_row:\n"
        "    ldrh   r0, [r4], #2\n"          /* j */
        "    ldrh   r1, [r4]\n"              /* end */
        "    ldm    sp, {r2, r3, r6, ip, lr}\n" /* th, v_prev, v, xsat, slope in one (round 18:
                                             * slope without a load of its own; xsat unused) */
        "    ldrsh  r2, [r2, r0, lsl #1]\n"  /* n1 */
        "    cmp    r2, r3\n"
        "    bge    .Ldf_done\n"             /* n1 >= v_prev (x <= dv): psi = 0 by (A) */
        /* r = 0 for x <= 0, else (x slope + 2^15) >> 16: x clamped at 0
         * by one BIC gives 0 there too. x < xsat on every row visited (the
         * band starts at the first n1 above v - xsat, n1 rises from row
         * to row), so the C step's rmax case is never taken here (round 18:
         * 5 instructions a row where the compares, branches and the
         * slope's load took 10) */
        "    sub    r3, r6, r2\n"            /* x = v - n1 */
        "    bic    r3, r3, r3, asr #31\n"   /* max(x, 0) */
        "    mul    r3, r3, lr\n"
        "    add    r3, r3, #32768\n"
        "    asrs   r3, r3, #16\n"
        "    ldr    lr, [sp, #24]\n"         /* old_end */
        ".Ldf_old:\n"
        "    cmp    r9, lr\n"
        "    bhs    .Ldf_norun\n"
        "    ldrsh  ip, [r9, #8]\n"
        "    cmp    ip, r2\n"
        "    bge    .Ldf_old_ge\n"
        "    add    r9, r9, #16\n"
        "    b      .Ldf_old\n"
        ".Ldf_old_ge:\n"
        "    bne    .Ldf_norun\n"
        /* the row's run moves as one */
        "    ldrd   lr, ip, [r9], #16\n"     /* csum, lvl (round 18: one LDRD) */
        "    ldrh   r2, [r9, #-6]\n"         /* k */
        "    add    r2, r0, r2\n"            /* p = j + k */
        "    cmp    r3, ip\n"
        "    beq    .Ldf_run_same\n"
        "    sub    ip, r3, ip\n"
        "    smlal  r7, r8, ip, lr\n"
        "    dcc_fill\n"
        ".Ldf_run_same:\n"
        "    mov    r0, r2\n"
        /* the row's next operators join while psi > r (round 18: the run's
         * path falls through to them, the other rows' paths branch here;
         * the rows without a run or a block at rmax, .Ldf_plain, out of line) */
        ".Ldf_scan:\n"
        "    cmp    r0, r1\n"
        "    bge    .Ldf_scan_end\n"
        ".Ldf_scan_op:\n"
        "    ldr    ip, [r5, r0, lsl #2]\n"
        "    subs   ip, r3, ip\n"
        "    bge    .Ldf_scan_end\n"         /* psi <= r: the rest of the row stays */
        "    ldr    r2, [r11, r0, lsl #2]\n"
        "    smlal  r7, r8, ip, r2\n"
        "    add    lr, lr, r2\n"
        "    str    r3, [r5, r0, lsl #2]\n"
        "    adds   r0, r0, #1\n"
        "    cmp    r0, r1\n"
        "    blt    .Ldf_scan_op\n"
        ".Ldf_scan_end:\n"
        "    ldrh   r1, [r4, #-2]\n"         /* j */
        "    subs   r2, r0, r1\n"            /* operators that moved */
        "    ble    .Ldf_next\n"
        "    ldrd   ip, r6, [sp, #40]\n"     /* out_end, th */
        "    cmp    r10, ip\n"
        "    bhs    .Ldf_next\n"
        "    ldrsh  ip, [r6, r1, lsl #1]\n"  /* n1 */
        "    pkhbt  ip, ip, r2, lsl #16\n"   /* thr and k as one word (round 16) */
        "    strd   lr, r3, [r10], #8\n"     /* csum, lvl */
        "    str    ip, [r10], #8\n"         /* thr, k; the spare left alone */
        ".Ldf_next:\n"
        "    ldr    ip, [sp, #36]\n"
        "    cmp    r4, ip\n"
        "    blo    .Ldf_row\n"

        ".Ldf_done:\n"
        "    ldrd   ip, r1, [sp, #48]\n"     /* dcc, yd */
        "    ldr    r0, [sp, #28]\n"
        "    sub    r0, r10, r0\n"
        "    lsr    r0, r0, #4\n"
        "    strb   r0, [ip, #43]\n"         /* n_run */
        "    strd   r7, r8, [ip, #24]\n"     /* kacc (runs: const_w) */
        "    ldr    r4, [sp, #8]\n"
        "    strh   r4, [ip, #34]\n"         /* v_prev = v */
        "    dcc_law_out\n"
        "    add    sp, #48\n"
        "    pop    {r1, r2, r4-r11, pc}\n"

        ".Ldf_norun:\n"
        "    ldr    r6, [sp, #32]\n"         /* psum */
        "    cbnz   r6, 29f\n"               /* (one instruction less than CMP, BEQ) */
        "    b      .Ldf_plain\n"
        "29: ldr    r6, [r5, r0, lsl #2]\n"  /* psi[j] */
        "    ldr    lr, [sp, #20]\n"
        "    cmp    r6, lr\n"
        "    bne    .Ldf_diag\n"
        /* a row entering the band with its first operators at rmax */
        "    dcc_block_end\n"
        "    ldrh   r1, [r4]\n"              /* end */
        "    ldr    ip, [sp, #32]\n"
        "    ldr    lr, [ip, r2, lsl #2]\n"
        "    ldr    ip, [ip, r0, lsl #2]\n"
        "    sub    lr, lr, ip\n"            /* csum = psum[e] - psum[j] */
        "    sub    ip, r3, r6\n"
        "    smlal  r7, r8, ip, lr\n"        /* (r - rmax) csum */
        "    dcc_fill\n"
        "    mov    r0, r2\n"
        "    b      .Ldf_scan\n"

        ".Ldf_diag:\n"                        /* r6 = psi[j] */
        "    sub    ip, r1, r0\n"
        "    cmp    ip, #3\n"
        "    blt    .Ldf_plain\n"
        "    add    ip, r5, r0, lsl #2\n"
        "    ldrd   lr, ip, [ip, #4]\n"      /* psi[j + 1], psi[j + 2] */
        "    cmp    lr, r3\n"
        "    ble    .Ldf_plain\n"
        "    cmp    lr, ip\n"
        "    bne    .Ldf_plain\n"
        /* the first operator alone, then the block equal to the next */
        "    sub    r6, r3, r6\n"
        "    ldr    ip, [r11, r0, lsl #2]\n"
        "    smlal  r7, r8, r6, ip\n"        /* (r - psi[j]) c[j] */
        "    str    r3, [r5, r0, lsl #2]\n"
        "    mov    r6, lr\n"                /* b */
        "    add    r0, r0, #1\n"            /* from j + 1 */
        "    dcc_block_end\n"
        "    sub    r6, r3, r6\n"            /* r - b */
        "    ldr    ip, [sp, #32]\n"
        "    ldr    lr, [ip, r2, lsl #2]\n"  /* psum[e] */
        "    add    ip, ip, r0, lsl #2\n"
        "    ldr    r1, [ip]\n"              /* psum[j + 1] */
        "    sub    r1, lr, r1\n"
        "    smlal  r7, r8, r6, r1\n"        /* (r - b) (psum[e] - psum[j + 1]) */
        "    ldr    ip, [ip, #-4]\n"
        "    sub    lr, lr, ip\n"            /* csum = psum[e] - psum[j] */
        "    ldrh   r1, [r4]\n"              /* end */
        "    dcc_fill\n"
        "    mov    r0, r2\n"
        "    b      .Ldf_scan\n"

        ".Ldf_plain:\n"
        "    mov    lr, #0\n"
        "    b      .Ldf_scan\n"            /* (round 18: out of line, the run path falls through) */
        "    .purgem dcc_fill\n"
        "    .purgem dcc_block_end\n"
        "    .purgem dcc_law_out\n"
        "    .purgem dcc_line_search\n"
        "    .purgem dcc_key_n1\n");
}

/*
 * Cortex-M4: dcc_rise_runs in Thumb-2 (round 15), the same integers; test_dcc
 * compares it with the C step as the falling one. A column's operators are
 * reached through the order array, so the column's bounds, its run's start
 * and the scans are pointers into it (an entry's low halfword the index, the
 * high one n2); the prefix sums of the n2 order are read at the same offset
 * from an order pointer (psum + n_ops + 1 - order, in bytes). The band's
 * first column is found as the falling step's first row (the hint, up to
 * two columns either way, else a bisection; round 17; the same macro since
 * round 18). Entered and left as the falling step (v in r3, yd in r1, the
 * law's output in r0).
 *
 * r4 &col_start[k + 1] once a column is read, r5 psi, r7:r8 kacc, r9 the old
 * run, r11 c; in a column r0 the position (pointer), r1 the column's end, r2
 * n2 then scratch, r3 r, r6 q (where the moving suffix starts), lr the
 * run's weight sum; r10, ip scratch. Frame: [sp] order, #4 v, #8 xsat, #12
 * slope, #16 rmax, #24 psum, #32 &col_start[n_cols], #36 the sums' offset,
 * #40 out, #44 the next run out, #48 out_end, #52 old_end (in pairs: one
 * LDRD per run out and at the end, one STRD each at the start, round 18),
 * #64 dcc, #68 yd (#20, #28, #56, #60 unused). A run's n2 is read back from the column's last
 * order entry (its high half) when the run is recorded, not kept per column.
 */
typedef char piezo_dcc_rise_m4_layout_check_t[
    (offsetof(struct piezo_dcc, order) == 8u && offsetof(struct piezo_dcc, n2_banded) == 41u &&
     offsetof(struct piezo_dcc, n_cols) == 48u && offsetof(struct piezo_dcc, col_cur) == 49u &&
     offsetof(struct piezo_dcc, col_start) == 122u && offsetof(struct piezo_kp_grid, n_ops) == 8u) ? 1 : -1];

static __attribute__((naked, noinline, used)) void dcc_rise_m4(void)
{
    __asm__ volatile(
        DCC_LAW_OUT_MACRO
        DCC_LINE_SEARCH_MACRO
        /* a column's key: n2 at its first order position (order in r10) */
        "    .macro dcc_key_n2 reg\n"
        "    add    \\reg, r10, \\reg, lsl #2\n"
        "    ldrsh  \\reg, [\\reg, #2]\n"
        "    .endm\n"
        /* ord entries [r0, r2) moved to r3 one by one: kacc (r7:r8) += (r3 -
         * psi) c, lr += c; then to done (written once for both run kinds) */
        "    .macro dcc_each_move done\n"
        ".Lmv\\@:\n"
        "    cmp    r0, r2\n"
        "    bhs    \\done\n"
        "    ldrh   ip, [r0], #4\n"
        "    ldr    r10, [r5, ip, lsl #2]\n"
        "    sub    r10, r3, r10\n"
        "    str    r3, [r5, ip, lsl #2]\n"
        "    ldr    ip, [r11, ip, lsl #2]\n"
        "    smlal  r7, r8, r10, ip\n"
        "    add    lr, lr, ip\n"
        "    b      .Lmv\\@\n"
        "    .endm\n"
        /* psi[ord entries [p, r1)] = r3, two per pass (as scatter_i32);
         * clobbers p, b (the last pair's bound), t0, t1 */
        "    .macro dcc_scatter p, b, t0, t1\n"
        "    sub    \\b, r1, #4\n"
        "    cmp    \\p, \\b\n"
        "    bhs    2f\n"
        "1:  ldrh   \\t0, [\\p], #4\n"
        "    ldrh   \\t1, [\\p], #4\n"
        "    str    r3, [r5, \\t0, lsl #2]\n"
        "    str    r3, [r5, \\t1, lsl #2]\n"
        "    cmp    \\p, \\b\n"
        "    blo    1b\n"
        "2:  cmp    \\p, r1\n"
        "    bhs    3f\n"
        "    ldrh   \\t0, [\\p]\n"
        "    str    r3, [r5, \\t0, lsl #2]\n"
        "3:\n"
        "    .endm\n"

        "    push   {r0, r1, r4-r11, lr}\n"  /* dcc, yd kept for the output */
        "    sub    sp, #64\n"
        "    ldm    r0, {r1, r5, r10}\n"     /* coeffs, psi, order in one (round 18; v in r3) */
        "    mov    r2, r10\n"
        "    ldr    r6, [r1, #20]\n"         /* xsat */
        "    ldr    r7, [r1, #16]\n"         /* slope */
        "    ldrsh  r8, [r1, #12]\n"         /* rmax */
        "    stm    sp, {r2, r3, r6, r7, r8}\n" /* the frame's first five words in one */
        "    ldr    r11, [r1, #24]\n"        /* c */
        "    ldr    lr, [r0, #52]\n"         /* psum */
        "    str    lr, [sp, #24]\n"
        "    ldrh   r2, [r1, #8]\n"          /* n_ops */
        "    add    lr, lr, r2, lsl #2\n"
        "    add    lr, lr, #4\n"
        "    sub    lr, lr, r10\n"           /* psum + n_ops + 1 - order (bytes) */
        "    add    r4, r0, #122\n"          /* col_start */
        "    ldrb   r3, [r0, #48]\n"         /* n_cols */
        "    add    r8, r4, r3, lsl #1\n"    /* &col_start[n_cols], kept past the search */
        "    strd   r8, lr, [sp, #32]\n"
        /* the band's first column (first_col_above: the first whose n2
         * exceeds v_prev - xsat; every column without n2_banded), from the
         * last rising tick's: up to two columns either way one by one,
         * beyond them a bisection (round 17) */
        "    movs   r2, #0\n"
        "    ldrb   lr, [r0, #41]\n"         /* n2_banded */
        "    cmp    lr, #0\n"
        "    beq    19f\n"
        "    ldrsh  lr, [r0, #34]\n"         /* v_prev */
        "    sub    r6, lr, r6\n"            /* t = v_prev - xsat */
        "    dcc_line_search dcc_key_n2, lr, 49\n" /* k = col_cur, then the answer */
        "19: add    r4, r4, r2, lsl #1\n"    /* &col_start[k] */
        "    cmp    r4, r8\n"                /* k = n_cols: no column moves (the flags kept to the
                                             * test below: nothing between sets them; round 18) */
        "    ldrh   r1, [r4]\n"
        "    add    r1, r10, r1, lsl #2\n"   /* its first position (round 18: then each column's from the last one's end) */
        "    ldrb   r3, [r0, #44]\n"         /* cur */
        "    add    r9, r0, #188\n"
        "    eor    r2, r3, #1\n"
        "    strb   r2, [r0, #44]\n"         /* cur ^= 1 now (round 18: the step reads it no more) */
        "    add    r10, r9, r2, lsl #6\n"   /* out = run[cur ^ 1] */
        "    add    r9, r9, r3, lsl #6\n"    /* old = run[cur] */
        "    add    r2, r10, #64\n"          /* out_end */
        "    ldrb   r3, [r0, #43]\n"         /* n_run */
        "    add    r3, r9, r3, lsl #4\n"    /* old_end */
        "    strd   r10, r10, [sp, #40]\n"   /* out, the next run out */
        "    strd   r2, r3, [sp, #48]\n"     /* out_end, old_end (round 18) */
        "    ldrd   r7, r8, [r0, #24]\n"     /* kacc: the moves add to it (round 18) */
        "    bhs    .Ldr_done\n"

        ".Ldr_col:\n"                         /* r1: the column's first position (the last one's end) */
        "    mov    r0, r1\n"
        "    ldrh   r1, [r4, #2]!\n"         /* end */
        "    ldm    sp, {r2, r3, ip, lr}\n"  /* order, v, xsat, slope in one (round 16; slope since
                                             * round 18: no load of its own) */
        "    add    r1, r2, r1, lsl #2\n"
        "    ldrsh  r2, [r0, #2]\n"          /* n2 */
        "    subs   r3, r3, r2\n"            /* x = v - n2 */
        "    ble    .Ldr_done\n"             /* n2 >= v from here on: r = 0 */
        "    cmp    r3, ip\n"
        "    bge    .Ldr_sat\n"
        "    mul    r3, r3, lr\n"
        "    add    r3, r3, #32768\n"
        "    asrs   r3, r3, #16\n"
        "    b      .Ldr_ridge\n"
        ".Ldr_sat:\n"
        "    ldr    r3, [sp, #16]\n"
        ".Ldr_ridge:\n"
        "    ldr    lr, [sp, #52]\n"         /* old_end */
        ".Ldr_old:\n"
        "    cmp    r9, lr\n"
        "    bhs    .Ldr_norun\n"
        "    ldrsh  ip, [r9, #8]\n"
        "    cmp    ip, r2\n"
        "    bge    .Ldr_old_ge\n"
        "    add    r9, r9, #16\n"
        "    b      .Ldr_old\n"
        ".Ldr_old_ge:\n"
        "    bne    .Ldr_norun\n"
        /* the column's run moves as one */
        "    ldrd   lr, ip, [r9], #16\n"     /* csum, lvl (round 18: one LDRD) */
        "    ldrh   r2, [r9, #-6]\n"         /* k */
        "    sub    r2, r1, r2, lsl #2\n"    /* q: the run's first position */
        "    cmp    r3, ip\n"
        "    beq    .Ldr_join\n"
        "    sub    ip, r3, ip\n"
        "    smlal  r7, r8, ip, lr\n"
        "    mov    r6, r2\n"
        "    dcc_scatter r6, r0, ip, r10\n"
        "    ldrh   r0, [r4, #-2]\n"         /* pos again */
        "    ldr    ip, [sp, #0]\n"
        "    add    r0, ip, r0, lsl #2\n"
        ".Ldr_join:\n"                        /* the operators before the run join */
        "    mov    r6, r2\n"
        "    cmp    r6, r0\n"
        "    bls    .Ldr_rec\n"
        "20: ldrh   ip, [r6, #-4]!\n"
        "    ldr    r10, [r5, ip, lsl #2]\n"
        "    subs   r10, r3, r10\n"
        "    ble    21f\n"                   /* psi >= r */
        "    str    r3, [r5, ip, lsl #2]\n"
        "    ldr    ip, [r11, ip, lsl #2]\n"
        "    smlal  r7, r8, r10, ip\n"
        "    add    lr, lr, ip\n"
        "    cmp    r6, r0\n"
        "    bhi    20b\n"
        "    b      .Ldr_rec\n"
        "21: add    r6, r6, #4\n"
        "    b      .Ldr_rec\n"

        ".Ldr_norun:\n"
        /* operators that do not move, then (a suffix) all that do */
        "22: cmp    r0, r1\n"
        "    bhs    .Ldr_next\n"            /* none moves: no run out (round 17) */
        "    ldrh   ip, [r0]\n"
        "    ldr    r10, [r5, ip, lsl #2]\n" /* kept: the first mover's psi (round 18) */
        "    cmp    r10, r3\n"
        "    blt    23f\n"
        "    add    r0, r0, #4\n"
        "    b      22b\n"
        "23: mov    r6, r0\n"                /* q */
        "    ldr    r2, [sp, #24]\n"         /* psum */
        "    cbnz   r2, 29f\n"               /* (one instruction less than CMP, BEQ) */
        "    mov    r2, r1\n"                /* no prefix sums: z = end */
        "    b      .Ldr_each0\n"           /* (r0 < r1 here) */
        "29: mov    r2, r1\n"                /* z: from z on at 0 */
        "    ldrh   ip, [r1, #-4]\n"
        "    ldr    ip, [r5, ip, lsl #2]\n"
        "    cmp    ip, #0\n"
        "    bne    .Ldr_each0\n"
        /* its last operators at 0: their first by bisection (none when
         * the first mover, its psi still in r10, is at 0) */
        "    mov    r2, r0\n"
        "    cmp    r10, #0\n"
        "    beq    25f\n"
        "    add    r2, r0, #4\n"
        "    sub    r10, r1, #4\n"
        "24: cmp    r2, r10\n"
        "    bhs    25f\n"
        "    sub    ip, r10, r2\n"
        "    lsr    ip, ip, #3\n"
        "    add    ip, r2, ip, lsl #2\n"    /* mid */
        "    ldrh   lr, [ip]\n"
        "    ldr    lr, [r5, lr, lsl #2]\n"
        "    cmp    lr, #0\n"
        "    ite    eq\n"
        "    moveq  r10, ip\n"
        "    addne  r2, ip, #4\n"
        "    b      24b\n"
        "25: ldr    ip, [sp, #36]\n"
        "    ldr    lr, [r1, ip]\n"
        "    ldr    ip, [r2, ip]\n"
        "    sub    lr, lr, ip\n"            /* csum = their weights' sum */
        "    smlal  r7, r8, r3, lr\n"        /* r csum */
        /* [e, z) one by one first, then the block [z, end) is stored with
         * z and e as the scatter's pointer and bound (both dead after it):
         * no spill of r4 and r9 around it (round 17, 4 per such column) */
        "26: dcc_each_move 27f\n"
        "27:\n"
        "    dcc_scatter r2, r0, ip, r10\n"
        "    b      .Ldr_rec\n"
        ".Ldr_each0:\n"
        "    mov    lr, #0\n"                /* the run's weight sum (the zero block sets its own) */
        ".Ldr_each:\n"                        /* [e, z) move one by one */
        "    dcc_each_move .Ldr_rec\n"

        ".Ldr_rec:\n"                         /* the run out: [q, end) */
        "    subs   r2, r1, r6\n"            /* (two positions in one array: no overflow) */
        "    ble    .Ldr_next\n"
        "    ldrd   r10, ip, [sp, #44]\n"    /* the next run out, out_end */
        "    cmp    r10, ip\n"
        "    bhs    .Ldr_next\n"
        "    ldrsh  ip, [r1, #-2]\n"         /* n2: the column's last entry's high half (round 18) */
        "    pkhbt  ip, ip, r2, lsl #14\n"   /* thr and k (r2 = 4 k) as one word (round 16) */
        "    strd   lr, r3, [r10], #8\n"     /* csum, lvl */
        "    str    ip, [r10], #8\n"         /* thr, k; the spare left alone */
        "    str    r10, [sp, #44]\n"
        ".Ldr_next:\n"
        "    ldr    ip, [sp, #32]\n"
        "    cmp    r4, ip\n"
        "    blo    .Ldr_col\n"

        ".Ldr_done:\n"
        "    ldrd   ip, r1, [sp, #64]\n"     /* dcc, yd */
        "    ldrd   r2, r0, [sp, #40]\n"     /* out, the next run out */
        "    sub    r0, r0, r2\n"
        "    lsr    r0, r0, #4\n"
        "    strb   r0, [ip, #43]\n"         /* n_run */
        "    strd   r7, r8, [ip, #24]\n"     /* kacc */
        "    ldr    r4, [sp, #4]\n"
        "    strh   r4, [ip, #34]\n"         /* v_prev = v */
        "    dcc_law_out\n"
        "    add    sp, #64\n"
        "    pop    {r1, r2, r4-r11, pc}\n"
        "    .purgem dcc_scatter\n"
        "    .purgem dcc_each_move\n"
        "    .purgem dcc_law_out\n"
        "    .purgem dcc_line_search\n"
        "    .purgem dcc_key_n2\n");
}
#endif

/*
 * Rising to v with runs: in a column (one n2; its order positions by index,
 * i.e. by n1) psi is non-increasing in n1, so the operators that move,
 * psi < r(v - n2), are the last ones of the column: a run, as falling. A
 * column without a run is scanned forward: past the first operator that
 * moves, all the others move too.
 */
static int64_t dcc_rise_runs(struct piezo_dcc *dcc, int32_t v)
{
    const struct piezo_kp_grid *g = &dcc->coeffs->grid;
    const int32_t *c = dcc->coeffs->c_q24;
    const int32_t *ord = dcc->order;
    const uint16_t *cs = dcc->col_start;
    int32_t *psi = dcc->psi_q15;
    const int32_t n_cols = dcc->n_cols;
    const int32_t slope = g->slope_q16, xsat = g->xsat_q15, rmax = g->rmax_q15;
    const struct piezo_dcc_run *old = dcc->run[dcc->cur];
    const struct piezo_dcc_run *old_end = old + dcc->n_run;
    struct piezo_dcc_run *out = dcc->run[dcc->cur ^ 1u];
    struct piezo_dcc_run *out_end = out + PIEZO_DCC_RUNS, *o = out;
    int64_t dk = 0;
    int32_t k = dcc->n2_banded ? first_col_above(ord, cs, n_cols, dcc->v_prev_q15 - xsat, &dcc->col_cur) : 0;
    for (; k < n_cols; k++) {
        const int32_t pos = cs[k], end = cs[k + 1];
        const int32_t n2 = ord[pos] >> 16;
        const int32_t x = v - n2;
        if (x <= 0) {
            break; /* n2 >= v from here on: r = 0 */
        }
        const int32_t r = x >= xsat ? rmax : (x * slope + 32768) >> 16;
        while (old < old_end && old->thr < n2) {
            old++;
        }
        int32_t q;
        int32_t csum = 0;
        if (old < old_end && old->thr == n2) {
            csum = old->csum;
            q = end - old->k; /* the run: positions q .. end-1 */
            if (r != old->lvl) {
                dk += (int64_t)(r - old->lvl) * csum;
                scatter_i32(psi, ord + q, ord + end, r);
            }
            old++;
            while (q > pos) { /* the column's operators before the run join */
                const int32_t jj = (uint16_t)ord[q - 1];
                const int32_t d = r - psi[jj];
                if (d <= 0) {
                    break; /* psi >= r (by the sign of d: one subs) */
                }
                dk += (int64_t)d * c[jj];
                csum += c[jj];
                psi[jj] = r;
                q--;
            }
        } else {
            int32_t e = pos;
            /* operators that do not move, then (a suffix) all that do */
            for (; e < end && psi[(uint16_t)ord[e]] >= r; e++) {
            }
            q = e;
            int32_t z = end; /* from z on the column's operators are at 0 */
            if (dcc->psum != NULL && e < end && psi[(uint16_t)ord[end - 1]] == 0) {
                /* its last operators at 0 (psi is non-increasing along the
                 * column) move to r at once: their first by bisection (none
                 * when the first that moves is at 0), their weights' sum from
                 * the prefix sums */
                int32_t lo = e, hi = e;
                if (psi[(uint16_t)ord[e]] != 0) {
                    lo = e + 1;
                    hi = end - 1;
                }
                while (lo < hi) {
                    const int32_t mid = (lo + hi) >> 1;
                    if (psi[(uint16_t)ord[mid]] == 0) {
                        hi = mid;
                    } else {
                        lo = mid + 1;
                    }
                }
                z = lo;
                const int32_t *pc = dcc->psum + dcc->coeffs->grid.n_ops + 1;
                const int32_t zs = pc[end] - pc[z];
                dk += (int64_t)r * zs;
                csum = zs;
                scatter_i32(psi, ord + z, ord + end, r);
            }
            for (; e < z; e++) {
                const int32_t jj = (uint16_t)ord[e];
                dk += (int64_t)(r - psi[jj]) * c[jj];
                csum += c[jj];
                psi[jj] = r;
            }
        }
        if (q < end && o < out_end) {
            o->csum = csum; /* field by field: the spare is left alone */
            o->lvl = r;
            o->thr = (int16_t)n2;
            o->k = (uint16_t)(end - q);
            o++;
        }
    }
    dcc->cur ^= 1u;
    dcc->n_run = (uint8_t)(o - out);
    return dk;
}

/*
 * Advance the operators with v; sum_j psi_j c_j kept in kacc (const_w).
 *
 * psi_j is the KP operator (dcc.h): rising psi = max(psi, r(v - n2)),
 * falling psi = min(psi, r(v - n1)), Psi_j = v - psi_j. Only operators that
 * can move are visited (docs/kernels-kp.md, "DCC: work per tick"), by two
 * invariants that hold after every update from reset (v_prev the last input):
 *   (A) psi_j > 0 implies n1_j < v_prev;
 *   (B) psi_j < rmax implies n2_j > v_prev - xsat (given n2_j > nmin - xsat
 *       for every operator, which init records as n2_banded).
 * Falling to v: a move needs psi > 0 (n1 < v_prev by A) and r(v - n1) < rmax
 * (n1 > v - xsat); with n1 non-decreasing that is one index range.
 * Rising to v: a move needs r(v - n2) > 0 (n2 < v) and psi < rmax
 * (n2 > v_prev - xsat by B); one range of the n2 order.
 */
static __attribute__((noinline)) void dcc_ops(struct piezo_dcc *dcc, int16_t v_q15)
{
    const struct piezo_kp_grid *g = &dcc->coeffs->grid;
    const int32_t *c = dcc->coeffs->c_q24;
    int32_t *psi = dcc->psi_q15;
    const uint16_t n = g->n_ops;
    const int32_t v = v_q15;
    const int32_t slope = g->slope_q16, xsat = g->xsat_q15, rmax = g->rmax_q15;
    const int32_t dv = v - dcc->v_prev_q15;
    int64_t dk = 0;

    if (dv == 0) {
        return;
    }
    const int8_t dir = dv > 0 ? 1 : -1;
    if (dir != dcc->dir) { /* reversal: where it happened (kept for the record) */
        dcc->xi_q15 = dcc->v_prev_q15;
        dcc->dir = dir;
        dcc->n_run = 0u; /* the runs are the other direction's */
    }
    if (dcc->const_w && dcc->n_rows != 0u && dcc->n_cols != 0u && dcc->c_abs_31) {
        dk = dir > 0 ? dcc_rise_runs(dcc, v) : dcc_fall_runs(dcc, v, dv);
        dcc->v_prev_q15 = v_q15;
        dcc->kacc += dk; /* the runs need const_w */
        return;
    }
    /* Operators with the same threshold share x and the ridge r: r is
     * computed once per threshold, each operator then costs a compare (and
     * the update if it moves). */
    if (dir > 0) {
        const int32_t *ord = dcc->order;
        uint16_t k = dcc->n2_banded ? first_n2_above(ord, n, dcc->v_prev_q15 - xsat) : 0u;
        while (k < n) {
            int32_t e = ord[k];
            const int32_t n2 = e >> 16;
            const int32_t x = v - n2;
            if (x <= 0) {
                break; /* n2 >= v from here on: r = 0 */
            }
            const int32_t r = x >= xsat ? rmax : (x * slope + 32768) >> 16;
            for (;;) {
                const uint32_t j = (uint16_t)e;
                const int32_t p = psi[j];
                if (r > p) {
                    psi[j] = r;
                    dk += (int64_t)(r - p) * c[j];
                }
                if (++k >= n) {
                    break;
                }
                e = ord[k];
                if ((e >> 16) != n2) {
                    break;
                }
            }
        }
    } else {
        const int16_t *th = g->n1_q15;
        uint16_t j = 0u;
        int32_t stop = INT32_MIN; /* unsorted n1: visit every operator */
        if (dcc->n1_sorted) {
            j = first_n1_above(th, n, v - xsat);
            stop = dv; /* x <= dv: n1 >= v_prev, psi = 0 by (A), and so on */
        }
        while (j < n) {
            const int32_t n1 = th[j];
            const int32_t x = v - n1;
            if (x <= stop) {
                break;
            }
            const int32_t r = x >= xsat ? rmax : x <= 0 ? 0 : (x * slope + 32768) >> 16;
            for (;;) {
                const int32_t p = psi[j];
                if (r < p) {
                    psi[j] = r;
                    dk += (int64_t)(r - p) * c[j];
                }
                if (++j >= n || th[j] != n1) {
                    break;
                }
            }
        }
    }
    dcc->v_prev_q15 = v_q15;
    if (dcc->const_w) {
        dcc->kacc += dk;
    }
}

void piezo_dcc_ops_update_c(struct piezo_dcc *dcc, int16_t v_q15)
{
    dcc_ops(dcc, v_q15);
}

/* The law's output from sum_j Psi_j c_j (Q39): the feedthrough, rounded and
 * saturated; kept as the next tick's input. */
static inline __attribute__((always_inline)) int16_t dcc_out(struct piezo_dcc *dcc, int64_t acc,
                                                             int16_t yd_q15)
{
    acc += (int64_t)yd_q15 * dcc->coeffs->g_q24;
    const int16_t u = piezo_sat_q15_rnd24(acc);
    dcc->u_last_q15 = u;
    return u;
}

/* The law's tick with the C kernels: the operators (dcc_ops, which also
 * takes the runs), then the sum. */
static inline __attribute__((always_inline)) int16_t process_c(struct piezo_dcc *dcc, int16_t yd_q15)
{
    const int16_t v = dcc->u_last_q15;
    if (v != dcc->v_prev_q15) { /* (dcc_ops returns at once then; its call is saved) */
        dcc_ops(dcc, v);
    }
    /* sum_j Psi_j c_j = sum_j (v - psi_j) c_j = v C - sum_j psi_j c_j */
    int64_t acc;
    if (dcc->runs) {
        /* |C| <= sum |c_j| < 2^31 (c_abs_31): one 32 x 32 product */
        acc = (int64_t)v * (int32_t)dcc->csum - dcc->kacc;
    } else if (dcc->const_w) {
        acc = (int64_t)v * dcc->csum - dcc->kacc;
    } else {
        const int32_t *c = dcc->coeffs->c_q24;
        const int32_t *psi = dcc->psi_q15;
        acc = 0;
        for (uint16_t j = 0; j < dcc->coeffs->grid.n_ops; j++) {
            acc += (int64_t)(v - psi[j]) * c[j];
        }
    }
    return dcc_out(dcc, acc, yd_q15);
}

#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/* Without the runs (the RKP kind's changing weights, a plane the runs do not
 * handle): the C tick, out of the Thumb-2 entry's way. */
static __attribute__((noinline, used)) int16_t dcc_process_scan(struct piezo_dcc *dcc, int16_t yd_q15)
{
    return process_c(dcc, yd_q15);
}

/*
 * Cortex-M4: the law's tick with runs in Thumb-2 (round 18). gcc's C tick
 * (round 17's) pushed six registers, moved the arguments to saved ones,
 * called the step and read kacc back after it (32 instructions besides the
 * step at tick 203). Here the tick tests runs, compares v = u_last with
 * v_prev, makes the reversal's three stores (as dcc_ops) and jumps into the
 * rising or falling step with v in r3 and yd in r1; the step ends with the
 * output (dcc_law_out, kacc still in registers) and returns it. A tick
 * without a move takes the output alone. test_dcc's walks compare it with
 * the band scan's C law and, through piezo_dcc_ops_update (below), every
 * operator and the step's state with the C step.
 */
typedef char piezo_dcc_process_m4_layout_check_t[
    (offsetof(struct piezo_dcc, runs) == 50u && offsetof(struct piezo_dcc, u_last_q15) == 36u &&
     offsetof(struct piezo_dcc, v_prev_q15) == 34u && offsetof(struct piezo_dcc, xi_q15) == 32u &&
     offsetof(struct piezo_dcc, dir) == 38u && offsetof(struct piezo_dcc, n_run) == 43u &&
     offsetof(struct piezo_dcc, csum) == 16u && offsetof(struct piezo_dcc, kacc) == 24u &&
     offsetof(struct piezo_dcc_coeffs, g_q24) == 28u) ? 1 : -1];

__attribute__((naked, noinline)) int16_t piezo_dcc_process(struct piezo_dcc *dcc, int16_t yd_q15)
{
    (void)dcc;
    (void)yd_q15;
    __asm__ volatile(
        DCC_LAW_OUT_MACRO
        "    ldrb   r2, [r0, #50]\n"         /* runs */
        "    cbz    r2, 3f\n"
        "    ldrsh  r3, [r0, #36]\n"         /* v = u_last: the operators' input */
        "    ldrsh  r2, [r0, #34]\n"         /* v_prev */
        "    cmp    r3, r2\n"
        "    beq    4f\n"
        "    ldrsb  ip, [r0, #38]\n"         /* dir */
        "    blt    1f\n"
        "    cmp    ip, #1\n"
        "    beq.w  dcc_rise_m4\n"
        "    movs   ip, #1\n"                /* a reversal to rising */
        "    b      2f\n"
        "1:  cmn    ip, #1\n"
        "    beq.w  dcc_fall_m4\n"
        "    mov    ip, #-1\n"               /* a reversal to falling */
        "2:  strh   r2, [r0, #32]\n"         /* xi = v_prev */
        "    strb   ip, [r0, #38]\n"         /* dir */
        "    movs   r2, #0\n"
        "    strb   r2, [r0, #43]\n"         /* n_run = 0: the runs are the other direction's */
        "    cmp    ip, #0\n"
        "    bgt.w  dcc_rise_m4\n"
        "    b.w    dcc_fall_m4\n"
        "3:  b.w    dcc_process_scan\n"
        "4:  push   {r4-r8, lr}\n"           /* no move: the output alone */
        "    mov    r4, r3\n"
        "    mov    ip, r0\n"
        "    ldrd   r7, r8, [r0, #24]\n"     /* kacc */
        "    dcc_law_out\n"
        "    pop    {r4-r8, pc}\n"
        "    .purgem dcc_law_out\n");
}

/* The operators alone: on the Cortex-M4 with runs, the law's Thumb-2 tick on
 * input v (u_last set to v and put back; the output is dropped), so that
 * test_dcc's twin tests compare that path with the C step. */
void piezo_dcc_ops_update(struct piezo_dcc *dcc, int16_t v_q15)
{
    if (dcc->runs) {
        const int16_t u = dcc->u_last_q15;
        dcc->u_last_q15 = v_q15;
        (void)piezo_dcc_process(dcc, 0);
        dcc->u_last_q15 = u;
        return;
    }
    dcc_ops(dcc, v_q15);
}
#else
void piezo_dcc_ops_update(struct piezo_dcc *dcc, int16_t v_q15)
{
    dcc_ops(dcc, v_q15);
}

int16_t piezo_dcc_process(struct piezo_dcc *dcc, int16_t yd_q15)
{
    return process_c(dcc, yd_q15);
}
#endif
