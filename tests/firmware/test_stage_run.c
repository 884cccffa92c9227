/* Determinism and the equivalence of the stage's entry points: the code path
 * (stage_step, as the SIL firmware uses it), the float path (stage_run, as
 * the host uses it) and stage_simulate_file (ctypes) give the same samples. */
#include "piezo_test.h"
#include "stage_model.h"

#include <math.h>
#include <string.h>

#define N 20000

static double drive(int k, int axis)
{
    double t = k / 10000.0;
    return axis == 0 ? 75.0 + 70.0 * sin(2.0 * 3.14159265358979 * 7.0 * t) * cos(3.0 * t)
                     : 60.0 + 40.0 * sin(2.0 * 3.14159265358979 * 23.0 * t);
}

static void test_same_seed_same_samples(void **state)
{
    stage_params p = stage_params_two_axis();
    stage_t a, b, c;
    int k, differ = 0;
    (void)state;
    assert_int_equal(stage_init(&a, &p, 42), STAGE_OK);
    assert_int_equal(stage_init(&b, &p, 42), STAGE_OK);
    assert_int_equal(stage_init(&c, &p, 43), STAGE_OK);
    for (k = 0; k < N; k++) {
        int32_t dac[2], ya[2], yb[2], yc[2];
        dac[0] = stage_drive_to_dac_code(&a, 0, drive(k, 0));
        dac[1] = stage_drive_to_dac_code(&a, 1, drive(k, 1));
        stage_step(&a, dac, ya);
        stage_step(&b, dac, yb);
        stage_step(&c, dac, yc);
        assert_int_equal(ya[0], yb[0]);
        assert_int_equal(ya[1], yb[1]);
        differ += ya[0] != yc[0];
        /* the noise is the only random part */
        assert_true(stage_true_um(&a, 0) == stage_true_um(&c, 0));
    }
    /* 2 nm noise on a 0.37 nm LSB: another seed changes most samples */
    assert_true(differ > N / 2);
}

static void test_run_equals_step(void **state)
{
    stage_params p = stage_params_two_axis();
    stage_t a, b;
    static double u0[N], u1[N], y0[N], y1[N];
    int k;
    (void)state;
    for (k = 0; k < N; k++) {
        u0[k] = drive(k, 0);
        u1[k] = drive(k, 1);
    }
    assert_int_equal(stage_init(&a, &p, 9), STAGE_OK);
    assert_int_equal(stage_init(&b, &p, 9), STAGE_OK);
    assert_int_equal(stage_run(&a, N, u0, u1, y0, y1), STAGE_OK);
    for (k = 0; k < N; k++) {
        int32_t dac[2], adc[2];
        dac[0] = stage_drive_to_dac_code(&b, 0, u0[k]);
        dac[1] = stage_drive_to_dac_code(&b, 1, u1[k]);
        stage_step(&b, dac, adc);
        if (y0[k] != stage_adc_code_to_um(&b, 0, adc[0]) || y1[k] != stage_adc_code_to_um(&b, 1, adc[1])) {
            fail_msg("sample %d: stage_run %.17g %.17g, stage_step %.17g %.17g", k, y0[k], y1[k],
                     stage_adc_code_to_um(&b, 0, adc[0]), stage_adc_code_to_um(&b, 1, adc[1]));
        }
    }
}

static void test_simulate_file_equals_run(void **state)
{
    stage_params p = stage_params_default();
    stage_t a;
    static double u0[N], ya[N], yb[N];
    char err[256];
    int k;
    (void)state;
    for (k = 0; k < N; k++) {
        u0[k] = drive(k, 0);
    }
    assert_int_equal(stage_init(&a, &p, 3), STAGE_OK);
    assert_int_equal(stage_run(&a, N, u0, NULL, ya, NULL), STAGE_OK);
    assert_int_equal(stage_simulate_file(STAGE_DIR "/default.json", 3, 0.0, N, u0, NULL, yb, NULL, err, sizeof err),
                     STAGE_OK);
    assert_memory_equal(ya, yb, sizeof ya);
    /* errors come back as text */
    assert_int_equal(stage_simulate_file(STAGE_DIR "/nope.json", 3, 0.0, 1, u0, NULL, yb, NULL, err, sizeof err),
                     STAGE_ERR_FILE);
    assert_non_null(strstr(err, "nope.json"));
}

static void test_run_continues_and_reinit_resets(void **state)
{
    stage_params p = stage_params_default();
    stage_t a, b;
    static double u[N], y[N], y2[N];
    int k;
    (void)state;
    for (k = 0; k < N; k++) {
        u[k] = drive(k, 0);
    }
    assert_int_equal(stage_init(&a, &p, 11), STAGE_OK);
    assert_int_equal(stage_run(&a, N, u, NULL, y, NULL), STAGE_OK);
    /* in two halves: the state carries over */
    assert_int_equal(stage_init(&b, &p, 11), STAGE_OK);
    assert_int_equal(stage_run(&b, N / 2, u, NULL, y2, NULL), STAGE_OK);
    assert_int_equal(stage_run(&b, N - N / 2, u + N / 2, NULL, y2 + N / 2, NULL), STAGE_OK);
    assert_memory_equal(y, y2, sizeof y);
    /* init again: the same run again */
    assert_int_equal(stage_init(&b, &p, 11), STAGE_OK);
    assert_int_equal(stage_run(&b, N, u, NULL, y2, NULL), STAGE_OK);
    assert_memory_equal(y, y2, sizeof y);
}

static void test_gaussian_generator(void **state)
{
    stage_t s;
    stage_params p = stage_params_ideal();
    double sum = 0, sum2 = 0, sum4 = 0;
    int k, n = 400000;
    uint64_t st = 0;
    (void)state;
    /* splitmix64 reference values for seed 0 */
    assert_true(stage_rng_next(&st) == 0xE220A8397B1DCDAFull);
    assert_true(stage_rng_next(&st) == 0x6E789E6AA1B965F4ull);
    assert_int_equal(stage_init(&s, &p, 123), STAGE_OK);
    for (k = 0; k < n; k++) {
        double g = stage_rng_gauss(&s);
        sum += g;
        sum2 += g * g;
        sum4 += g * g * g * g;
    }
    assert_true(fabs(sum / n) < 4.0 / sqrt((double)n));
    assert_true(fabs(sum2 / n - 1.0) < 4.0 * sqrt(2.0 / n));
    assert_true(fabs(sum4 / n - 3.0) < 4.0 * sqrt(96.0 / n)); /* kurtosis of a Gaussian */
}

static void test_bad_arguments(void **state)
{
    stage_params p = stage_params_default();
    stage_t s;
    (void)state;
    assert_int_equal(stage_init(NULL, &p, 1), STAGE_ERR_ARG);
    assert_int_equal(stage_init(&s, NULL, 1), STAGE_ERR_ARG);
    p.num_axes = 3;
    assert_int_equal(stage_init(&s, &p, 1), STAGE_ERR_PARAM);
    p = stage_params_default();
    assert_int_equal(stage_init(&s, &p, 1), STAGE_OK);
    assert_int_equal(stage_run(&s, 1, NULL, NULL, NULL, NULL), STAGE_ERR_ARG);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_same_seed_same_samples),
        cmocka_unit_test(test_run_equals_step),
        cmocka_unit_test(test_simulate_file_equals_run),
        cmocka_unit_test(test_run_continues_and_reinit_resets),
        cmocka_unit_test(test_gaussian_generator),
        cmocka_unit_test(test_bad_arguments),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
