/* Cross-coupling predictor (firmware/core/xcouple.c) against the host golden
 * model (host/piezoctl/golden/xcouple.py), bit for bit, plus init's refusals. */
#include <string.h>

#include "piezo_test.h"
#include "piezo_err.h"
#include "xcouple.h"
#include "xcouple_vectors.h"

struct xc_case {
    const char *name;
    struct piezo_xc_coef k;
    const int16_t *u, *x, *y;
    size_t n;
};

#define XC_CASE(p)                                                                                   \
    {#p,                                                                                             \
     {.m = xc_##p##_M, .n_ch = xc_##p##_NCH, .n_pow = xc_##p##_NPOW, .n_deg = xc_##p##_NDEG,           \
      .u_center_q15 = xc_##p##_UC, .u_gain_q16 = xc_##p##_UG, .x_center_q15 = xc_##p##_XC,            \
      .x_gain_q16 = xc_##p##_XG, .a_q24 = xc_##p##_a, .b_q24 = xc_##p##_b, .e_q24 = xc_##p##_e,        \
      .eta_q24 = xc_##p##_eta, .xi_q24 = xc_##p##_xi},                                                \
     xc_##p##_u, xc_##p##_x, xc_##p##_y, sizeof(xc_##p##_u) / sizeof(int16_t)},
static const struct xc_case cases[] = {XC_GOLDEN_CASES(XC_CASE)};
#define N_CASES (sizeof(cases) / sizeof(cases[0]))

static void run(struct piezo_xc *s, const struct xc_case *c, size_t k0, size_t k1)
{
    char label[64];
    snprintf(label, sizeof label, "xcouple %s", c->name);
    for (size_t k = k0; k < k1; k++) {
        assert_golden_i32(label, k, piezo_xc_process(s, c->u[k], c->x[k]), c->y[k]);
    }
}

static void test_golden_cases(void **state)
{
    (void)state;
    assert_true(N_CASES >= 6u);
    for (size_t i = 0; i < N_CASES; i++) {
        struct piezo_xc s;
        assert_int_equal(piezo_xc_init(&s, &cases[i].k), PIEZO_OK);
        run(&s, &cases[i], 0, cases[i].n);
    }
}

/* reset mid-run: the second half restarts at its first input's equilibrium,
 * which is what a fresh instance fed only the second half computes */
static void test_reset_restarts_at_equilibrium(void **state)
{
    (void)state;
    const struct xc_case *c = &cases[0];
    struct piezo_xc a, b;
    size_t h = c->n / 2;
    assert_int_equal(piezo_xc_init(&a, &c->k), PIEZO_OK);
    assert_int_equal(piezo_xc_init(&b, &c->k), PIEZO_OK);
    for (size_t k = 0; k < h; k++) {
        (void)piezo_xc_process(&a, c->u[k], c->x[k]);
    }
    piezo_xc_reset(&a);
    for (size_t k = h; k < c->n; k++) {
        assert_int_equal(piezo_xc_process(&a, c->u[k], c->x[k]), piezo_xc_process(&b, c->u[k], c->x[k]));
    }
    assert_true(memcmp(a.zeta_q24, b.zeta_q24, sizeof a.zeta_q24) == 0);
}

/* a constant input from the start gives a constant output (steady start) */
static void test_constant_input_is_steady(void **state)
{
    (void)state;
    struct piezo_xc s;
    int16_t y0;
    assert_int_equal(piezo_xc_init(&s, &cases[0].k), PIEZO_OK);
    y0 = piezo_xc_process(&s, 12345, -2222);
    assert_true(y0 != 0);
    for (int k = 0; k < 300; k++) {
        int16_t y = piezo_xc_process(&s, 12345, -2222);
        assert_true(y >= y0 - 1 && y <= y0 + 1); /* rounding of E only */
    }
}

static void test_init_refusals(void **state)
{
    (void)state;
    const struct piezo_xc_coef *k0 = &cases[0].k; /* m = 2, two channels */
    struct piezo_xc s;
    struct piezo_xc_coef k;
    int32_t a[4], eta[64], xi[32], b[2];
    assert_int_equal(piezo_xc_init(NULL, k0), PIEZO_EINVAL);
    assert_int_equal(piezo_xc_init(&s, NULL), PIEZO_EINVAL);
#define FRESH() do { k = *k0; memcpy(a, k0->a_q24, sizeof a); memcpy(b, k0->b_q24, sizeof b);            \
                     memcpy(eta, k0->eta_q24, sizeof(int32_t) * k0->n_ch * k0->n_pow * k0->n_deg);     \
                     memcpy(xi, k0->xi_q24, sizeof(int32_t) * k0->n_ch * k0->m * k0->n_deg);           \
                     k.a_q24 = a; k.b_q24 = b; k.eta_q24 = eta; k.xi_q24 = xi; } while (0)
    FRESH();
    assert_int_equal(piezo_xc_init(&s, &k), PIEZO_OK);
    FRESH(); k.m = 0; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_EINVAL);
    FRESH(); k.m = PIEZO_XC_MAX_M + 1u; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_EINVAL);
    FRESH(); k.n_ch = 3; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_EINVAL);
    FRESH(); k.n_pow = PIEZO_XC_MAX_POW + 1u; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_EINVAL);
    FRESH(); k.n_deg = 0; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_EINVAL);
    FRESH(); k.u_gain_q16 = 0; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
    FRESH(); k.x_center_q15 = 40000; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
    /* A not lower triangular, an unstable diagonal, a negative pole */
    FRESH(); a[1] = 1; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
    FRESH(); a[0] = 1 << 24; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
    FRESH(); a[3] = -1; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
    /* a pole so slow that no state bound 2^(24+10) holds */
    FRESH(); a[0] = (1 << 24) - 2000; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
    /* sum |eta_c| above 1, by one LSB */
    FRESH();
    {
        int64_t sum = 0;
        for (uint32_t q = 0; q < (uint32_t)k.n_pow * k.n_deg; q++) {
            sum += eta[q] < 0 ? -(int64_t)eta[q] : eta[q];
        }
        eta[0] += (eta[0] >= 0 ? 1 : -1) * (int32_t)((1 << 24) - sum);
        assert_int_equal(piezo_xc_init(&s, &k), PIEZO_OK); /* exactly 1: allowed */
        eta[0] += eta[0] >= 0 ? 1 : -1;
        assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
    }
    /* filter 0's output weights beyond 2^(35 - s_0) (s_0 = 3 for the paper's
     * Laguerre pole): three full-scale int32 weights, 3 (2^31 - 1) > 2^32 */
    FRESH(); xi[0] = INT32_MAX; xi[1] = 0; xi[2] = 0; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_OK);
    xi[1] = INT32_MAX; xi[2] = INT32_MAX; assert_int_equal(piezo_xc_init(&s, &k), PIEZO_ERANGE);
#undef FRESH
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_golden_cases),
        cmocka_unit_test(test_reset_restarts_at_equilibrium),
        cmocka_unit_test(test_constant_input_is_steady),
        cmocka_unit_test(test_init_refusals),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
