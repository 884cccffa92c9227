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

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_proportional_and_integral_action),
        cmocka_unit_test(test_anti_windup_recovers_at_once),
        cmocka_unit_test(test_notch_rejects_its_frequency_and_passes_dc),
        cmocka_unit_test(test_limiter_clamps_and_slews),
        cmocka_unit_test(test_notch_output_rounding_matches_int64),
    };
    return cmocka_run_group_tests_name("pid", tests, NULL, NULL);
}
