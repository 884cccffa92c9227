/* The stage parameter file: the shipped files equal the built-in defaults,
 * and bad files give errors that name the file, the line and the key. */
#include "piezo_test.h"
#include "stage_model.h"

#include <string.h>

static char err[512];

static int parse(const char *text, stage_params *p)
{
    err[0] = '\0';
    return stage_params_parse_json(text, "t.json", p, err, sizeof err);
}

static void expect_error(const char *text, int rc, const char *fragment1, const char *fragment2)
{
    stage_params p;
    int got = parse(text, &p);
    if (got != rc) {
        fail_msg("rc %d, want %d (error: '%s') for: %s", got, rc, err, text);
    }
    if (!strstr(err, fragment1) || (fragment2 && !strstr(err, fragment2))) {
        fail_msg("error '%s' lacks '%s' / '%s'", err, fragment1, fragment2 ? fragment2 : "");
    }
}

/* Same samples from two parameter sets (a strong check that all fields match). */
static void assert_same_stage(const stage_params *a, const stage_params *b)
{
    stage_t sa, sb;
    int k, i;
    assert_int_equal(a->num_axes, b->num_axes);
    assert_string_equal(a->name, b->name);
    assert_int_equal(stage_init(&sa, a, 5), STAGE_OK);
    assert_int_equal(stage_init(&sb, b, 5), STAGE_OK);
    for (k = 0; k < 30000; k++) {
        int32_t dac[2], ya[2], yb[2];
        dac[0] = (int32_t)(k * 37 % 65536);
        dac[1] = (int32_t)(65535 - k * 11 % 65536);
        stage_step(&sa, dac, ya);
        stage_step(&sb, dac, yb);
        for (i = 0; i < a->num_axes; i++) {
            assert_int_equal(ya[i], yb[i]);
            assert_true(stage_true_um(&sa, i) == stage_true_um(&sb, i));
        }
    }
}

static void test_default_file_is_the_default(void **state)
{
    stage_params p, d = stage_params_default();
    (void)state;
    if (stage_params_load_json(STAGE_DIR "/default.json", &p, err, sizeof err) != STAGE_OK) {
        fail_msg("%s", err);
    }
    assert_same_stage(&p, &d);
    assert_true(p.axis[0].hysteresis.alpha == d.axis[0].hysteresis.alpha);
    assert_int_equal(p.axis[0].creep.n_terms, 5);
    assert_true(p.axis[0].creep.term[4].tau_s == 100.0);
    assert_int_equal(p.axis[0].mechanics.n_modes, 2);
}

static void test_two_axis_file_is_the_two_axis_default(void **state)
{
    stage_params p, d = stage_params_two_axis();
    (void)state;
    if (stage_params_load_json(STAGE_DIR "/two_axis.json", &p, err, sizeof err) != STAGE_OK) {
        fail_msg("%s", err);
    }
    assert_same_stage(&p, &d);
    assert_true(p.coupling.enabled);
    assert_true(p.coupling.into[1].dynamic_percent == 6.04);
    assert_true(p.axis[1].mechanics.mode[0].freq_hz == 140.0);
}

static void test_keys_override_the_base(void **state)
{
    stage_params p;
    (void)state;
    assert_int_equal(parse("{\"base\": \"ideal\", \"axes\": [{\"delay\": {\"enabled\": true, \"samples\": 3},"
                           " \"note\": \"free text\"}], \"sample_rate_hz\": 5e3}",
                           &p),
                     STAGE_OK);
    assert_true(p.axis[0].delay.enabled);
    assert_int_equal(p.axis[0].delay.samples, 3);
    assert_false(p.axis[0].hysteresis.enabled);
    assert_true(p.sample_rate_hz == 5000.0);
    /* without "base" the default stage is the base */
    assert_int_equal(parse("{\"axes\": [{\"noise\": {\"rms_um\": 0.01}}]}", &p), STAGE_OK);
    assert_true(p.axis[0].noise.rms_um == 0.01);
    assert_true(p.axis[0].hysteresis.enabled);
    assert_true(p.axis[0].actuator_gain_um_per_v == 0.11);
    /* escapes and negative exponents */
    assert_int_equal(parse("{\"name\": \"a\\\"b\\u00e9\", \"axes\": [{\"adc\": {\"range_um\": [-2.5E-1, 1e1]}}]}",
                           &p),
                     STAGE_OK);
    assert_string_equal(p.name, "a\"b\xc3\xa9");
    assert_true(p.axis[0].adc.y_min_um == -0.25 && p.axis[0].adc.y_max_um == 10.0);
}

static void test_unknown_key(void **state)
{
    (void)state;
    expect_error("{\n\"axes\": [\n {\"hysteresis\": {\n  \"alpah\": 0.3}}]}", STAGE_ERR_JSON,
                 "t.json:4:", "axes[0].hysteresis.alpah: unknown key");
    expect_error("{\"sample_rate\": 1}", STAGE_ERR_JSON, "t.json:1:", "sample_rate: unknown key");
    expect_error("{\"base\": \"fancy\"}", STAGE_ERR_JSON, "base", "ideal");
}

static void test_bad_number(void **state)
{
    (void)state;
    expect_error("{\n\"sample_rate_hz\": 1.2.3}", STAGE_ERR_JSON, "t.json:2:", "bad number");
    expect_error("{\"sample_rate_hz\": 01}", STAGE_ERR_JSON, "t.json:1:", "bad number");
    expect_error("{\"sample_rate_hz\": 1.}", STAGE_ERR_JSON, "t.json:1:", "digits expected");
    expect_error("{\"sample_rate_hz\": 1e}", STAGE_ERR_JSON, "t.json:1:", "exponent");
    expect_error("{\"sample_rate_hz\": 1e999}", STAGE_ERR_JSON, "t.json:1:", "out of range");
    expect_error("{\"sample_rate_hz\": NaN}", STAGE_ERR_JSON, "t.json:1:", "value expected");
    expect_error("{\n\n\"sample_rate_hz\": \"10000\"}", STAGE_ERR_JSON, "t.json:3:",
                 "sample_rate_hz: must be a number, not a string");
    expect_error("{\"axes\": [{\"delay\": {\"samples\": 1.5}}]}", STAGE_ERR_JSON, "axes[0].delay.samples",
                 "must be an integer");
    expect_error("{\"axes\": [{\"dac\": {\"range_v\": [1]}}]}", STAGE_ERR_JSON, "axes[0].dac.range_v",
                 "[min, max]");
    expect_error("{\"axes\": [{\"dac\": {\"enabled\": 1}}]}", STAGE_ERR_JSON, "axes[0].dac.enabled",
                 "true or false");
}

static void test_syntax_errors(void **state)
{
    (void)state;
    expect_error("{\"name\": \"x\",}", STAGE_ERR_JSON, "t.json:1:", "key in double quotes");
    expect_error("{\"name\": \"x\"\n\"sample_rate_hz\": 1}", STAGE_ERR_JSON, "t.json:2:", "',' or '}'");
    expect_error("{\"name\": \"x\", \"name\": \"y\"}", STAGE_ERR_JSON, "t.json:1:", "duplicate key 'name'");
    expect_error("{\"name\": \"x", STAGE_ERR_JSON, "t.json:1:", "unterminated string");
    expect_error("{} {}", STAGE_ERR_JSON, "t.json:1:", "trailing");
    expect_error("[1, 2]", STAGE_ERR_JSON, "t.json", "must be an object");
    expect_error("", STAGE_ERR_JSON, "t.json", "unexpected end");
}

static void test_out_of_range_values(void **state)
{
    (void)state;
    expect_error("{\"axes\": [{\"adc\": {\"bits\": 40}}]}", STAGE_ERR_PARAM, "t.json", "axes[0].adc.bits: 40");
    expect_error("{\"axes\": [{\"mechanics\": {\"modes\": [{\"freq_hz\": -1, \"damping\": 0.1, \"gain\": 1}]}}]}",
                 STAGE_ERR_PARAM, "axes[0].mechanics.modes[0].freq_hz", "> 0");
    expect_error("{\"axes\": [{\"hysteresis\": {\"beta\": 0.1, \"gamma\": 0.5}}]}", STAGE_ERR_PARAM,
                 "axes[0].hysteresis", "beta > |gamma|");
    expect_error("{\"axes\": [{\"mechanics\": {\"modes\": [{}, {}, {}, {}, {}]}}]}", STAGE_ERR_JSON,
                 "axes[0].mechanics.modes", "at most 4");
    expect_error("{\"coupling\": {\"enabled\": true}}", STAGE_ERR_PARAM, "coupling", "1 axis");
    expect_error("{\"axes\": [{\"delay\": {\"samples\": 65}}]}", STAGE_ERR_PARAM, "delay.samples", "0..64");
}

static void test_missing_file(void **state)
{
    stage_params p;
    (void)state;
    assert_int_equal(stage_params_load_json(STAGE_TMP_DIR "/no_such_stage.json", &p, err, sizeof err),
                     STAGE_ERR_FILE);
    assert_non_null(strstr(err, "no_such_stage.json"));
    assert_non_null(strstr(err, "cannot open"));
}

static void test_file_errors_name_the_file(void **state)
{
    stage_params p;
    const char *path = STAGE_TMP_DIR "/test_stage_json_bad.json";
    FILE *f = fopen(path, "w");
    (void)state;
    assert_non_null(f);
    fputs("{\n  \"name\": \"bad\",\n  \"axes\": [{\"amplifier\": {\"gian\": 15}}]\n}\n", f);
    fclose(f);
    assert_int_equal(stage_params_load_json(path, &p, err, sizeof err), STAGE_ERR_JSON);
    assert_non_null(strstr(err, "test_stage_json_bad.json:3:"));
    assert_non_null(strstr(err, "axes[0].amplifier.gian: unknown key"));
    remove(path);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_default_file_is_the_default),
        cmocka_unit_test(test_two_axis_file_is_the_two_axis_default),
        cmocka_unit_test(test_keys_override_the_base),
        cmocka_unit_test(test_unknown_key),
        cmocka_unit_test(test_bad_number),
        cmocka_unit_test(test_syntax_errors),
        cmocka_unit_test(test_out_of_range_values),
        cmocka_unit_test(test_missing_file),
        cmocka_unit_test(test_file_errors_name_the_file),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
