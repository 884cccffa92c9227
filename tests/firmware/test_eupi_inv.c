/* The EUPI inverse compensator against the host golden model, bit for bit. */
#include "eupi_inv.h"
#include "fixed_q.h"
#include "eupi_inv_vectors.h"
#include "piezo_test.h"

#define NCPI GOLDEN_EUPI_INV_NCPI
#define NUPI (GOLDEN_EUPI_INV_NUR * GOLDEN_EUPI_INV_NUA)

static const struct piezo_eupi_inv_coef ref_coef = {
    {golden_eupi_inv_r_cpi_q15, NULL, golden_eupi_inv_b_q24, GOLDEN_EUPI_INV_NCPI, 0},
    {golden_eupi_inv_r_upi_q15, golden_eupi_inv_a_upi_q24, golden_eupi_inv_d_q24,
     GOLDEN_EUPI_INV_NUR, GOLDEN_EUPI_INV_NUA},
    golden_eupi_inv_p_q24, GOLDEN_EUPI_INV_A0I_Q24, GOLDEN_EUPI_INV_KEX_Q24,
    GOLDEN_EUPI_INV_P0_Q24, GOLDEN_EUPI_INV_NP,
};

static int32_t state_buf[NCPI + NUPI];
#define NWORK PIEZO_EUPI_INV_WORK_LEN(GOLDEN_EUPI_INV_NUR, GOLDEN_EUPI_INV_NUA)
static int64_t work_buf[NWORK];

static void run_case(const char *name, const int16_t *yr, const int16_t *u, size_t n)
{
    struct piezo_eupi_inv c;
    assert_int_equal(piezo_eupi_inv_init(&c, &ref_coef, state_buf, NCPI + NUPI,
                                         work_buf, NWORK), PIEZO_OK);
    for (size_t k = 0; k < n; k++) {
        assert_golden_i32(name, k, piezo_eupi_inv_process(&c, yr[k]), u[k]);
    }
}

#define RUN(tag, TAG)                                                                 \
    run_case(#tag, golden_eupi_inv_##tag##_yr, golden_eupi_inv_##tag##_u,            \
             GOLDEN_EUPI_INV_##TAG##_N)

static void test_random(void **state) { (void)state; RUN(random, RANDOM); }
static void test_realistic(void **state) { (void)state; RUN(realistic, REALISTIC); }
static void test_steps(void **state) { (void)state; RUN(steps, STEPS); }
static void test_reversals(void **state) { (void)state; RUN(reversals, REVERSALS); }
static void test_constant(void **state) { (void)state; RUN(constant, CONSTANT); }

/* Full-scale yr asks for more than the model gives: the drive clamps to q15
 * at both ends exactly where the golden model clamps. */
static void test_edges_clamp_like_golden(void **state)
{
    (void)state;
    int seen_max = 0;
    int seen_min = 0;
    for (size_t k = 0; k < GOLDEN_EUPI_INV_EDGES_N; k++) {
        seen_max |= golden_eupi_inv_edges_u[k] == PIEZO_Q15_MAX;
        seen_min |= golden_eupi_inv_edges_u[k] == PIEZO_Q15_MIN;
    }
    assert_true(seen_max && seen_min);
    RUN(edges, EDGES);
}

static void test_split_run_carries_state(void **state)
{
    (void)state;
    static int32_t st2[NCPI + NUPI];
    static int64_t wk2[NWORK];
    struct piezo_eupi_inv a;
    struct piezo_eupi_inv b;
    assert_int_equal(piezo_eupi_inv_init(&a, &ref_coef, state_buf, NCPI + NUPI, work_buf, NWORK),
                     PIEZO_OK);
    assert_int_equal(piezo_eupi_inv_init(&b, &ref_coef, st2, NCPI + NUPI, wk2, NWORK), PIEZO_OK);
    for (size_t k = 0; k < GOLDEN_EUPI_INV_SPLIT_HALF; k++) {
        assert_golden_i32("split block 1", k,
                          piezo_eupi_inv_process(&a, golden_eupi_inv_realistic_yr[k]),
                          golden_eupi_inv_split_u[k]);
        (void)piezo_eupi_inv_process(&b, golden_eupi_inv_random_yr[k % GOLDEN_EUPI_INV_RANDOM_N]);
    }
    piezo_eupi_inv_reset(&b);
    for (size_t k = GOLDEN_EUPI_INV_SPLIT_HALF; k < GOLDEN_EUPI_INV_REALISTIC_N; k++) {
        (void)piezo_eupi_inv_process(&b, golden_eupi_inv_edges_yr[k % GOLDEN_EUPI_INV_EDGES_N]);
        assert_golden_i32("split block 2", k,
                          piezo_eupi_inv_process(&a, golden_eupi_inv_realistic_yr[k]),
                          golden_eupi_inv_split_u[k]);
    }
    piezo_eupi_inv_reset(&a);
    for (size_t k = 0; k < 50; k++) {
        assert_golden_i32("after reset", k,
                          piezo_eupi_inv_process(&a, golden_eupi_inv_realistic_yr[k]),
                          golden_eupi_inv_realistic_u[k]);
    }
}

/* A pure linear model by hand: y = 0.5 u, so the inverse is u = 2 yr;
 * P = p0 = 0.25 is subtracted: u = 2 (yr - 0.25). */
static void test_linear_by_hand(void **state)
{
    (void)state;
    const struct piezo_eupi_inv_coef c = {
        {NULL, NULL, NULL, 0, 0}, {NULL, NULL, NULL, 0, 0}, NULL,
        2 * PIEZO_Q24_ONE, 0, PIEZO_Q24_ONE / 4, 0,
    };
    struct piezo_eupi_inv inv;
    int32_t st[1];
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 1, NULL, 0), PIEZO_OK);
    assert_int_equal(piezo_eupi_inv_process(&inv, 16384), 16384);   /* 2 (0.5 - 0.25) */
    assert_int_equal(piezo_eupi_inv_process(&inv, -4096), -24576);  /* 2 (-0.125 - 0.25) */
    assert_int_equal(piezo_eupi_inv_process(&inv, 32767), 32767);   /* 1.5: clamped */
    assert_int_equal(piezo_eupi_inv_process(&inv, -32768), -32768);  /* -2.5: clamped */
}

static void test_init_refuses_bad_coefficients(void **state)
{
    (void)state;
    int32_t ri[2] = {0, 40000}; /* inverse thresholds may exceed 1.0 */
    int32_t bi[2] = {-PIEZO_Q24_ONE / 4, -PIEZO_Q24_ONE / 8};
    int32_t ru[1] = {1000};
    int32_t au[2] = {PIEZO_Q24_ONE / 2, 2 * PIEZO_Q24_ONE};
    int32_t d[2] = {PIEZO_Q24_ONE / 100, PIEZO_Q24_ONE / 100};
    int32_t p[1] = {PIEZO_Q24_ONE / 20};
    struct piezo_eupi_inv_coef c = {
        {ri, NULL, bi, 2, 0}, {ru, au, d, 1, 2}, p, 2 * PIEZO_Q24_ONE, PIEZO_Q24_ONE / 10, 0, 1,
    };
    struct piezo_eupi_inv inv;
    int32_t st[4];
    int64_t wk[3]; /* 2 operators and the columns' rest counts */

    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_OK);
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 3, wk, 3), PIEZO_ERANGE);
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 2), PIEZO_ERANGE);
    assert_int_equal(piezo_eupi_inv_init(&inv, NULL, st, 4, wk, 3), PIEZO_EINVAL);
    c.a0_inv_q24 = 0;
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_EINVAL);
    c.a0_inv_q24 = 2 * PIEZO_Q24_ONE;
    ri[1] = PIEZO_PLAY_WIDE_MAX_Q15 + 1; /* beyond the wide range */
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_EINVAL);
    ri[1] = 0;
    ri[0] = 5; /* descending */
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_EORDER);
    ri[0] = 0;
    d[0] = -1; /* UPI weights stay >= 0 */
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_EINVAL);
    d[0] = PIEZO_Q24_ONE / 100;
    au[0] = -1;
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_EINVAL);
    au[0] = PIEZO_Q24_ONE / 2;
    ru[0] = 32768; /* UPI threshold not below 1 */
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_EINVAL);
    ru[0] = 1000;
    c.kex_q24 = 16 * PIEZO_Q24_ONE; /* |G2| bound above 16 FS */
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_EINVAL);
    c.kex_q24 = -PIEZO_Q24_ONE; /* k_ex of either sign is fine */
    assert_int_equal(piezo_eupi_inv_init(&inv, &c, st, 4, wk, 3), PIEZO_OK);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_random),
        cmocka_unit_test(test_realistic),
        cmocka_unit_test(test_steps),
        cmocka_unit_test(test_reversals),
        cmocka_unit_test(test_constant),
        cmocka_unit_test(test_edges_clamp_like_golden),
        cmocka_unit_test(test_split_run_carries_state),
        cmocka_unit_test(test_linear_by_hand),
        cmocka_unit_test(test_init_refuses_bad_coefficients),
    };
    return cmocka_run_group_tests_name("eupi_inv", tests, NULL, NULL);
}
