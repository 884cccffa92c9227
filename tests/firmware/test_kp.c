/* KP operators and model (firmware/core/kp.c) against the host golden model
 * (host/piezoctl/golden/kp.py), bit for bit, plus init's refusals. */
#include <string.h>

#include "piezo_test.h"
#include "kp.h"
#include "kp_vectors.h"

#define GRID_OF(p)                                                                  \
    {                                                                               \
        .n1_q15 = p##_n1, .n2_q15 = p##_n2, .n_ops = p##_NOPS, .nmin_q15 = p##_NMIN, \
        .rmax_q15 = p##_RMAX, .slope_q16 = p##_SLOPE, .xsat_q15 = p##_XSAT          \
    }

static const struct piezo_kp_coeffs kp_std = {.grid = GRID_OF(kp_std), .w_q24 = kp_std_w};
static const struct piezo_kp_coeffs kp_edge = {.grid = GRID_OF(kp_edge), .w_q24 = kp_edge_w};
static const struct piezo_kp_coeffs kp_flat = {.grid = GRID_OF(kp_flat), .w_q24 = kp_flat_w};

struct kp_case {
    const char *name;
    const struct piezo_kp_coeffs *c;
    const int16_t *u;
    const int16_t *y;
    size_t n;
};

#define KP_CASE(name, set) \
    {#name, &set, kp_case_##name##_u, kp_case_##name##_y, sizeof(kp_case_##name##_u) / sizeof(int16_t)},
static const struct kp_case cases[] = {KP_GOLDEN_CASES(KP_CASE)};
#define N_CASES (sizeof(cases) / sizeof(cases[0]))

static int16_t psi_a[PIEZO_KP_MAX_OPS];
static int16_t psi_b[PIEZO_KP_MAX_OPS];

static void run_block(struct piezo_kp *kp, const struct kp_case *c, size_t k0, size_t k1)
{
    char label[64];
    snprintf(label, sizeof label, "kp %s", c->name);
    for (size_t k = k0; k < k1; k++) {
        assert_golden_i32(label, k, piezo_kp_process(kp, c->u[k]), c->y[k]);
    }
}

static void test_golden_cases(void **state)
{
    (void)state;
    assert_true(N_CASES >= 9u);
    for (size_t i = 0; i < N_CASES; i++) {
        struct piezo_kp kp;
        assert_int_equal(piezo_kp_init(&kp, cases[i].c, psi_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
        run_block(&kp, &cases[i], 0, cases[i].n);
    }
}

static const struct kp_case *find_case(const char *name)
{
    for (size_t i = 0; i < N_CASES; i++) {
        if (strcmp(cases[i].name, name) == 0) {
            return &cases[i];
        }
    }
    fail_msg("no golden case %s", name);
    return NULL;
}

/* Two process loops with a pause between them (another instance sharing the
 * coefficients runs meanwhile): the state carries over; the end state matches. */
static void test_split_run_and_shared_coeffs(void **state)
{
    (void)state;
    const struct kp_case *c = find_case("realistic");
    const struct kp_case *other = find_case("random");
    struct piezo_kp a, b;
    assert_int_equal(piezo_kp_init(&a, &kp_std, psi_a, kp_std_NOPS), PIEZO_OK);
    assert_int_equal(piezo_kp_init(&b, &kp_std, psi_b, kp_std_NOPS), PIEZO_OK);
    const size_t split = c->n / 3u + 17u;
    run_block(&a, c, 0, split);
    run_block(&b, other, 0, other->n);
    run_block(&a, c, split, c->n);
    for (size_t j = 0; j < kp_std_NOPS; j++) {
        assert_golden_i32("kp realistic psi_end", j, psi_a[j], kp_case_realistic_psi_end[j]);
    }
}

static void test_reset_restores_initial_state(void **state)
{
    (void)state;
    const struct kp_case *c = find_case("steps");
    struct piezo_kp kp;
    assert_int_equal(piezo_kp_init(&kp, &kp_std, psi_a, kp_std_NOPS), PIEZO_OK);
    run_block(&kp, find_case("random"), 0, 500);
    piezo_kp_reset(&kp);
    for (size_t j = 0; j < kp_std_NOPS; j++) {
        assert_int_equal(psi_a[j], 0);
    }
    assert_int_equal(kp.u_prev_q15, kp_std_NMIN);
    run_block(&kp, c, 0, c->n);
}

/* The ridge at its corners: 0 up to x = 0, rmax from xsat on, rounded between. */
static void test_ridge_corners(void **state)
{
    (void)state;
    const struct piezo_kp_grid *g = &kp_std.grid;
    assert_int_equal(piezo_kp_ridge_q15(g, -65535), 0);
    assert_int_equal(piezo_kp_ridge_q15(g, 0), 0);
    assert_int_equal(piezo_kp_ridge_q15(g, g->xsat_q15), g->rmax_q15);
    assert_int_equal(piezo_kp_ridge_q15(g, 65535), g->rmax_q15);
    assert_true(piezo_kp_ridge_q15(g, g->xsat_q15 - 1) < g->rmax_q15);
    int32_t last = 0;
    for (int32_t x = -10; x <= g->xsat_q15 + 10; x++) {
        const int32_t r = piezo_kp_ridge_q15(g, x);
        assert_true(r >= last);
        last = r;
    }
}

static int16_t bad_n1[kp_std_NOPS];
static int16_t bad_n2[kp_std_NOPS];

static enum piezo_err init_with(const struct piezo_kp_coeffs *c, size_t n_state)
{
    struct piezo_kp kp;
    return piezo_kp_init(&kp, c, psi_a, n_state);
}

static void test_init_refuses_bad_coefficients(void **state)
{
    (void)state;
    struct piezo_kp kp;
    struct piezo_kp_coeffs c = kp_std;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_OK);

    assert_int_equal(piezo_kp_init(NULL, &c, psi_a, kp_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(piezo_kp_init(&kp, NULL, psi_a, kp_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(piezo_kp_init(&kp, &c, NULL, kp_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(init_with(&c, kp_std_NOPS - 1u), PIEZO_ERANGE);

    c = kp_std; c.w_q24 = NULL;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    c = kp_std; c.grid.n1_q15 = NULL;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    c = kp_std; c.grid.n_ops = 0;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_ERANGE);
    c = kp_std; c.grid.n_ops = (uint16_t)(PIEZO_KP_MAX_OPS + 1u);
    assert_int_equal(init_with(&c, PIEZO_KP_MAX_OPS + 1u), PIEZO_ERANGE);

    /* n1 > n2 on one operator */
    memcpy(bad_n1, kp_std_n1, sizeof bad_n1);
    memcpy(bad_n2, kp_std_n2, sizeof bad_n2);
    bad_n1[7] = (int16_t)(bad_n2[7] + 1);
    c = kp_std; c.grid.n1_q15 = bad_n1; c.grid.n2_q15 = bad_n2;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EORDER);

    c = kp_std; c.grid.rmax_q15 = 0;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    c = kp_std; c.grid.rmax_q15 = -5;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    c = kp_std; c.grid.slope_q16 = 0;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    c = kp_std; c.grid.xsat_q15 = 0;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    /* xsat one too high (not the first saturating x) or one too low */
    c = kp_std; c.grid.xsat_q15 = kp_std_XSAT + 1;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    c = kp_std; c.grid.xsat_q15 = kp_std_XSAT - 1;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    /* a slope that no longer matches xsat */
    c = kp_std; c.grid.slope_q16 = kp_std_SLOPE / 2;
    assert_int_equal(init_with(&c, kp_std_NOPS), PIEZO_EINVAL);
    /* a refused init leaves the instance unbound */
    kp.coeffs = &kp_std;
    c = kp_std; c.grid.rmax_q15 = 0;
    assert_int_equal(piezo_kp_init(&kp, &c, psi_a, kp_std_NOPS), PIEZO_EINVAL);
    assert_null(kp.coeffs);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_golden_cases),
        cmocka_unit_test(test_split_run_and_shared_coeffs),
        cmocka_unit_test(test_reset_restores_initial_state),
        cmocka_unit_test(test_ridge_corners),
        cmocka_unit_test(test_init_refuses_bad_coefficients),
    };
    return cmocka_run_group_tests_name("kp", tests, NULL, NULL);
}
