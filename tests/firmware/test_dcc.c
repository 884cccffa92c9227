/* KP compensation operators and the DCC law (firmware/core/dcc.c) against the
 * host golden model (host/piezoctl/golden/dcc.py), bit for bit; the identity
 * psi_j + Psi_j == v in integers against the KP kernel; init's refusals. */
#include <string.h>

#include "piezo_test.h"
#include "dcc.h"
#include "kp.h"
#include "dcc_vectors.h"

#define DCC_OF(p)                                                                     \
    {                                                                                 \
        .grid = {.n1_q15 = p##_n1, .n2_q15 = p##_n2, .n_ops = p##_NOPS,               \
                 .nmin_q15 = p##_NMIN, .rmax_q15 = p##_RMAX, .slope_q16 = p##_SLOPE,  \
                 .xsat_q15 = p##_XSAT},                                               \
        .c_q24 = p##_c, .g_q24 = p##_G                                                \
    }

static const struct piezo_dcc_coeffs dcc_std = DCC_OF(dcc_std);
static const struct piezo_dcc_coeffs dcc_half = DCC_OF(dcc_half);
static const struct piezo_dcc_coeffs dcc_edge = DCC_OF(dcc_edge);

struct dcc_case {
    const char *name;
    const struct piezo_dcc_coeffs *c;
    const int16_t *yd;
    const int16_t *u;
    size_t n;
};

#define DCC_CASE(name, set) \
    {#name, &set, dcc_case_##name##_yd, dcc_case_##name##_u, sizeof(dcc_case_##name##_yd) / sizeof(int16_t)},
static const struct dcc_case cases[] = {DCC_GOLDEN_CASES(DCC_CASE)};
#define N_CASES (sizeof(cases) / sizeof(cases[0]))
#define N_OF(a) (sizeof(a) / sizeof((a)[0]))

static int32_t cpsi_a[PIEZO_KP_MAX_OPS], zo_a[PIEZO_KP_MAX_OPS];
static int32_t cpsi_b[PIEZO_KP_MAX_OPS], zo_b[PIEZO_KP_MAX_OPS];
/* prefix sums of the planes below (the golden sets and the walks' L = 30:
 * the cortex-m4 test image has no room for PIEZO_KP_MAX_OPS) */
#define SUMS_MAX_OPS 465u
static int32_t sums_a[2u * (SUMS_MAX_OPS + 1u)];

/* dc's weights' prefix sums for an instance initialized on dc (as the
 * controller's loader does); 1 when they apply (sum |c| < 2^31) */
static int with_sums(struct piezo_dcc *d, struct piezo_dcc_coeffs *dc)
{
    const enum piezo_err rc = piezo_dcc_prefix_sums(d, sums_a, sizeof sums_a / sizeof sums_a[0]);
    dc->csum_q24 = rc == PIEZO_OK ? sums_a : NULL;
    return rc == PIEZO_OK;
}
static int16_t psi_k[PIEZO_KP_MAX_OPS];

static void run_block(struct piezo_dcc *d, const struct dcc_case *c, size_t k0, size_t k1)
{
    char label[64];
    snprintf(label, sizeof label, "dcc %s", c->name);
    for (size_t k = k0; k < k1; k++) {
        assert_golden_i32(label, k, piezo_dcc_process(d, c->yd[k]), c->u[k]);
    }
}

static const struct dcc_case *find_case(const char *name)
{
    for (size_t i = 0; i < N_CASES; i++) {
        if (strcmp(cases[i].name, name) == 0) {
            return &cases[i];
        }
    }
    fail_msg("no golden case %s", name);
    return NULL;
}

static void test_golden_cases(void **state)
{
    (void)state;
    assert_true(N_CASES >= 9u);
    assert_true(dcc_std_NOPS <= SUMS_MAX_OPS && dcc_edge_NOPS <= SUMS_MAX_OPS);
    for (size_t i = 0; i < N_CASES; i++) {
        struct piezo_dcc d;
        assert_int_equal(piezo_dcc_init(&d, cases[i].c, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
        run_block(&d, &cases[i], 0, cases[i].n);
        /* the same with the weights declared constant (kept sums): the runs
         * on the reference planes (sum |c| < 2^31), the band scan on the
         * edge set's extreme weights */
        assert_int_equal(piezo_dcc_init(&d, cases[i].c, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
        piezo_dcc_const_weights(&d);
        assert_int_equal(d.c_abs_31, cases[i].c == &dcc_edge ? 0 : 1);
        assert_true(cases[i].c == &dcc_edge || (d.n_rows != 0u && d.n_cols != 0u)); /* the runs, with their tables */
        run_block(&d, &cases[i], 0, cases[i].n);
        /* and with the weights' prefix sums (lines at rmax or 0 join as one) */
        struct piezo_dcc_coeffs dc = *cases[i].c;
        assert_int_equal(piezo_dcc_init(&d, &dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
        assert_int_equal(with_sums(&d, &dc), cases[i].c == &dcc_edge ? 0 : 1);
        piezo_dcc_const_weights(&d);
        assert_true(cases[i].c == &dcc_edge || d.psum == sums_a);
        run_block(&d, &cases[i], 0, cases[i].n);
    }
}

/* Prefix sums: too small an array and weights whose sums could leave int32
 * are refused; sums that do not match the weights are not used (checked
 * entry by entry by piezo_dcc_const_weights), and the law is unchanged. */
static void test_prefix_sums_checked(void **state)
{
    (void)state;
    struct piezo_dcc d;
    struct piezo_dcc_coeffs dc = dcc_std;
    assert_int_equal(piezo_dcc_init(&d, &dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_prefix_sums(&d, sums_a, 2u * dcc_std_NOPS + 1u), PIEZO_ERANGE);
    assert_int_equal(piezo_dcc_prefix_sums(&d, NULL, 2u * dcc_std_NOPS + 2u), PIEZO_EINVAL);
    assert_int_equal(piezo_dcc_prefix_sums(&d, sums_a, 2u * dcc_std_NOPS + 2u), PIEZO_OK);
    assert_int_equal(sums_a[0], 0);
    assert_int_equal(sums_a[dcc_std_NOPS + 1u], 0);
    assert_int_equal(sums_a[dcc_std_NOPS], sums_a[2u * dcc_std_NOPS + 1u]); /* both orders sum every c */
    struct piezo_dcc_coeffs de = dcc_edge;
    assert_int_equal(piezo_dcc_init(&d, &de, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_prefix_sums(&d, sums_a, sizeof sums_a / sizeof sums_a[0]), PIEZO_EINVAL);
    /* one entry off, in either half: not used */
    const size_t bad[] = {1u, dcc_std_NOPS / 2u, dcc_std_NOPS, dcc_std_NOPS + 1u, dcc_std_NOPS + 7u,
                          2u * dcc_std_NOPS + 1u};
    const struct dcc_case *c = find_case("realistic");
    for (size_t b = 0; b < N_OF(bad); b++) {
        assert_int_equal(piezo_dcc_init(&d, &dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
        assert_int_equal(with_sums(&d, &dc), 1);
        sums_a[bad[b]] += 1;
        piezo_dcc_const_weights(&d);
        assert_null(d.psum);
        run_block(&d, c, 0, c->n);
    }
}

/* psi_j + Psi_j == v exactly, every operator, every sample, from reset;
 * const_w: with the weights declared constant (the kernel's runs, dcc.c). */
static void check_identity(const struct piezo_dcc_coeffs *dc, const int16_t *v, size_t n,
                           const char *name, int const_w)
{
    const struct piezo_kp_coeffs kc = {.grid = dc->grid, .w_q24 = dc->c_q24};
    struct piezo_kp kp;
    struct piezo_dcc d;
    assert_int_equal(piezo_kp_init(&kp, &kc, psi_k, PIEZO_KP_MAX_OPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_init(&d, dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
    if (const_w) {
        piezo_dcc_const_weights(&d);
    }
    for (uint16_t j = 0; j < dc->grid.n_ops; j++) {
        assert_int_equal(psi_k[j] + piezo_dcc_cpsi(&d, j), dc->grid.nmin_q15);
    }
    for (size_t k = 0; k < n; k++) {
        (void)piezo_kp_process(&kp, v[k]);
        piezo_dcc_ops_update(&d, v[k]);
        for (uint16_t j = 0; j < dc->grid.n_ops; j++) {
            const int32_t cpsi = piezo_dcc_cpsi(&d, j);
            if ((int32_t)psi_k[j] + cpsi != v[k]) {
                fail_msg("%s: sample %lu operator %u: psi %d + Psi %ld != v %d", name,
                         (unsigned long)k, (unsigned)j, psi_k[j], (long)cpsi, v[k]);
            }
        }
    }
}

static void test_psi_plus_compensation_is_input(void **state)
{
    (void)state;
    const struct piezo_dcc_coeffs *sets[] = {&dcc_std, &dcc_half, &dcc_edge};
    for (size_t s = 0; s < N_OF(sets); s++) {
        for (int cw = 0; cw <= 1; cw++) {
            check_identity(sets[s], dcc_ops_random_v, N_OF(dcc_ops_random_v), "random", cw);
            check_identity(sets[s], dcc_ops_alternating_v, N_OF(dcc_ops_alternating_v), "alternating", cw);
            check_identity(sets[s], dcc_ops_steps_v, N_OF(dcc_ops_steps_v), "steps", cw);
            check_identity(sets[s], dcc_ops_edges_v, N_OF(dcc_ops_edges_v), "edges", cw);
            check_identity(sets[s], dcc_ops_realistic_v, N_OF(dcc_ops_realistic_v), "realistic", cw);
        }
    }
}

/* Two process loops with a pause (another instance sharing the coefficients
 * runs in between): the state carries over. */
static void test_split_run_and_shared_coeffs(void **state)
{
    (void)state;
    const struct dcc_case *c = find_case("realistic");
    const struct dcc_case *other = find_case("random");
    struct piezo_dcc a, b;
    assert_int_equal(piezo_dcc_init(&a, &dcc_std, cpsi_a, zo_a, dcc_std_NOPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_init(&b, &dcc_std, cpsi_b, zo_b, dcc_std_NOPS), PIEZO_OK);
    const size_t split = c->n / 4u + 1u;
    run_block(&a, c, 0, split);
    run_block(&b, other, 0, other->n);
    run_block(&a, c, split, c->n);
    /* the same with constant weights: the runs are per instance */
    assert_int_equal(piezo_dcc_init(&a, &dcc_std, cpsi_a, zo_a, dcc_std_NOPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_init(&b, &dcc_std, cpsi_b, zo_b, dcc_std_NOPS), PIEZO_OK);
    piezo_dcc_const_weights(&a);
    piezo_dcc_const_weights(&b);
    run_block(&a, c, 0, split);
    run_block(&b, other, 0, other->n);
    run_block(&a, c, split, c->n);
}

static void test_reset_restores_initial_state(void **state)
{
    (void)state;
    struct piezo_dcc d;
    assert_int_equal(piezo_dcc_init(&d, &dcc_std, cpsi_a, zo_a, dcc_std_NOPS), PIEZO_OK);
    run_block(&d, find_case("random"), 0, 321);
    piezo_dcc_reset(&d);
    assert_int_equal(d.u_last_q15, dcc_std_NMIN);
    assert_int_equal(d.dir, -1);
    for (uint16_t j = 0; j < dcc_std_NOPS; j++) {
        assert_int_equal(piezo_dcc_cpsi(&d, j), dcc_std_NMIN);
    }
    const struct dcc_case *c = find_case("steps");
    run_block(&d, c, 0, c->n);
}

/* Grids at the row and column tables' limit, in (n1, n2) order: K rows of
 * two operators on two shared columns, and two rows over K columns. Up to
 * PIEZO_DCC_MAX_ROWS rows and columns the runs take them (init's tables),
 * beyond it the band scan; either way psi + Psi == v against the KP kernel
 * and the law's drive equals the one with the weights summed every tick. */
static void check_tables(const int16_t *n1, const int16_t *n2, const int32_t *c, uint16_t n_ops,
                         uint16_t want_rows, uint16_t want_cols)
{
    struct piezo_dcc_coeffs dc = dcc_std;
    dc.grid.n1_q15 = n1;
    dc.grid.n2_q15 = n2;
    dc.grid.n_ops = n_ops;
    dc.grid.nmin_q15 = -32768;
    dc.c_q24 = c;
    struct piezo_dcc a, b;
    assert_int_equal(piezo_dcc_init(&a, &dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_init(&b, &dc, cpsi_b, zo_b, PIEZO_KP_MAX_OPS), PIEZO_OK);
    piezo_dcc_const_weights(&a);
    assert_int_equal(a.n_rows, want_rows);
    assert_int_equal(a.n_cols, want_cols);
    const struct dcc_case *rc = find_case("realistic");
    for (size_t i = 0; i < rc->n; i++) {
        assert_int_equal(piezo_dcc_process(&a, rc->yd[i]), piezo_dcc_process(&b, rc->yd[i]));
    }
    for (int cw = 0; cw <= 1; cw++) {
        check_identity(&dc, dcc_ops_random_v, N_OF(dcc_ops_random_v), "tables random", cw);
        check_identity(&dc, dcc_ops_realistic_v, N_OF(dcc_ops_realistic_v), "tables realistic", cw);
    }
}

static void test_row_and_column_table_limits(void **state)
{
    (void)state;
    static int16_t n1[2 * (PIEZO_DCC_MAX_ROWS + 1u)], n2[2 * (PIEZO_DCC_MAX_ROWS + 1u)];
    static int32_t c[2 * (PIEZO_DCC_MAX_ROWS + 1u)];
    static const uint16_t sizes[] = {PIEZO_DCC_MAX_ROWS - 1u, PIEZO_DCC_MAX_ROWS, PIEZO_DCC_MAX_ROWS + 1u};
    for (size_t t = 0; t < N_OF(sizes); t++) {
        const uint16_t k = sizes[t];
        const uint16_t want = k <= PIEZO_DCC_MAX_ROWS ? k : 0u;
        for (uint16_t i = 0; i < 2u * k; i++) {
            c[i] = 40000 + 7 * (int32_t)i - 900 * (int32_t)(i & 1u);
        }
        /* K rows (n1 spread over the range), each on the columns 30000 and 31000 */
        for (uint16_t i = 0; i < k; i++) {
            n1[2 * i] = n1[2 * i + 1] = (int16_t)(-32000 + (int32_t)i * (61000 / k));
            n2[2 * i] = 30000;
            n2[2 * i + 1] = 31000;
        }
        check_tables(n1, n2, c, (uint16_t)(2u * k), want, 2u);
        /* two rows (n1 -32000, -31000), each over K columns (n2 spread) */
        for (uint16_t r = 0; r < 2u; r++) {
            for (uint16_t i = 0; i < k; i++) {
                n1[r * k + i] = (int16_t)(-32000 + 1000 * (int32_t)r);
                n2[r * k + i] = (int16_t)(-31000 + (int32_t)i * (62000 / k));
            }
        }
        check_tables(n1, n2, c, (uint16_t)(2u * k), 2u, want);
    }
}

/* ---- the runs on random walks with small and large reversals, against an oracle ---- */

/* A KP plane of L levels in the host's cell convention (row by row, the
 * operators at the cells' midpoints) over the reference set's range, with
 * weights of both signs whose magnitudes sum below 2^31 (the runs apply). */
#define WALK_MAX_L 30u
#define WALK_MAX_OPS (WALK_MAX_L * (WALK_MAX_L + 1u) / 2u)
static int16_t walk_n1[WALK_MAX_OPS], walk_n2[WALK_MAX_OPS];
static int32_t walk_c[WALK_MAX_OPS];
static int32_t walk_psi[WALK_MAX_OPS]; /* the oracle's operators */

static uint32_t walk_rng;
static uint32_t walk_rand(uint32_t n)
{
    return (uint32_t)(((uint64_t)(piezo_test_lcg(&walk_rng) >> 8) * n) >> 24);
}

/* The plane's L levels over [-32768, hi] (walk_plane: the whole range). */
static struct piezo_dcc_coeffs walk_plane_to(uint16_t L, int32_t hi)
{
    const int32_t lo = -32768;
    uint16_t j = 0;
    for (uint16_t i = 0; i < L; i++) {
        for (uint16_t k = i; k < L; k++) {
            walk_n1[j] = (int16_t)(lo + (int32_t)((2 * i + 1) * (hi - lo)) / (2 * L));
            walk_n2[j] = (int16_t)(lo + (int32_t)((2 * k + 1) * (hi - lo)) / (2 * L));
            walk_c[j] = (int32_t)walk_rand(1u << 18) - (1 << 16); /* |c| < 2^18, 465 of them < 2^27 */
            j++;
        }
    }
    struct piezo_dcc_coeffs dc = dcc_std;
    dc.grid.n1_q15 = walk_n1;
    dc.grid.n2_q15 = walk_n2;
    dc.grid.n_ops = j;
    dc.grid.nmin_q15 = (int16_t)lo;
    dc.c_q24 = walk_c;
    return dc;
}

static struct piezo_dcc_coeffs walk_plane(uint16_t L)
{
    return walk_plane_to(L, 32767);
}

/* The next input of a walk: monotone segments of random length, half of
 * them short (1..8 ticks of 0..8 LSB: the jitter of a closed loop's drive,
 * small reversals), the others long (up to 400 ticks of up to 600 LSB: large
 * reversals), now and then a jump or a pause; kept in q15. */
struct walk {
    int32_t v;
    int32_t dir;
    int32_t left;
    int32_t step;
};

static int16_t walk_next(struct walk *w)
{
    if (w->left == 0) {
        w->dir = -w->dir;
        if (walk_rand(2u) == 0u) {
            w->left = 1 + (int32_t)walk_rand(8u);
            w->step = (int32_t)walk_rand(9u);
        } else {
            w->left = 10 + (int32_t)walk_rand(390u);
            w->step = 1 + (int32_t)walk_rand(600u);
        }
    }
    w->left--;
    int32_t dv = w->dir * (int32_t)walk_rand((uint32_t)w->step + 1u);
    if (walk_rand(500u) == 0u) {
        dv = (int32_t)walk_rand(65536u) - 32768; /* a jump */
    }
    w->v += dv;
    if (w->v > 32767 || w->v < -32768) {
        w->v = w->v > 32767 ? 32767 : -32768;
        w->dir = -w->dir;
    }
    return (int16_t)w->v;
}

/* The oracle: every operator by the KP equations (dcc.h), one by one. */
static void walk_oracle(const struct piezo_kp_grid *g, int32_t v_prev, int32_t v)
{
    for (uint16_t j = 0; j < g->n_ops; j++) {
        if (v > v_prev) {
            const int32_t r = piezo_kp_ridge_q15(g, v - g->n2_q15[j]);
            walk_psi[j] = r > walk_psi[j] ? r : walk_psi[j];
        } else if (v < v_prev) {
            const int32_t r = piezo_kp_ridge_q15(g, v - g->n1_q15[j]);
            walk_psi[j] = r < walk_psi[j] ? r : walk_psi[j];
        }
    }
}

/* Every operator of d (and of its C twin e, when not NULL) against the oracle's; returns the oracle's kept sum
 * sum psi_j c_j. Written once for the walk, the jump and the empty-band checks. */
static int64_t walk_check_ops(const struct piezo_dcc *d, const struct piezo_dcc *e, uint16_t n_ops, unsigned L,
                              unsigned long seed, unsigned long k, int v, long v_prev)
{
    int64_t kacc = 0;
    for (uint16_t j = 0; j < n_ops; j++) {
        const int32_t c_psi = e != NULL ? e->psi_q15[j] : d->psi_q15[j];
        if (d->psi_q15[j] != walk_psi[j] || c_psi != walk_psi[j]) {
            fail_msg("L %u seed %lu tick %lu v %d (from %ld) operator %u: psi %ld (C %ld), oracle %ld", L, seed, k,
                     v, v_prev, (unsigned)j, (long)d->psi_q15[j], (long)c_psi, (long)walk_psi[j]);
        }
        kacc += (int64_t)walk_psi[j] * walk_c[j];
    }
    return kacc;
}

/* Runs (constant weights) against the oracle, every operator and the kept
 * sum every tick, on a walk with small and large reversals; and the law's
 * drive against the band scan (weights summed every tick). Returns the
 * walk's reversals. */
static unsigned walk_check(uint16_t L, uint32_t seed, size_t n, int sums)
{
    walk_rng = seed;
    struct piezo_dcc_coeffs dc = walk_plane(L);
    struct piezo_dcc d, band;
    assert_int_equal(piezo_dcc_init(&d, &dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
    if (sums) {
        assert_int_equal(with_sums(&d, &dc), 1);
    }
    piezo_dcc_const_weights(&d);
    assert_true(d.n_rows == L && d.n_cols == L && d.c_abs_31);
    assert_true(sums ? d.psum == sums_a : d.psum == NULL);
    for (uint16_t j = 0; j < dc.grid.n_ops; j++) {
        walk_psi[j] = 0;
    }
    struct walk w = {.v = dc.grid.nmin_q15, .dir = 1, .left = 0, .step = 0};
    int32_t v_prev = dc.grid.nmin_q15;
    int dir = -1;
    unsigned reversals = 0;
    for (size_t k = 0; k < n; k++) {
        const int16_t v = walk_next(&w);
        const int ndir = v > v_prev ? 1 : v < v_prev ? -1 : dir;
        reversals += ndir != dir;
        dir = ndir;
        walk_oracle(&dc.grid, v_prev, v);
        piezo_dcc_ops_update(&d, v);
        const int64_t kacc =
            walk_check_ops(&d, NULL, dc.grid.n_ops, L, (unsigned long)seed, (unsigned long)k, v, (long)v_prev);
        if (d.kacc != kacc) {
            fail_msg("L %u seed %lu tick %lu: kept sum %lld, oracle %lld", (unsigned)L, (unsigned long)seed,
                     (unsigned long)k, (long long)d.kacc, (long long)kacc);
        }
        v_prev = v;
    }
    /* the law on its own drive: a desired output walking the same way */
    assert_int_equal(piezo_dcc_init(&d, &dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_init(&band, &dc, cpsi_b, zo_b, PIEZO_KP_MAX_OPS), PIEZO_OK);
    piezo_dcc_const_weights(&d);
    assert_true(sums ? d.psum == sums_a : d.psum == NULL);
    struct walk wy = {.v = 0, .dir = 1, .left = 0, .step = 0};
    for (size_t k = 0; k < n; k++) {
        const int16_t yd = walk_next(&wy);
        const int16_t ur = piezo_dcc_process(&d, yd), ub = piezo_dcc_process(&band, yd);
        if (ur != ub) {
            fail_msg("L %u seed %lu tick %lu: runs %d, band scan %d", (unsigned)L, (unsigned long)seed,
                     (unsigned long)k, ur, ub);
        }
    }
    return reversals;
}

static void test_runs_on_random_walks(void **state)
{
    (void)state;
    static const uint16_t planes[] = {10u, 20u, 30u};
    for (size_t i = 0; i < N_OF(planes); i++) {
        for (uint32_t seed = 1u; seed <= 2u; seed++) {
            for (int sums = 0; sums <= 1; sums++) {
                const unsigned reversals = walk_check(planes[i], seed * 7919u + planes[i], 20000u, sums);
                /* a segment lasts about 100 ticks on average: some 200 reversals */
                assert_true(reversals >= 100u);
            }
        }
    }
}

/* Two instances on one walk plane of L levels (seeded), d with the prefix
 * sums when sums is set, both with constant weights: the Thumb-2 step's and
 * the C step's twins of step_check and jump_check. */
static void twin_init_to(uint16_t L, int32_t hi, uint32_t seed, int sums, struct piezo_dcc_coeffs *dc,
                         struct piezo_dcc *d, struct piezo_dcc *e)
{
    walk_rng = seed;
    *dc = walk_plane_to(L, hi);
    assert_int_equal(piezo_dcc_init(d, dc, cpsi_a, zo_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
    if (sums) {
        assert_int_equal(with_sums(d, dc), 1);
    }
    assert_int_equal(piezo_dcc_init(e, dc, cpsi_b, zo_b, PIEZO_KP_MAX_OPS), PIEZO_OK);
    piezo_dcc_const_weights(d);
    piezo_dcc_const_weights(e);
}

static void twin_init(uint16_t L, uint32_t seed, int sums, struct piezo_dcc_coeffs *dc, struct piezo_dcc *d,
                      struct piezo_dcc *e)
{
    twin_init_to(L, 32767, seed, sums, dc, d, e);
}

/* The step piezo_dcc_ops_update takes (on the Cortex-M4 the falling rows
 * in Thumb-2, round 15) against the C step (piezo_dcc_ops_update_c), two
 * instances on one plane and walk: every operator, the kept sum, the runs
 * and the hints every tick. Elsewhere both are the C step (the test then
 * checks only that the two entry points agree). Returns the falling ticks
 * that took the runs. */
static unsigned step_check(uint16_t L, uint32_t seed, size_t n, int sums)
{
    struct piezo_dcc_coeffs dc;
    struct piezo_dcc d, e;
    twin_init(L, seed, sums, &dc, &d, &e);
    assert_true(d.runs && e.runs && (sums ? d.psum == sums_a : d.psum == NULL));
    struct walk w = {.v = dc.grid.nmin_q15, .dir = 1, .left = 0, .step = 0};
    unsigned falls = 0;
    for (size_t k = 0; k < n; k++) {
        const int16_t v = walk_next(&w);
        falls += v < d.v_prev_q15;
        piezo_dcc_ops_update(&d, v);
        piezo_dcc_ops_update_c(&e, v);
        for (uint16_t j = 0; j < dc.grid.n_ops; j++) {
            if (d.psi_q15[j] != e.psi_q15[j]) {
                fail_msg("L %u seed %lu tick %lu v %d operator %u: psi %ld, C step %ld", (unsigned)L,
                         (unsigned long)seed, (unsigned long)k, v, (unsigned)j, (long)d.psi_q15[j],
                         (long)e.psi_q15[j]);
            }
        }
        if (d.kacc != e.kacc || d.v_prev_q15 != e.v_prev_q15 || d.xi_q15 != e.xi_q15 || d.dir != e.dir ||
            d.n_run != e.n_run || d.cur != e.cur || d.row_cur != e.row_cur || d.col_cur != e.col_cur) {
            fail_msg("L %u seed %lu tick %lu: state (kacc %lld, n_run %u, cur %u, row %u) against the C "
                     "step's (%lld, %u, %u, %u)",
                     (unsigned)L, (unsigned long)seed, (unsigned long)k, (long long)d.kacc, d.n_run, d.cur,
                     d.row_cur, (long long)e.kacc, e.n_run, e.cur, e.row_cur);
        }
        for (uint8_t i = 0; i < d.n_run; i++) {
            const struct piezo_dcc_run *a = &d.run[d.cur][i], *b = &e.run[e.cur][i];
            if (a->csum != b->csum || a->lvl != b->lvl || a->thr != b->thr || a->k != b->k) {
                fail_msg("L %u seed %lu tick %lu run %u: (%ld, %ld, %d, %u) against (%ld, %ld, %d, %u)",
                         (unsigned)L, (unsigned long)seed, (unsigned long)k, (unsigned)i, (long)a->csum,
                         (long)a->lvl, a->thr, a->k, (long)b->csum, (long)b->lvl, b->thr, b->k);
            }
        }
    }
    return falls;
}

static void test_step_matches_c_step(void **state)
{
    (void)state;
    static const uint16_t planes[] = {10u, 20u, 30u};
    for (size_t i = 0; i < N_OF(planes); i++) {
        for (uint32_t seed = 3u; seed <= 4u; seed++) {
            for (int sums = 0; sums <= 1; sums++) {
                const unsigned falls = step_check(planes[i], seed * 7919u + planes[i], 20000u, sums);
                assert_true(falls >= 5000u); /* about half the ticks fall */
            }
        }
    }
}

/* The band's first line walked from the last hint one line at a time, as
 * round 16's Thumb-2 steps found it: the first of the n ascending keys that
 * exceeds t. */
static uint8_t walk_line(const int16_t *key, uint16_t n, uint8_t k, int32_t t, unsigned *steps)
{
    const uint8_t k0 = k;
    while (k > 0u && key[k - 1u] > t) {
        k--;
    }
    while (k < n && key[k] <= t) {
        k++;
    }
    *steps = k > k0 ? (unsigned)(k - k0) : (unsigned)(k0 - k);
    return k;
}

/* Large jumps (round 17): an input anywhere in the range every tick, now
 * and then a small move. The step's hints (row_cur falling, col_cur rising)
 * against the walk's line, every operator against the oracle and the kept
 * sum, and the step against the C step (which bisects). Returns the ticks
 * on which the walk took three lines or more (the steps' bisection). */
static unsigned jump_check(uint16_t L, uint32_t seed, size_t n, int sums)
{
    struct piezo_dcc_coeffs dc;
    struct piezo_dcc d, e;
    twin_init(L, seed, sums, &dc, &d, &e);
    assert_true(d.runs && d.n2_banded && d.n_rows == L && d.n_cols == L);
    /* the rows' keys (n1) and the columns' (n2), ascending: the plane's L levels */
    int16_t rows[WALK_MAX_L], cols[WALK_MAX_L];
    for (uint16_t i = 0; i < L; i++) {
        rows[i] = walk_n1[i == 0u ? 0u : (uint16_t)(i * L - i * (i - 1u) / 2u)]; /* row i's first operator */
        cols[i] = walk_n2[i];                                                   /* row 0 holds every column */
    }
    for (uint16_t j = 0; j < dc.grid.n_ops; j++) {
        walk_psi[j] = 0;
    }
    const int32_t xsat = dc.grid.xsat_q15;
    int32_t v_prev = dc.grid.nmin_q15;
    uint8_t row = 0u, col = 0u;
    unsigned far = 0u, steps = 0u;
    for (size_t k = 0; k < n; k++) {
        const int32_t v = walk_rand(8u) == 0u ? v_prev + (int32_t)walk_rand(2001u) - 1000
                                              : (int32_t)walk_rand(65536u) - 32768;
        const int16_t vq = (int16_t)(v > 32767 ? 32767 : (v < -32768 ? -32768 : v));
        if (vq < v_prev) {
            row = walk_line(rows, L, row, vq - xsat, &steps);
            far += steps >= 3u;
        } else if (vq > v_prev) {
            col = walk_line(cols, L, col, v_prev - xsat, &steps);
            far += steps >= 3u;
        }
        walk_oracle(&dc.grid, v_prev, vq);
        piezo_dcc_ops_update(&d, vq);
        piezo_dcc_ops_update_c(&e, vq);
        if (d.row_cur != row || d.col_cur != col || e.row_cur != row || e.col_cur != col) {
            fail_msg("L %u seed %lu tick %lu v %d (from %ld): rows %u (C %u), columns %u (C %u), the walk's %u, %u",
                     (unsigned)L, (unsigned long)seed, (unsigned long)k, vq, (long)v_prev, d.row_cur, e.row_cur,
                     d.col_cur, e.col_cur, row, col);
        }
        const int64_t kacc =
            walk_check_ops(&d, &e, dc.grid.n_ops, L, (unsigned long)seed, (unsigned long)k, vq, (long)v_prev);
        if (d.kacc != kacc || e.kacc != kacc) {
            fail_msg("L %u seed %lu tick %lu: kept sum %lld (C %lld), oracle %lld", (unsigned)L,
                     (unsigned long)seed, (unsigned long)k, (long long)d.kacc, (long long)e.kacc, (long long)kacc);
        }
        v_prev = vq;
    }
    return far;
}

static void test_search_after_large_jumps(void **state)
{
    (void)state;
    static const uint16_t planes[] = {10u, 20u, 30u};
    for (size_t i = 0; i < N_OF(planes); i++) {
        for (int sums = 0; sums <= 1; sums++) {
            const unsigned far = jump_check(planes[i], 104729u + planes[i], 3000u, sums);
            assert_true(far >= 1000u); /* most jumps cross three lines or more */
        }
    }
}

/* An empty band (round 18): a plane whose levels span the range's lower
 * half only, so an input above its top level plus xsat leaves no row in the
 * falling band (v - xsat >= every n1) and, once v_prev is there too, no
 * column in the rising one: the steps' exit before their loops (on the
 * Cortex-M4 the flags of the line table's end test). Inputs anywhere above
 * the plane's middle, now and then a small move; the step against the C
 * step (state, runs and hints) and both against the oracle every tick.
 * Returns the falling ticks with an empty band (*rising: the rising ones). */
static unsigned empty_check(uint16_t L, uint32_t seed, size_t n, int sums, unsigned *rising)
{
    struct piezo_dcc_coeffs dc;
    struct piezo_dcc d, e;
    twin_init_to(L, 0, seed, sums, &dc, &d, &e);
    assert_true(d.runs && d.n2_banded && d.n_rows == L && d.n_cols == L);
    const int32_t xsat = dc.grid.xsat_q15, top = walk_n2[L - 1u]; /* the top level: last n1 = last n2 */
    assert_true(top + xsat < 32767 - 4000);                         /* room for empty bands */
    for (uint16_t j = 0; j < dc.grid.n_ops; j++) {
        walk_psi[j] = 0;
    }
    int32_t v_prev = dc.grid.nmin_q15;
    unsigned falls = 0u;
    *rising = 0u;
    for (size_t k = 0; k < n; k++) {
        const int32_t v = walk_rand(4u) == 0u ? v_prev + (int32_t)walk_rand(601u) - 300
                                              : -16384 + (int32_t)walk_rand(49152u);
        const int16_t vq = (int16_t)(v > 32767 ? 32767 : (v < -32768 ? -32768 : v));
        falls += vq < v_prev && vq - xsat >= top;
        *rising += vq > v_prev && v_prev - xsat >= top;
        walk_oracle(&dc.grid, v_prev, vq);
        piezo_dcc_ops_update(&d, vq);
        piezo_dcc_ops_update_c(&e, vq);
        const int64_t kacc =
            walk_check_ops(&d, &e, dc.grid.n_ops, L, (unsigned long)seed, (unsigned long)k, vq, (long)v_prev);
        if (d.kacc != kacc || e.kacc != kacc || d.v_prev_q15 != e.v_prev_q15 || d.n_run != e.n_run ||
            d.cur != e.cur || d.row_cur != e.row_cur || d.col_cur != e.col_cur) {
            fail_msg("L %u seed %lu tick %lu v %d (from %ld): kacc %lld (C %lld, oracle %lld), n_run %u (%u), "
                     "cur %u (%u), rows %u (%u), columns %u (%u)",
                     (unsigned)L, (unsigned long)seed, (unsigned long)k, vq, (long)v_prev, (long long)d.kacc,
                     (long long)e.kacc, (long long)kacc, d.n_run, e.n_run, d.cur, e.cur, d.row_cur, e.row_cur,
                     d.col_cur, e.col_cur);
        }
        for (uint8_t i = 0; i < d.n_run; i++) {
            const struct piezo_dcc_run *a = &d.run[d.cur][i], *b = &e.run[e.cur][i];
            if (a->csum != b->csum || a->lvl != b->lvl || a->thr != b->thr || a->k != b->k) {
                fail_msg("L %u seed %lu tick %lu run %u: (%ld, %ld, %d, %u) against (%ld, %ld, %d, %u)",
                         (unsigned)L, (unsigned long)seed, (unsigned long)k, (unsigned)i, (long)a->csum,
                         (long)a->lvl, a->thr, a->k, (long)b->csum, (long)b->lvl, b->thr, b->k);
            }
        }
        v_prev = vq;
    }
    return falls;
}

static void test_empty_band(void **state)
{
    (void)state;
    static const uint16_t planes[] = {10u, 20u, 30u};
    for (size_t i = 0; i < N_OF(planes); i++) {
        for (int sums = 0; sums <= 1; sums++) {
            unsigned rising = 0u;
            const unsigned falls = empty_check(planes[i], 15485863u + planes[i], 3000u, sums, &rising);
            /* about one tick in six each way: some 500 of 3000 */
            assert_true(falls >= 250u && rising >= 250u);
        }
    }
}

static enum piezo_err init_with(const struct piezo_dcc_coeffs *c, size_t n_state)
{
    struct piezo_dcc d;
    return piezo_dcc_init(&d, c, cpsi_a, zo_a, n_state);
}

static void test_init_refuses_bad_coefficients(void **state)
{
    (void)state;
    struct piezo_dcc d;
    struct piezo_dcc_coeffs c = dcc_std;
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_init(NULL, &c, cpsi_a, zo_a, dcc_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(piezo_dcc_init(&d, NULL, cpsi_a, zo_a, dcc_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(piezo_dcc_init(&d, &c, NULL, zo_a, dcc_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(piezo_dcc_init(&d, &c, cpsi_a, NULL, dcc_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(init_with(&c, dcc_std_NOPS - 1u), PIEZO_ERANGE);
    c = dcc_std; c.c_q24 = NULL;
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_EINVAL);
    c = dcc_std; c.g_q24 = 0;
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_EINVAL);
    c = dcc_std; c.g_q24 = -(1 << 24);
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_EINVAL);
    c = dcc_std; c.g_q24 = 1;
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_OK);
    /* the grid is checked too */
    c = dcc_std; c.grid.n_ops = 0;
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_ERANGE);
    c = dcc_std; c.grid.slope_q16 = 0;
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_EINVAL);
    c = dcc_std; c.grid.n1_q15 = dcc_std_n2; c.grid.n2_q15 = dcc_std_n1; /* swapped */
    assert_int_equal(init_with(&c, dcc_std_NOPS), PIEZO_EORDER);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_golden_cases),
        cmocka_unit_test(test_psi_plus_compensation_is_input),
        cmocka_unit_test(test_split_run_and_shared_coeffs),
        cmocka_unit_test(test_reset_restores_initial_state),
        cmocka_unit_test(test_init_refuses_bad_coefficients),
        cmocka_unit_test(test_row_and_column_table_limits),
        cmocka_unit_test(test_runs_on_random_walks),
        cmocka_unit_test(test_step_matches_c_step),
        cmocka_unit_test(test_search_after_large_jumps),
        cmocka_unit_test(test_empty_band),
        cmocka_unit_test(test_prefix_sums_checked),
    };
    return cmocka_run_group_tests_name("dcc", tests, NULL, NULL);
}
