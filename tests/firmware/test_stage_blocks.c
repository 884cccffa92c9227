/* Each block of the stage model against its analytic response. The other
 * blocks are ideal (stage_params_ideal()), so the chain is the block alone:
 * DAC volts in, unit amplifier, 1 um/V actuator, true displacement out. */
#include "piezo_test.h"
#include "stage_model.h"

#include <math.h>

#define FS 10000.0
#define T (1.0 / FS)
#define PI 3.14159265358979323846

static void fail_if_far(const char *what, int k, double got, double want, double tol)
{
    if (!(fabs(got - want) <= tol)) {
        fail_msg("%s: sample %d: got %.17g, want %.17g (|diff| %.3g > %.3g)", what, k, got, want,
                 fabs(got - want), tol);
    }
}

static void init_ok(stage_t *s, const stage_params *p)
{
    char err[256] = "";
    if (stage_params_check(p, err, sizeof err) != STAGE_OK) {
        fail_msg("parameters refused: %s", err);
    }
    assert_int_equal(stage_init(s, p, 1), STAGE_OK);
}

/* One float step on axis 0 (axis 1 held at 0 V). */
static double step1(stage_t *s, double v)
{
    double vin[2] = {v, 0.0}, y[2];
    stage_step_f(s, vin, y);
    return y[0];
}

/* Closed-form unit step response of w^2 / (s^2 + 2 z w s + w^2). */
static double mode_step(double f, double z, double t)
{
    double w = 2.0 * PI * f;
    if (z < 1.0) {
        double wd = w * sqrt(1.0 - z * z);
        return 1.0 - exp(-z * w * t) * (cos(wd * t) + z * w / wd * sin(wd * t));
    }
    if (z > 1.0) { /* two real poles r1, r2 */
        double q = w * sqrt(z * z - 1.0), r1 = -z * w + q, r2 = -z * w - q;
        return 1.0 + (r2 * exp(r1 * t) - r1 * exp(r2 * t)) / (r1 - r2);
    }
    return 1.0 - exp(-w * t) * (1.0 + w * t);
}

static void check_mode_step(double f, double z)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    int k;
    p.axis[0].mechanics.enabled = true;
    p.axis[0].mechanics.n_modes = 1;
    p.axis[0].mechanics.mode[0].freq_hz = f;
    p.axis[0].mechanics.mode[0].damping = z;
    p.axis[0].mechanics.mode[0].gain = 1.0;
    init_ok(&s, &p);
    for (k = 0; k < 3000; k++) {
        /* the value at the end of sample k: t = (k + 1) T */
        fail_if_far("mode step", k, step1(&s, 2.5), 2.5 * mode_step(f, z, (k + 1) * T), 1e-11);
    }
}

static void test_mode_step_underdamped(void **state)
{
    (void)state;
    check_mode_step(970.0, 0.03);
    check_mode_step(140.0, 0.04);
    check_mode_step(12.0, 0.0); /* undamped */
}

static void test_mode_step_critical_and_overdamped(void **state)
{
    (void)state;
    check_mode_step(300.0, 1.0);
    check_mode_step(300.0, 2.5);
}

static void test_two_modes_superpose(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    int k;
    double peak = 0.0;
    (void)state;
    p.axis[0].mechanics.enabled = true;
    p.axis[0].mechanics.n_modes = 2;
    p.axis[0].mechanics.mode[0] = (stage_mode){140.0, 0.04, 0.98};
    p.axis[0].mechanics.mode[1] = (stage_mode){620.0, 0.03, 0.02};
    init_ok(&s, &p);
    for (k = 0; k < 4000; k++) {
        double t = (k + 1) * T;
        double want = 0.98 * mode_step(140.0, 0.04, t) + 0.02 * mode_step(620.0, 0.03, t);
        double y = step1(&s, 1.0);
        fail_if_far("two modes", k, y, want, 1e-11);
        peak = fmax(peak, y);
    }
    /* the 140 Hz mode overshoots by exp(-pi z / sqrt(1 - z^2)) = 88 % */
    assert_true(peak > 1.8 && peak < 1.9);
}

static void test_amplifier_first_order_step(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    double a = exp(-2.0 * PI * 2000.0 * T);
    int k;
    (void)state;
    p.axis[0].amp.gain = 15.0;
    p.axis[0].amp.offset_v = 3.0;
    p.axis[0].amp.bandwidth.enabled = true;
    p.axis[0].amp.bandwidth.hz = 2000.0;
    init_ok(&s, &p);
    /* at rest the output is 0 V; the target is 15 * 2 + 3 = 33 V */
    for (k = 0; k < 200; k++) {
        double y = step1(&s, 2.0);
        fail_if_far("amplifier step", k, stage_hv_volts(&s, 0), 33.0 * (1.0 - pow(a, k + 1)), 1e-12);
        fail_if_far("amplifier -> displacement", k, y, stage_hv_volts(&s, 0), 0.0);
    }
}

static void test_slew_rate_ramp(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    const double rate = 0.1 / 1.5e-6; /* V/s */
    int k;
    (void)state;
    p.axis[0].amp.gain = 15.0;
    p.axis[0].amp.slew.enabled = true;
    p.axis[0].amp.slew.current_limit_a = 0.1;
    p.axis[0].amp.slew.load_capacitance_f = 1.5e-6;
    init_ok(&s, &p);
    for (k = 0; k < 40; k++) { /* 0 -> 150 V ramps at I/C, 22.5 samples */
        step1(&s, 10.0);
        fail_if_far("rising ramp", k, stage_hv_volts(&s, 0), fmin(rate * (k + 1) * T, 150.0), 1e-9);
    }
    for (k = 0; k < 40; k++) {
        step1(&s, 2.0);
        fail_if_far("falling ramp", k, stage_hv_volts(&s, 0), fmax(150.0 - rate * (k + 1) * T, 30.0), 1e-9);
    }
}

static void test_slew_with_bandwidth(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    const double step = 0.1 / 1.5e-6 * T;
    double prev = 0.0;
    int k, limited = 0;
    (void)state;
    p.axis[0].amp.gain = 15.0;
    p.axis[0].amp.bandwidth.enabled = true;
    p.axis[0].amp.bandwidth.hz = 2000.0;
    p.axis[0].amp.slew.enabled = true;
    p.axis[0].amp.slew.current_limit_a = 0.1;
    p.axis[0].amp.slew.load_capacitance_f = 1.5e-6;
    init_ok(&s, &p);
    for (k = 0; k < 200; k++) {
        double v, d;
        step1(&s, 10.0);
        v = stage_hv_volts(&s, 0);
        d = v - prev;
        prev = v;
        assert_true(d <= step * (1.0 + 1e-12));
        if (fabs(d - step) < 1e-9) {
            limited++;
        }
    }
    /* large signal: slew-limited first, then the first-order tail reaches 150 V */
    assert_true(limited >= 10);
    fail_if_far("settled", 199, prev, 150.0, 1e-6);
}

static void test_saturation(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    (void)state;
    p.axis[0].amp.gain = 20.0;
    p.axis[0].amp.saturation.enabled = true;
    p.axis[0].amp.saturation.v_min = -20.0;
    p.axis[0].amp.saturation.v_max = 150.0;
    init_ok(&s, &p);
    fail_if_far("inside", 0, step1(&s, 5.0), 100.0, 0.0);
    fail_if_far("above", 1, step1(&s, 10.0), 150.0, 0.0);
    fail_if_far("below", 2, step1(&s, -5.0), -20.0, 0.0);
    fail_if_far("hv below", 2, stage_hv_volts(&s, 0), -20.0, 0.0);
}

static void test_transport_delay_exact(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    int k;
    (void)state;
    p.axis[0].delay.enabled = true;
    p.axis[0].delay.samples = 7;
    init_ok(&s, &p);
    for (k = 0; k < 100; k++) {
        double u = 1.0 + 0.01 * k * k;
        double y = step1(&s, u);
        double want = k < 7 ? 0.0 : 1.0 + 0.01 * (k - 7) * (k - 7);
        fail_if_far("delay 7", k, y, want, 0.0);
    }
    p.axis[0].delay.samples = 0;
    init_ok(&s, &p);
    fail_if_far("delay 0", 0, step1(&s, 4.25), 4.25, 0.0);
}

static void test_dac_quantization(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    int32_t dac[2] = {0, 0}, adc[2];
    double v;
    (void)state;
    p.axis[0].dac.enabled = true;
    p.axis[0].dac.bits = 8;
    p.axis[0].dac.v_min = 0.0;
    p.axis[0].dac.v_max = 10.0;
    p.axis[0].adc.bits = 24;
    p.axis[0].adc.y_max_um = 16.0;
    init_ok(&s, &p);
    /* 1.23 V = 31.488 LSB -> code 31 -> 31 * 10/256 V */
    fail_if_far("round down", 0, step1(&s, 1.23), 31.0 * 10.0 / 256.0, 0.0);
    fail_if_far("round half up", 1, step1(&s, 32.5 * 10.0 / 256.0), 33.0 * 10.0 / 256.0, 0.0);
    fail_if_far("clamp low", 2, step1(&s, -1.0), 0.0, 0.0);
    fail_if_far("clamp high", 3, step1(&s, 20.0), 255.0 * 10.0 / 256.0, 0.0);
    /* the code path: code 300 is clamped to 255 */
    dac[0] = 300;
    stage_step(&s, dac, adc);
    fail_if_far("code clamp", 4, stage_true_um(&s, 0), 255.0 * 10.0 / 256.0, 0.0);
    dac[0] = 100;
    stage_step(&s, dac, adc);
    fail_if_far("code 100", 5, stage_true_um(&s, 0), 100.0 * 10.0 / 256.0, 0.0);
    /* an error of at most half an LSB over a sweep */
    for (v = 0.0; v < 9.9; v += 0.0137) {
        double y = step1(&s, v);
        assert_true(fabs(y - v) <= 0.5 * 10.0 / 256.0 + 1e-12);
    }
}

static void test_adc_quantization(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    int32_t dac[2], adc[2] = {0, 0};
    const double lsb = 10.0 / 1024.0;
    double v;
    (void)state;
    p.axis[0].adc.enabled = true;
    p.axis[0].adc.bits = 10;
    p.axis[0].adc.y_min_um = 0.0;
    p.axis[0].adc.y_max_um = 10.0;
    init_ok(&s, &p);
    /* 3.3 um = 337.92 LSB -> code 338 */
    fail_if_far("float path", 0, step1(&s, 3.3), 338.0 * lsb, 0.0);
    assert_int_equal(stage_um_to_adc_code(&s, 0, 3.3), 338);
    assert_int_equal(stage_um_to_adc_code(&s, 0, -0.5), 0);
    assert_int_equal(stage_um_to_adc_code(&s, 0, 12.0), 1023);
    assert_int_equal(stage_um_to_adc_code(&s, 0, NAN), 0);
    fail_if_far("decode", 0, stage_adc_code_to_um(&s, 0, 338), 338.0 * lsb, 0.0);
    /* the code path: DAC code 21626 of 16 bits over 0..10 V -> 3.2998657 um */
    dac[0] = 21626;
    dac[1] = 0;
    stage_step(&s, dac, adc);
    assert_int_equal(adc[0], (int32_t)floor(21626.0 * 10.0 / 65536.0 / lsb + 0.5));
    for (v = 0.0; v < 9.99; v += 0.0071) {
        assert_true(fabs(step1(&s, v) - v) <= 0.5 * lsb + 1e-12);
    }
}

static void test_creep_step_time_constants(void **state)
{
    stage_params p = stage_params_default();
    stage_params q = stage_params_ideal();
    stage_t s;
    int k, j;
    (void)state;
    q.axis[0].creep = p.axis[0].creep; /* the default stage's terms: 0.05 s .. 100 s */
    init_ok(&s, &q);
    for (k = 0; k < 300000; k++) { /* 30 s */
        double t = (k + 1) * T, want = 1.0;
        double y = step1(&s, 1.0);
        for (j = 0; j < q.axis[0].creep.n_terms; j++) {
            want += q.axis[0].creep.term[j].gain * (1.0 - exp(-t / q.axis[0].creep.term[j].tau_s));
        }
        fail_if_far("creep step", k, y, want, 1e-12);
        if (k == 0) {
            assert_true(y > 1.0 && y < 1.0 + 1e-3);
        }
    }
    /* 30 s after the step four terms have mostly settled, the 100 s one not */
    {
        double y = stage_true_um(&s, 0);
        assert_true(y > 1.0 + 0.008 * (3.0 + 0.86) && y < 1.0 + 0.008 * 4.3);
    }
}

static void test_thermal_drift(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    int k;
    (void)state;
    p.axis[0].thermal.enabled = true;
    p.axis[0].thermal.drift_um_per_k = 0.05;
    p.axis[0].thermal.delta_k = 0.5;
    p.axis[0].thermal.time_constant_s = 2.0;
    init_ok(&s, &p);
    for (k = 0; k < 50000; k++) {
        fail_if_far("thermal", k, step1(&s, 0.0), 0.025 * (1.0 - exp(-(k + 1) * T / 2.0)), 1e-13);
    }
}

static void test_sensor_errors(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    (void)state;
    p.axis[0].sensor.enabled = true;
    p.axis[0].sensor.offset_um = 0.02;
    p.axis[0].sensor.gain_error = 0.002;
    p.axis[0].sensor.nonlinearity = 0.0005;
    p.axis[0].sensor.range_min_um = 0.0;
    p.axis[0].sensor.range_max_um = 20.0;
    init_ok(&s, &p);
    /* ends of the range: offset and gain only; centre: plus 0.05 % of 20 um */
    fail_if_far("x = 0", 0, step1(&s, 0.0), 0.02, 1e-15);
    fail_if_far("x = 20", 1, step1(&s, 20.0), 0.02 + 1.002 * 20.0, 1e-13);
    fail_if_far("x = 10", 2, step1(&s, 10.0), 0.02 + 1.002 * 10.0 + 0.0005 * 20.0, 1e-13);
    fail_if_far("x = 5", 3, step1(&s, 5.0), 0.02 + 1.002 * 5.0 + 0.0005 * 20.0 * 0.75, 1e-13);
    fail_if_far("true", 3, stage_true_um(&s, 0), 5.0, 0.0);
}

static void test_noise_statistics(void **state)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    const int n = 200000;
    double sum = 0.0, sum2 = 0.0, mean, sd;
    int k;
    (void)state;
    p.axis[0].noise.enabled = true;
    p.axis[0].noise.rms_um = 0.002;
    init_ok(&s, &p);
    for (k = 0; k < n; k++) {
        double y = step1(&s, 5.0) - 5.0;
        sum += y;
        sum2 += y * y;
        assert_true(stage_true_um(&s, 0) == 5.0);
    }
    mean = sum / n;
    sd = sqrt(sum2 / n - mean * mean);
    /* standard errors: mean 4.5e-6 um, sd 0.16 % */
    assert_true(fabs(mean) < 4.0 * 0.002 / sqrt((double)n));
    assert_true(fabs(sd / 0.002 - 1.0) < 0.01);
}

/* Loop width of axis 0 for a sine of the drive [V] from lo to hi at freq:
 * max |descending - ascending| at equal drive over the last of `periods`
 * periods, relative to the peak-to-peak of the true displacement. */
static double loop_width(const stage_params *p, double freq, double lo, double hi, int periods)
{
    stage_t s;
    int n = (int)(FS / freq + 0.5), k, total = n * periods;
    static double y[100000];
    double ymin = 1e300, ymax = -1e300, wmax = 0.0;
    assert_true(n <= 100000 && n % 2 == 0);
    assert_int_equal(stage_init(&s, p, 7), STAGE_OK);
    for (k = 0; k < total; k++) {
        double u = lo + (hi - lo) * 0.5 * (1.0 - cos(2.0 * PI * k / n));
        double in[2] = {u, 0.0}, out[2];
        int32_t dac[2] = {0, 0}, adc[2];
        if (p->axis[0].dac.enabled) { /* through the codes, as the firmware would */
            dac[0] = stage_drive_to_dac_code(&s, 0, u);
            stage_step(&s, dac, adc);
        } else {
            in[0] = (u - p->axis[0].amp.offset_v) / p->axis[0].amp.gain;
            stage_step_f(&s, in, out);
        }
        if (k >= total - n) {
            y[k - (total - n)] = stage_true_um(&s, 0);
        }
    }
    for (k = 0; k < n; k++) {
        ymin = fmin(ymin, y[k]);
        ymax = fmax(ymax, y[k]);
    }
    for (k = 1; k < n / 2; k++) { /* drive at k equals drive at n - k */
        wmax = fmax(wmax, fabs(y[n - k] - y[k]));
    }
    return wmax / (ymax - ymin);
}

static void test_default_loop_width_in_band(void **state)
{
    stage_params p = stage_params_default();
    stage_params q = stage_params_two_axis();
    double w1, w2;
    (void)state;
    w1 = loop_width(&p, 1.0, 0.0, 150.0, 3);
    w2 = loop_width(&q, 1.0, 0.0, 150.0, 3);
    print_message("loop width at 1 Hz, 0..150 V: default %.2f %%, two_axis %.2f %%\n", 100 * w1, 100 * w2);
    assert_true(w1 >= 0.10 && w1 <= 0.15);
    assert_true(w2 >= 0.10 && w2 <= 0.15);
}

static stage_params hysteresis_only(bool rate)
{
    stage_params p = stage_params_ideal();
    p.axis[0].hysteresis = stage_params_default().axis[0].hysteresis;
    p.axis[0].hysteresis.rate.enabled = rate;
    return p;
}

static void test_hysteresis_rate_dependence(void **state)
{
    stage_params p = hysteresis_only(true);
    double w1 = loop_width(&p, 1.0, 0.0, 150.0, 2);
    double w100 = loop_width(&p, 100.0, 0.0, 150.0, 2);
    (void)state;
    print_message("rate-dependent loop width: 1 Hz %.2f %%, 100 Hz %.2f %%\n", 100 * w1, 100 * w100);
    assert_true(w100 > 1.15 * w1);
    /* without rate dependence the loop hardly changes (the sampled path differs) */
    p = hysteresis_only(false);
    w1 = loop_width(&p, 1.0, 0.0, 150.0, 2);
    w100 = loop_width(&p, 100.0, 0.0, 150.0, 2);
    assert_true(fabs(w100 / w1 - 1.0) < 0.01);
}

/* Bouc-Wen integrated exactly along the straight path between samples is
 * rate independent: holding each sample ten times gives the same outputs. */
static void test_hysteresis_rate_independent_exactly(void **state)
{
    stage_params p = hysteresis_only(false);
    stage_t fast, slow;
    int k, r;
    (void)state;
    init_ok(&fast, &p);
    init_ok(&slow, &p);
    for (k = 0; k < 3000; k++) {
        double u = 75.0 - 75.0 * cos(2.0 * PI * k / 300.0) * (1.0 - k / 4000.0);
        double yf = step1(&fast, u), ys = 0.0;
        for (r = 0; r < 10; r++) {
            ys = step1(&slow, u);
        }
        fail_if_far("held ten times", k, ys, yf, 0.0);
    }
}

/* The Bouc-Wen loop: from rest, the ascending branch lies below the
 * descending one, the reversal is continuous, and a2 makes it asymmetric. */
static void test_hysteresis_branches(void **state)
{
    stage_params p = hysteresis_only(false);
    stage_t s;
    double up, down;
    int k;
    (void)state;
    init_ok(&s, &p);
    for (k = 0; k <= 150; k++) {
        up = step1(&s, 1.0 * k);
        if (k == 75) {
            fail_if_far("ascending below the line", k, up < 75.0 ? 1.0 : 0.0, 1.0, 0.0);
        }
    }
    for (k = 149; k >= 75; k--) {
        down = step1(&s, 1.0 * k);
    }
    assert_true(down > up - 150.0); /* sanity */
    {
        stage_t s2;
        double a;
        init_ok(&s2, &p);
        for (k = 0; k <= 75; k++) {
            a = step1(&s2, 1.0 * k);
        }
        /* at 75 V the descending branch is above the ascending one */
        assert_true(down - a > 0.05 * 150.0 * (1.0 + 0.15));
    }
}

/* Two-axis coupling: the fraction of axis 0's displacement seen on axis 1
 * grows with frequency as (static + dynamic (f / f_ref)^2) percent. */
static double coupling_percent(double f, double pos1_um)
{
    stage_params p = stage_params_ideal();
    stage_t s;
    const int settle = 10000, n = 10000;
    double c0 = 0, s0 = 0, c1 = 0, s1 = 0;
    int k, i;
    p.num_axes = 2;
    for (i = 0; i < 2; i++) {
        p.axis[i].actuator_gain_um_per_v = 0.11;
        p.axis[i].mechanics = stage_params_two_axis().axis[i].mechanics;
    }
    p.coupling = stage_params_two_axis().coupling;
    assert_int_equal(stage_init(&s, &p, 1), STAGE_OK);
    for (k = 0; k < settle + n; k++) {
        double ph = 2.0 * PI * f * k * T;
        double v[2] = {81.8 + 50.0 * sin(ph), pos1_um / 0.11}, y[2];
        stage_step_f(&s, v, y);
        if (k >= settle) { /* Fourier coefficients over 1 s: whole periods */
            double x0 = stage_true_um(&s, 0), x1 = stage_true_um(&s, 1);
            c0 += x0 * cos(ph);
            s0 += x0 * sin(ph);
            c1 += x1 * cos(ph);
            s1 += x1 * sin(ph);
        }
    }
    return 100.0 * sqrt(c1 * c1 + s1 * s1) / sqrt(c0 * c0 + s0 * s0);
}

static void test_coupling_grows_with_frequency(void **state)
{
    static const double f[4] = {1.0, 10.0, 35.0, 100.0};
    static const double paper[4] = {0.30, 0.33, 0.99, 6.34};
    double prev = 0.0;
    int i;
    (void)state;
    for (i = 0; i < 4; i++) {
        double c = coupling_percent(f[i], 9.0); /* axis 1 at the centre: factor 1 */
        double model = 0.30 + 6.04 * (f[i] / 100.0) * (f[i] / 100.0);
        print_message("coupling at %5.1f Hz: %.3f %% (model %.3f %%, paper %.2f %%)\n", f[i], c, model,
                      paper[i]);
        assert_true(c > prev);
        prev = c;
        assert_true(fabs(c / model - 1.0) < 0.01);
        assert_true(fabs(c / paper[i] - 1.0) < 0.15);
    }
}

static void test_coupling_depends_on_position(void **state)
{
    double lo = coupling_percent(10.0, 3.0), mid = coupling_percent(10.0, 9.0),
           hi = coupling_percent(10.0, 15.0);
    (void)state;
    /* factor 1 + 0.02 / um * (x1 - 9 um) */
    assert_true(fabs(lo / mid - 0.88) < 0.01);
    assert_true(fabs(hi / mid - 1.12) < 0.01);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mode_step_underdamped),
        cmocka_unit_test(test_mode_step_critical_and_overdamped),
        cmocka_unit_test(test_two_modes_superpose),
        cmocka_unit_test(test_amplifier_first_order_step),
        cmocka_unit_test(test_slew_rate_ramp),
        cmocka_unit_test(test_slew_with_bandwidth),
        cmocka_unit_test(test_saturation),
        cmocka_unit_test(test_transport_delay_exact),
        cmocka_unit_test(test_dac_quantization),
        cmocka_unit_test(test_adc_quantization),
        cmocka_unit_test(test_creep_step_time_constants),
        cmocka_unit_test(test_thermal_drift),
        cmocka_unit_test(test_sensor_errors),
        cmocka_unit_test(test_noise_statistics),
        cmocka_unit_test(test_default_loop_width_in_band),
        cmocka_unit_test(test_hysteresis_rate_dependence),
        cmocka_unit_test(test_hysteresis_rate_independent_exactly),
        cmocka_unit_test(test_hysteresis_branches),
        cmocka_unit_test(test_coupling_grows_with_frequency),
        cmocka_unit_test(test_coupling_depends_on_position),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
