/* The EUPI model against the host golden model, bit for bit. */
#include "eupi.h"
#include "fixed_q.h"
#include "eupi_vectors.h"
#include "piezo_test.h"

#define NCPI GOLDEN_EUPI_NCPI
#define NUPI (GOLDEN_EUPI_NUR * GOLDEN_EUPI_NUA)

static const struct piezo_eupi_coef ref_coef = {
    {golden_eupi_r_cpi_q15, NULL, golden_eupi_b_q24, GOLDEN_EUPI_NCPI, 0},
    {golden_eupi_r_upi_q15, golden_eupi_a_upi_q24, golden_eupi_d_q24,
     GOLDEN_EUPI_NUR, GOLDEN_EUPI_NUA},
    golden_eupi_p_q24, GOLDEN_EUPI_A0_Q24, GOLDEN_EUPI_P0_Q24, GOLDEN_EUPI_NP,
};
static const struct piezo_eupi_coef hot_coef = {
    {golden_eupi_hot_r_cpi_q15, NULL, golden_eupi_hot_b_q24, GOLDEN_EUPI_HOT_NCPI, 0},
    {golden_eupi_hot_r_upi_q15, golden_eupi_hot_a_upi_q24, golden_eupi_hot_d_q24,
     GOLDEN_EUPI_HOT_NUR, GOLDEN_EUPI_HOT_NUA},
    golden_eupi_hot_p_q24, GOLDEN_EUPI_HOT_A0_Q24, GOLDEN_EUPI_HOT_P0_Q24,
    GOLDEN_EUPI_HOT_NP,
};

static int32_t state_buf[NCPI + NUPI];
#define NWORK PIEZO_EUPI_WORK_LEN(GOLDEN_EUPI_NUR, GOLDEN_EUPI_NUA)
static int64_t work_buf[NWORK];

static void run_case(const char *name, const struct piezo_eupi_coef *coef,
                     const int16_t *u, const int16_t *y, size_t n)
{
    struct piezo_eupi m;
    assert_int_equal(piezo_eupi_init(&m, coef, state_buf, NCPI + NUPI, work_buf, NWORK),
                     PIEZO_OK);
    for (size_t k = 0; k < n; k++) {
        assert_golden_i32(name, k, piezo_eupi_process(&m, u[k]), y[k]);
    }
}

#define RUN(tag, TAG) \
    run_case(#tag, &ref_coef, golden_eupi_##tag##_u, golden_eupi_##tag##_y, GOLDEN_EUPI_##TAG##_N)

static void test_random(void **state) { (void)state; RUN(random, RANDOM); }
static void test_realistic(void **state) { (void)state; RUN(realistic, REALISTIC); }
static void test_steps(void **state) { (void)state; RUN(steps, STEPS); }
static void test_reversals(void **state) { (void)state; RUN(reversals, REVERSALS); }
static void test_constant(void **state) { (void)state; RUN(constant, CONSTANT); }
static void test_edges(void **state) { (void)state; RUN(edges, EDGES); }

/* A model whose output clamps at both ends: the C clamps where the golden does. */
static void test_output_saturates_like_golden(void **state)
{
    (void)state;
    run_case("hot edges", &hot_coef, golden_eupi_edges_u, golden_eupi_hot_edges_y,
             GOLDEN_EUPI_EDGES_N);
}

/* Two instances share the coefficients; the realistic run continues across
 * the split while the other instance runs and is reset in between. */
static void test_split_run_carries_state(void **state)
{
    (void)state;
    static int32_t st2[NCPI + NUPI];
    static int64_t wk2[NWORK];
    struct piezo_eupi a;
    struct piezo_eupi b;
    assert_int_equal(piezo_eupi_init(&a, &ref_coef, state_buf, NCPI + NUPI, work_buf, NWORK),
                     PIEZO_OK);
    assert_int_equal(piezo_eupi_init(&b, &ref_coef, st2, NCPI + NUPI, wk2, NWORK), PIEZO_OK);
    for (size_t k = 0; k < GOLDEN_EUPI_SPLIT_HALF; k++) {
        assert_golden_i32("split block 1", k,
                          piezo_eupi_process(&a, golden_eupi_realistic_u[k]),
                          golden_eupi_split_y[k]);
        (void)piezo_eupi_process(&b, golden_eupi_random_u[k % GOLDEN_EUPI_RANDOM_N]);
    }
    piezo_eupi_reset(&b);
    for (size_t k = GOLDEN_EUPI_SPLIT_HALF; k < GOLDEN_EUPI_REALISTIC_N; k++) {
        (void)piezo_eupi_process(&b, golden_eupi_steps_u[k % GOLDEN_EUPI_STEPS_N]);
        assert_golden_i32("split block 2", k,
                          piezo_eupi_process(&a, golden_eupi_realistic_u[k]),
                          golden_eupi_split_y[k]);
    }
    /* Reset gives the run from the start again. */
    piezo_eupi_reset(&a);
    for (size_t k = 0; k < 50; k++) {
        assert_golden_i32("after reset", k,
                          piezo_eupi_process(&a, golden_eupi_realistic_u[k]),
                          golden_eupi_realistic_y[k]);
    }
}

/* Horner by hand: P(u) = p0 + p2 u^2 + p3 u^3 at u = 0.5 with p2 = 0.5,
 * p3 = 0.25, p0 = 0.125: 0.125 + 0.125 + 0.03125 = 0.28125. */
static void test_poly_by_hand(void **state)
{
    (void)state;
    const int32_t p[2] = {PIEZO_Q24_ONE / 2, PIEZO_Q24_ONE / 4};
    const int64_t got = piezo_eupi_poly_q39(p, 2, PIEZO_Q24_ONE / 8, 16384);
    assert_true(got == ((int64_t)9 << 34)); /* 0.28125 = 9 / 32 in Q39 */
    assert_true(piezo_eupi_poly_q39(p, 0, -PIEZO_Q24_ONE, 12345) == -((int64_t)1 << 39));
}

static void test_init_refuses_bad_coefficients(void **state)
{
    (void)state;
    int32_t r[2] = {0, 16384};
    int32_t b[2] = {PIEZO_Q24_ONE / 10, PIEZO_Q24_ONE / 10};
    int32_t ru[2] = {0, 8192};
    int32_t au[2] = {PIEZO_Q24_ONE / 2, 2 * PIEZO_Q24_ONE};
    int32_t d[4] = {1000, 2000, 3000, 4000};
    int32_t p[2] = {PIEZO_Q24_ONE / 20, -PIEZO_Q24_ONE / 50};
    struct piezo_eupi_coef c = {
        {r, NULL, b, 2, 0}, {ru, au, d, 2, 2}, p, PIEZO_Q24_ONE / 2, 0, 2,
    };
    struct piezo_eupi m;
    int32_t st[6];
    int64_t wk[5]; /* 2 x 2 operators and the columns' rest counts */

    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_OK);
    assert_int_equal(piezo_eupi_init(&m, &c, st, 5, wk, 5), PIEZO_ERANGE);
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 4), PIEZO_ERANGE);
    assert_int_equal(piezo_eupi_init(&m, &c, NULL, 6, wk, 5), PIEZO_EINVAL);
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, NULL, 0), PIEZO_EINVAL);
    c.a0_q24 = 0;
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    c.a0_q24 = -5;
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    c.a0_q24 = PIEZO_Q24_ONE / 2;
    b[1] = -1; /* CPI weight < 0 */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    b[1] = 7;
    d[3] = -1; /* UPI weight < 0 */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    d[3] = 4000;
    r[1] = 32768; /* threshold not below 1 */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    r[1] = -2; /* negative threshold */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    r[1] = 16384;
    ru[0] = 9000; /* UPI thresholds descending */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EORDER);
    ru[0] = 0;
    r[0] = 20000; /* CPI thresholds descending */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EORDER);
    r[0] = 0;
    au[1] = 0; /* a_j must be > 0 */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    au[1] = 2 * PIEZO_Q24_ONE;
    c.upi.n_a = 0; /* a UPI grid without slopes */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    c.upi.n_a = 2;
    c.cpi.n_a = 1; /* the CPI bank is classical */
    c.cpi.a_q24 = au;
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    c.cpi.n_a = 0;
    c.n_p = PIEZO_EUPI_MAX_POLY + 1u;
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_ERANGE);
    c.n_p = 2;
    p[0] = INT32_MAX; /* 128 */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    /* The bound is strict (round 18): sum = 64 lets h reach 2^30 (eupi.h). */
    p[0] = (int32_t)(PIEZO_EUPI_POLY_SUM_MAX_Q24 - PIEZO_Q24_ONE / 50); /* sum = 64 */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_EINVAL);
    p[0] -= 1; /* sum = 64 - 2^-24 */
    assert_int_equal(piezo_eupi_init(&m, &c, st, 6, wk, 5), PIEZO_OK);
}

/* The Horner steps as the 64-bit product, round and shift (eupi.h's
 * Rounding), written apart from the kernel's SMMULR form. */
static int32_t poly_hu_ref(const int32_t *p, uint16_t n_p, int16_t u)
{
    int64_t h = p[n_p - 1u];
    for (uint16_t m = n_p - 1u; m > 0u; m--) {
        h = piezo_rshift_rnd64(h * u, 15u) + p[m - 1u];
    }
    return (int32_t)piezo_rshift_rnd64(h * u, 15u);
}

/* At the strict bound's edge, sum |p_m| = 2^30 - 1: the SMMULR steps give
 * the 64-bit form's integers on every q15 input, u = -1 and 1 - 2^-15
 * included, with h as large as the bound allows (both signs, 1 to 3
 * terms). The largest coefficient first makes |h| = 2^30 - 1 at u = -1. */
static void test_poly_at_the_strict_bound(void **state)
{
    (void)state;
    const int32_t top = (int32_t)(PIEZO_EUPI_POLY_SUM_MAX_Q24 - 1);
    const int32_t sets[][3] = {
        {top, 0, 0},
        {-top, 0, 0},
        {1, top - 1, 0},
        {-(top / 2), top - top / 2, 0},
        {top / 3, -(top / 3), top - 2 * (top / 3)},
        {-5, 12345, -(top - 12350)},
    };
    const uint16_t n[] = {1, 1, 2, 2, 3, 3};
    for (size_t s = 0; s < sizeof n / sizeof n[0]; s++) {
        int64_t sum = 0;
        for (uint16_t m = 0; m < n[s]; m++) {
            sum += sets[s][m] < 0 ? -(int64_t)sets[s][m] : sets[s][m];
        }
        assert_true(sum == PIEZO_EUPI_POLY_SUM_MAX_Q24 - 1);
        for (int32_t u = -32768; u <= 32767; u += (u > -32700 && u < 32700) ? 97 : 1) {
            const int16_t uq = (int16_t)u;
            assert_int_equal(piezo_eupi_poly_hu_q24(sets[s], n[s], uq), poly_hu_ref(sets[s], n[s], uq));
        }
    }
    /* |hu| reaches the bound: hu = -(2^30 - 1) for p = {2^30 - 1}, u = -1. */
    assert_int_equal(piezo_eupi_poly_hu_q24(sets[0], 1, INT16_MIN), -top);
}

/* Every length the switch of piezo_eupi_poly_hu_q24 enters at (round 18:
 * the steps unrolled, one jump on n_p to the first term's load): n_p = 0
 * to PIEZO_EUPI_MAX_POLY against the 64-bit Horner above, coefficients of
 * both signs and of different sizes (so that a step entered at the wrong
 * term, or a term read twice, changes hu), every 61st q15 input and both
 * ends. */
static void test_poly_every_length(void **state)
{
    (void)state;
    const int32_t p[PIEZO_EUPI_MAX_POLY] = {
        50343993, -117441511, 83886157, -33585769,
        184553618, -16777233, 100935124, -151309103,
    }; /* Q7.24: 3, -7, 5, -2, 11, -1, 6, -9 and a little; sum |p_m| < 45 < 64 */
    for (int32_t u = -32768; u <= 32767; u += 61) {
        assert_int_equal(piezo_eupi_poly_hu_q24(p, 0u, (int16_t)u), 0);
    }
    for (uint16_t n = 1u; n <= PIEZO_EUPI_MAX_POLY; n++) {
        for (int32_t u = -32768; u <= 32767; u += (u > -32700 && u < 32700) ? 61 : 1) {
            const int16_t uq = (int16_t)u;
            assert_int_equal(piezo_eupi_poly_hu_q24(p, n, uq), poly_hu_ref(p, n, uq));
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_random),
        cmocka_unit_test(test_realistic),
        cmocka_unit_test(test_steps),
        cmocka_unit_test(test_reversals),
        cmocka_unit_test(test_constant),
        cmocka_unit_test(test_edges),
        cmocka_unit_test(test_output_saturates_like_golden),
        cmocka_unit_test(test_split_run_carries_state),
        cmocka_unit_test(test_poly_by_hand),
        cmocka_unit_test(test_init_refuses_bad_coefficients),
        cmocka_unit_test(test_poly_at_the_strict_bound),
        cmocka_unit_test(test_poly_every_length),
    };
    return cmocka_run_group_tests_name("eupi", tests, NULL, NULL);
}
