/* Rate-dependent KP model (firmware/core/rkp.c) against the host golden model
 * (host/piezoctl/golden/rkp.py), bit for bit, plus init's refusals. */
#include <string.h>

#include "piezo_test.h"
#include "rkp.h"
#include "piezo_interface.h"
#include "rkp_vectors.h"

#define RKP_OF(p)                                                                       \
    {                                                                                   \
        .grid = {.n1_q15 = p##_n1, .n2_q15 = p##_n2, .n_ops = p##_NOPS,                 \
                 .nmin_q15 = p##_NMIN, .rmax_q15 = p##_RMAX, .slope_q16 = p##_SLOPE,    \
                 .xsat_q15 = p##_XSAT},                                                 \
        .theta_q24 = p##_theta, .center_q24 = p##_center, .inv_width_q16 = p##_inv_width, \
        .n_rbf = p##_NRBF, .alpha_q16 = p##_ALPHA                                       \
    }

static const struct piezo_rkp_coeffs rkp_std = RKP_OF(rkp_std);
static const struct piezo_rkp_coeffs rkp_edge = RKP_OF(rkp_edge);
static const struct piezo_rkp_coeffs rkp_slow = RKP_OF(rkp_slow);

struct rkp_case {
    const char *name;
    const struct piezo_rkp_coeffs *c;
    const int16_t *u;
    const int16_t *y;
    size_t n;
};

#define RKP_CASE(name, set) \
    {#name, &set, rkp_case_##name##_u, rkp_case_##name##_y, sizeof(rkp_case_##name##_u) / sizeof(int16_t)},
static const struct rkp_case cases[] = {RKP_GOLDEN_CASES(RKP_CASE)};
#define N_CASES (sizeof(cases) / sizeof(cases[0]))

static int16_t psi_a[PIEZO_KP_MAX_OPS], psi_b[PIEZO_KP_MAX_OPS];
static int32_t w_a[PIEZO_KP_MAX_OPS], w_b[PIEZO_KP_MAX_OPS];

static void run_block(struct piezo_rkp *r, const struct rkp_case *c, size_t k0, size_t k1)
{
    char label[64];
    snprintf(label, sizeof label, "rkp %s", c->name);
    for (size_t k = k0; k < k1; k++) {
        assert_golden_i32(label, k, piezo_rkp_process(r, c->u[k]), c->y[k]);
    }
}

static const struct rkp_case *find_case(const char *name)
{
    for (size_t i = 0; i < N_CASES; i++) {
        if (strcmp(cases[i].name, name) == 0) {
            return &cases[i];
        }
    }
    fail_msg("no golden case %s", name);
    return NULL;
}

static void test_gauss_lut_interpolation(void **state)
{
    (void)state;
    for (size_t k = 0; k < RKP_GAUSS_N; k++) {
        assert_golden_i32("gauss", k, piezo_rkp_gauss_q15(rkp_gauss_z_q16[k]), rkp_gauss_f_q15[k]);
    }
    assert_int_equal(piezo_rkp_gauss_q15(PIEZO_GAUSS_ZMAX_Q16), 0);
    assert_int_equal(piezo_rkp_gauss_q15(0), piezo_gauss_lut_q15[0]);
}

static void test_golden_cases(void **state)
{
    (void)state;
    assert_true(N_CASES >= 10u);
    for (size_t i = 0; i < N_CASES; i++) {
        struct piezo_rkp r;
        assert_int_equal(piezo_rkp_init(&r, cases[i].c, psi_a, w_a, PIEZO_KP_MAX_OPS), PIEZO_OK);
        run_block(&r, &cases[i], 0, cases[i].n);
    }
}

/* Two process loops with a pause (another instance sharing the coefficients
 * runs in between); the end state (operators, density, rate) matches. */
static void test_split_run_and_end_state(void **state)
{
    (void)state;
    const struct rkp_case *c = find_case("realistic");
    const struct rkp_case *other = find_case("alternating");
    struct piezo_rkp a, b;
    assert_int_equal(piezo_rkp_init(&a, &rkp_std, psi_a, w_a, rkp_std_NOPS), PIEZO_OK);
    assert_int_equal(piezo_rkp_init(&b, &rkp_std, psi_b, w_b, rkp_std_NOPS), PIEZO_OK);
    const size_t split = c->n / 2u + 3u;
    run_block(&a, c, 0, split);
    run_block(&b, other, 0, other->n);
    run_block(&a, c, split, c->n);
    for (size_t j = 0; j < rkp_std_NOPS; j++) {
        assert_golden_i32("rkp psi_end", j, psi_a[j], rkp_case_realistic_psi_end[j]);
        assert_golden_i32("rkp w_end", j, w_a[j], rkp_case_realistic_w_end[j]);
    }
    assert_golden_i32("rkp rate_end", 0, a.rate_q24, RKP_CASE_REALISTIC_RATE_END);
}

static void test_reset_restores_initial_state(void **state)
{
    (void)state;
    struct piezo_rkp r;
    assert_int_equal(piezo_rkp_init(&r, &rkp_std, psi_a, w_a, rkp_std_NOPS), PIEZO_OK);
    run_block(&r, find_case("random"), 0, 300);
    piezo_rkp_reset(&r);
    assert_int_equal(r.rate_q24, 0);
    assert_int_equal(r.u_prev_q15, rkp_std_NMIN);
    for (size_t j = 0; j < rkp_std_NOPS; j++) {
        assert_int_equal(psi_a[j], 0);
        assert_int_equal(w_a[j], 0);
    }
    const struct rkp_case *c = find_case("steps");
    run_block(&r, c, 0, c->n);
}

static int32_t bad_theta[sizeof(rkp_std_theta) / sizeof(int32_t)];
static int32_t bad_vec[rkp_std_NRBF];

static enum piezo_err init_with(const struct piezo_rkp_coeffs *c, size_t n_state)
{
    struct piezo_rkp r;
    return piezo_rkp_init(&r, c, psi_a, w_a, n_state);
}

static void test_init_refuses_bad_coefficients(void **state)
{
    (void)state;
    struct piezo_rkp r;
    struct piezo_rkp_coeffs c = rkp_std;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_OK);
    assert_int_equal(init_with(&rkp_edge, 10), PIEZO_OK); /* row sums exactly INT32_MAX */

    assert_int_equal(piezo_rkp_init(NULL, &c, psi_a, w_a, rkp_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(piezo_rkp_init(&r, &c, psi_a, NULL, rkp_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(piezo_rkp_init(&r, &c, NULL, w_a, rkp_std_NOPS), PIEZO_EINVAL);
    assert_int_equal(init_with(&c, rkp_std_NOPS - 1u), PIEZO_ERANGE);
    c = rkp_std; c.theta_q24 = NULL;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
    c = rkp_std; c.center_q24 = NULL;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
    c = rkp_std; c.inv_width_q16 = NULL;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
    c = rkp_std; c.n_rbf = 0;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_ERANGE);
    c = rkp_std; c.n_rbf = PIEZO_RKP_MAX_RBF + 1u;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_ERANGE);
    c = rkp_std; c.alpha_q16 = 0;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
    c = rkp_std; c.alpha_q16 = 65537;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
    c = rkp_std; c.alpha_q16 = 65536;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_OK);
    /* the grid is checked too */
    c = rkp_std; c.grid.xsat_q15 = rkp_std_XSAT + 1;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);

    memcpy(bad_vec, rkp_std_center, sizeof bad_vec);
    bad_vec[3] = PIEZO_RKP_MAX_CENTER_Q24 + 1;
    c = rkp_std; c.center_q24 = bad_vec;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
    bad_vec[3] = -PIEZO_RKP_MAX_CENTER_Q24 - 1;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
    bad_vec[3] = PIEZO_RKP_MAX_CENTER_Q24;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_OK);

    memcpy(bad_vec, rkp_std_inv_width, sizeof bad_vec);
    bad_vec[12] = 0;
    c = rkp_std; c.inv_width_q16 = bad_vec;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);

    /* one operator's sum_m |Theta_jm| one past INT32_MAX */
    memcpy(bad_theta, rkp_std_theta, sizeof bad_theta);
    const size_t j = 20;
    for (size_t m = 0; m < rkp_std_NRBF; m++) {
        bad_theta[m * rkp_std_NOPS + j] = (m % 2u) ? -165191050 : 165191050;
    }
    bad_theta[j] = INT32_MAX - 165191050 * (int32_t)(rkp_std_NRBF - 1u);
    c = rkp_std; c.theta_q24 = bad_theta;
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_OK); /* exactly INT32_MAX */
    bad_theta[rkp_std_NOPS + j] -= 1;                       /* m = 1 is negative */
    assert_int_equal(init_with(&c, rkp_std_NOPS), PIEZO_EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_gauss_lut_interpolation),
        cmocka_unit_test(test_golden_cases),
        cmocka_unit_test(test_split_run_and_end_state),
        cmocka_unit_test(test_reset_restores_initial_state),
        cmocka_unit_test(test_init_refuses_bad_coefficients),
    };
    return cmocka_run_group_tests_name("rkp", tests, NULL, NULL);
}
