/* PI/PID with anti-windup, notch biquad, clamp and slew limiter. */
#include <math.h>

#include "piezo_test.h"
#include "fixed_q.h"
#include "piezo_err.h"
#include "pid.h"

static int32_t q24(double x) { return (int32_t)floor(x * 16777216.0 + 0.5); }

static void test_proportional_and_integral_action(void **state)
{
    (void)state;
    piezo_pid_coef_t c = {.kp_q24 = q24(0.5), .ki_q24 = q24(0.01), .kd_q24 = 0,
                          .out_min_q15 = -32768, .out_max_q15 = 32767};
    piezo_pid_t p;
    assert_int_equal(piezo_pid_init(&p, &c), PIEZO_OK);
    /* constant error 1000: u[k] = 500 + 10 (k + 1) */
    for (int k = 0; k < 50; k++) {
        assert_int_equal(piezo_pid_process(&p, 1000), 500 + 10 * (k + 1));
    }
}

static void test_anti_windup_recovers_at_once(void **state)
{
    (void)state;
    piezo_pid_coef_t c = {.kp_q24 = q24(0.1), .ki_q24 = q24(0.05), .kd_q24 = 0,
                          .out_min_q15 = -10000, .out_max_q15 = 10000};
    piezo_pid_t p;
    assert_int_equal(piezo_pid_init(&p, &c), PIEZO_OK);
    for (int k = 0; k < 100000; k++) {
        assert_signed_in_range(piezo_pid_process(&p, 20000), -10000, 10000);
    }
    assert_int_equal(p.out_q15, 10000);
    /* the integrator never holds more than full output ... */
    assert_true(p.integ_q39 <= (int64_t)10000 * 16777216);
    /* ... so a reversed error leaves saturation within a few ticks */
    int k = 0;
    while (piezo_pid_process(&p, -20000) >= 10000 && k < 1000) {
        k++;
    }
    assert_true(k <= 2);
}

static void test_notch_rejects_its_frequency_and_passes_dc(void **state)
{
    (void)state;
    /* notch at 140 Hz, Q = 5, fs = 10 kHz (RBJ cookbook form, a0 normalized) */
    double w0 = 2.0 * 3.141592653589793 * 140.0 / 10000.0, alpha = sin(w0) / (2.0 * 5.0);
    double a0 = 1.0 + alpha;
    piezo_biquad_coef_t c = {q24(1.0 / a0), q24(-2.0 * cos(w0) / a0), q24(1.0 / a0),
                             q24(-2.0 * cos(w0) / a0), q24((1.0 - alpha) / a0)};
    piezo_biquad_t f;
    assert_int_equal(piezo_biquad_init(&f, &c), PIEZO_OK);
    double peak = 0.0;
    for (int k = 0; k < 20000; k++) {
        int16_t x = (int16_t)lround(20000.0 * sin(w0 * k));
        int16_t y = piezo_biquad_process(&f, x);
        if (k > 15000 && fabs((double)y) > peak) {
            peak = fabs((double)y);
        }
    }
    print_message("notch: residual %.0f LSB of 20000 at 140 Hz\n", peak);
    assert_true(peak < 200.0); /* > 40 dB */
    piezo_biquad_reset(&f);
    int16_t y = 0;
    for (int k = 0; k < 5000; k++) {
        y = piezo_biquad_process(&f, 10000);
    }
    assert_signed_in_range(y, 9995, 10005);
}

/* The notch's output rounding, done in int32 (pid.c), against the int64
 * formula sat_q15(rshift_rnd(y31, 16)) over the whole q31 range: with
 * a1 = -1 and every other coefficient 0 the filter's y31 is its y1. */
static void test_notch_output_rounding_matches_int64(void **state)
{
    (void)state;
    const piezo_biquad_coef_t k = {.a1_q24 = -(int32_t)PIEZO_Q24_ONE};
    static const int32_t edges[] = {INT32_MIN, INT32_MIN + 1, -65537, -65536, -32769, -32768, -32767, -1, 0, 1,
                                    32767, 32768, 32769, 65535, 65536, 2147450879, 2147450880, 2147483647};
    piezo_biquad_t f;
    assert_int_equal(piezo_biquad_init(&f, &k), PIEZO_OK);
    for (int32_t i = 0; i < 20000; i++) {
        /* the edges, then a spread over the whole range with every low-bit pattern */
        int32_t y = i < (int32_t)(sizeof edges / sizeof edges[0]) ? edges[i] : (int32_t)((uint32_t)i * 214735u + (uint32_t)i);
        piezo_biquad_reset(&f);
        f.y1_q31 = y;
        assert_int_equal(piezo_biquad_process(&f, 0), piezo_sat_q15(piezo_rshift_rnd64(y, 16u)));
        assert_int_equal(f.y1_q31, y); /* y31 = y1 exactly: the case tests the output step alone */
    }
}

static void test_limiter_clamps_and_slews(void **state)
{
    (void)state;
    piezo_limit_coef_t c = {.min_q15 = -20000, .max_q15 = 20000, .max_step_q15 = 100};
    piezo_limit_t l;
    assert_int_equal(piezo_limit_init(&l, &c, 0), PIEZO_OK);
    for (int k = 1; k <= 200; k++) {
        assert_int_equal(piezo_limit_process(&l, 32767), k * 100 > 20000 ? 20000 : k * 100);
    }
    assert_true(l.flags & PIEZO_LIMIT_CLAMPED);
    assert_int_equal(piezo_limit_process(&l, 19950), 19950);
    assert_int_equal(l.flags, 0);
    c.max_step_q15 = -1;
    assert_int_equal(piezo_limit_init(&l, &c, 0), PIEZO_EINVAL);
}

/* The PID as the int64 formula of pid.h, written out (64-bit clamp of the
 * integrator and of the output): the reference for the int32 forms in pid.c. */
typedef struct {
    int64_t integ;
    int16_t e_prev, out;
    uint8_t saturated;
} ref_pid_t;

static int16_t ref_pid(ref_pid_t *p, const piezo_pid_coef_t *c, int16_t e)
{
    const int64_t lo = (int64_t)c->out_min_q15 * 16777216, hi = (int64_t)c->out_max_q15 * 16777216;
    int64_t v;
    if (!(p->saturated && ((p->out >= c->out_max_q15 && e > 0) || (p->out <= c->out_min_q15 && e < 0)))) {
        p->integ += (int64_t)c->ki_q24 * e;
        p->integ = p->integ > hi ? hi : (p->integ < lo ? lo : p->integ);
    }
    v = piezo_rshift_rnd64((int64_t)c->kp_q24 * e + p->integ + (int64_t)c->kd_q24 * ((int32_t)e - p->e_prev), 24u);
    p->saturated = (uint8_t)(v > c->out_max_q15 || v < c->out_min_q15);
    p->out = (int16_t)(v > c->out_max_q15 ? c->out_max_q15 : (v < c->out_min_q15 ? c->out_min_q15 : v));
    p->e_prev = e;
    return p->out;
}

/* One step of the tests' input walk from the random word m: a jump anywhere
 * (1 in 16), an extreme (1 in 16), else a small step, so that runs of one
 * sign drive the state into saturation and out. */
static int16_t walk_step(int16_t v, uint32_t m)
{
    if ((m & 15u) == 0u) {
        return (int16_t)(m >> 16);
    }
    if ((m & 15u) == 1u) {
        return (m & 16u) ? INT16_MAX : INT16_MIN;
    }
    return (int16_t)(v + (int16_t)((int32_t)(m >> 16) >> 6));
}

static void test_pid_matches_int64_formula(void **state)
{
    uint32_t seed = 7u;
    (void)state;
    /* the integrator's clamp at a fraction of an LSB above the limit: steps of
     * ki e = 0.6 LSB (q15) into narrow limits, both ways */
    {
        const piezo_pid_coef_t c = {.kp_q24 = q24(0.1), .ki_q24 = 3 << 20, .kd_q24 = 0,
                                    .out_min_q15 = -100, .out_max_q15 = 100};
        piezo_pid_t p;
        ref_pid_t r = {0, 0, 0, 0u};
        assert_int_equal(piezo_pid_init(&p, &c), PIEZO_OK);
        for (int k = 0; k < 2000; k++) {
            const int16_t e = (int16_t)((k / 500) % 2 ? -3 : 3);
            assert_int_equal(piezo_pid_process(&p, e), ref_pid(&r, &c, e));
            assert_true(p.integ_q39 == r.integ);
        }
    }
    for (int trial = 0; trial < 400; trial++) {
        /* gains over the whole q24 range (any sign, up to +-128), limits
         * anywhere (min <= max, sometimes equal, sometimes excluding 0) */
        piezo_pid_coef_t c;
        int16_t a = (int16_t)(piezo_test_lcg(&seed) >> 16), b = (int16_t)(piezo_test_lcg(&seed) >> 16);
        c.kp_q24 = (int32_t)piezo_test_lcg(&seed) >> (piezo_test_lcg(&seed) >> 27);
        c.ki_q24 = (int32_t)piezo_test_lcg(&seed) >> (piezo_test_lcg(&seed) >> 27); /* down to +-1 LSB */
        c.kd_q24 = (trial % 3 == 0) ? 0 : (int32_t)piezo_test_lcg(&seed) >> (piezo_test_lcg(&seed) >> 27);
        if (trial % 2 == 0) {
            a = (int16_t)(a >> 8); /* narrow limits: the clamps bind often */
            b = (int16_t)(b >> 8);
        }
        c.out_min_q15 = a < b ? a : b;
        c.out_max_q15 = (trial % 17 == 0) ? c.out_min_q15 : (a < b ? b : a);
        piezo_pid_t p;
        ref_pid_t r = {0, 0, 0, 0u};
        assert_int_equal(piezo_pid_init(&p, &c), PIEZO_OK);
        int16_t e = 0;
        for (int k = 0; k < 400; k++) {
            /* runs of one sign (into saturation and out), jumps, extremes */
            e = walk_step(e, piezo_test_lcg(&seed));
            const int16_t want = ref_pid(&r, &c, e);
            assert_int_equal(piezo_pid_process(&p, e), want);
            assert_true(p.integ_q39 == r.integ);
            assert_int_equal(p.saturated, r.saturated);
        }
    }
}

/* The notch's recurrence against the int64 formula it was first written as
 * (b0 x + b1 x1 + b2 x2) 2^16 - a1 y1 - a2 y2, rounded by 24 bits and
 * saturated to int32, the output rshift_rnd(y31, 16) saturated to q15: the
 * kernel forms -a1 y1 and -a2 y2 as products of the negated coefficients
 * (issue 15, round 14). Coefficients anywhere in init's range (-4, 4) in q24,
 * the extremes included, inputs with runs, jumps and extremes, states
 * preloaded anywhere in q31. */
static void test_notch_matches_int64_formula(void **state)
{
    uint32_t seed = 11u;
    const int32_t lim = 4 * (int32_t)PIEZO_Q24_ONE - 1;
    (void)state;
    for (int trial = 0; trial < 400; trial++) {
        piezo_biquad_coef_t c;
        int32_t *k[5] = {&c.b0_q24, &c.b1_q24, &c.b2_q24, &c.a1_q24, &c.a2_q24};
        for (int i = 0; i < 5; i++) {
            const uint32_t m = piezo_test_lcg(&seed);
            /* the edges now and then, else anywhere in (-lim, lim) at any scale */
            *k[i] = (m & 7u) == 0u ? ((m & 8u) ? lim : -lim) : (int32_t)(piezo_test_lcg(&seed) >> 5) - (1 << 26);
            *k[i] >>= (m >> 28) & 7u;
        }
        piezo_biquad_t f;
        assert_int_equal(piezo_biquad_init(&f, &c), PIEZO_OK);
        f.x1_q15 = (int16_t)(piezo_test_lcg(&seed) >> 16);
        f.x2_q15 = (int16_t)(piezo_test_lcg(&seed) >> 16);
        f.y1_q31 = (int32_t)piezo_test_lcg(&seed);
        f.y2_q31 = (int32_t)piezo_test_lcg(&seed);
        int16_t x = 0;
        for (int n = 0; n < 200; n++) {
            x = walk_step(x, piezo_test_lcg(&seed));
            const int64_t acc = ((int64_t)c.b0_q24 * x + (int64_t)c.b1_q24 * f.x1_q15 + (int64_t)c.b2_q24 * f.x2_q15) *
                                    PIEZO_Q16_ONE -
                                (int64_t)c.a1_q24 * f.y1_q31 - (int64_t)c.a2_q24 * f.y2_q31;
            const int32_t y31 = piezo_sat_i32(piezo_rshift_rnd64(acc, 24u));
            const int32_t y1 = f.y1_q31;
            const int16_t x1 = f.x1_q15;
            assert_int_equal(piezo_biquad_process(&f, x), piezo_sat_q15(piezo_rshift_rnd64(y31, 16u)));
            assert_int_equal(f.y1_q31, y31);
            assert_int_equal(f.y2_q31, y1);
            assert_int_equal(f.x1_q15, x);
            assert_int_equal(f.x2_q15, x1);
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_proportional_and_integral_action),
        cmocka_unit_test(test_anti_windup_recovers_at_once),
        cmocka_unit_test(test_notch_rejects_its_frequency_and_passes_dc),
        cmocka_unit_test(test_limiter_clamps_and_slews),
        cmocka_unit_test(test_notch_output_rounding_matches_int64),
        cmocka_unit_test(test_notch_matches_int64_formula),
        cmocka_unit_test(test_pid_matches_int64_formula),
    };
    return cmocka_run_group_tests_name("pid", tests, NULL, NULL);
}
