/* Wave generator against the ideal shapes it samples. */
#include <math.h>

#include "piezo_test.h"
#include "fixed_q.h"
#include "piezo_err.h"
#include "piezo_interface.h"
#include "wave.h"

#define TWO_PI 6.283185307179586

static uint32_t word_of(double f_hz) { return (uint32_t)llround(f_hz / 10000.0 * 4294967296.0); }

static void test_sine_tracks_ideal_within_two_lsb(void **state)
{
    (void)state;
    piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_SINE, .offset_q15 = 1000, .amplitude_q15 = 30000,
                          .freq_word = word_of(137.0)};
    piezo_wave_t w;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
    double worst = 0.0;
    for (int k = 0; k < 5000; k++) {
        double ideal = 1000.0 + 30000.0 * sin(TWO_PI * (double)c.freq_word * k / 4294967296.0);
        double err = fabs((double)piezo_wave_process(&w) - ideal);
        worst = err > worst ? err : worst;
    }
    print_message("sine: max error %.2f LSB\n", worst);
    assert_true(worst <= 2.0);
}

/* The sine sample by sample: offset + rshift_rnd(amplitude * sine(phase), 15)
 * in int64, saturated, phase k * freq_word, over random offsets, amplitudes
 * and words; with cycles the wave ends after that many wraps of the phase
 * (then the offset). */
static void test_sine_is_the_table_rule_and_finishes_after_cycles(void **state)
{
    (void)state;
    uint32_t x = 2024u;
    for (int t = 0; t < 40; t++) {
        piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_SINE, .cycles = (uint32_t)(t % 4)};
        piezo_wave_t w;
        uint32_t phase = 0u, wraps = 0u;
        c.offset_q15 = (int16_t)(piezo_test_lcg(&x) >> 16);
        c.amplitude_q15 = (int16_t)(piezo_test_lcg(&x) >> 16);
        c.freq_word = (piezo_test_lcg(&x) >> (t % 8u)) | 1u;
        assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
        for (int k = 0; k < 3000; k++) {
            int64_t v = (int64_t)c.offset_q15 +
                        (((int64_t)c.amplitude_q15 * piezo_sine_q15(phase) + (1 << 14)) >> 15);
            int16_t want = (int16_t)(v > 32767 ? 32767 : (v < -32768 ? -32768 : v));
            if (c.cycles != 0u && wraps >= c.cycles) {
                want = c.offset_q15; /* finished */
            }
            assert_int_equal(piezo_wave_process(&w), want);
            if (c.cycles == 0u || wraps < c.cycles) {
                wraps += (phase + c.freq_word < phase);
                phase += c.freq_word;
            }
            assert_int_equal(piezo_wave_running(&w), c.cycles == 0u || wraps < c.cycles);
        }
    }
}

static void test_triangle_is_exact_and_finishes_after_cycles(void **state)
{
    (void)state;
    /* freq_word 2^26: a period of exactly 64 ticks */
    piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_TRIANGLE, .amplitude_q15 = 32767, .freq_word = 1u << 26, .cycles = 2};
    piezo_wave_t w;
    int16_t y[200];
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
    int k = 0;
    while (piezo_wave_running(&w) && k < 200) {
        y[k++] = piezo_wave_process(&w);
    }
    assert_int_equal(k, 128);
    assert_int_equal(y[0], 0);
    assert_signed_in_range(y[16], 32765, 32767); /* peak at a quarter period */
    assert_signed_in_range(y[48], -32767, -32765);
    for (int i = 1; i < 16; i++) {
        assert_true(y[i] > y[i - 1]); /* rising edge is monotonic */
    }
    assert_int_equal(piezo_wave_process(&w), 0); /* finished: offset */
}

static void test_chirp_sweeps_and_stops_at_end_frequency(void **state)
{
    (void)state;
    piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_CHIRP, .amplitude_q15 = 20000, .freq_word = word_of(10.0),
                          .chirp_rate_word = 1000, .chirp_end_word = word_of(10.0) + 1000u * 500u};
    piezo_wave_t w;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
    int k = 0;
    while (piezo_wave_running(&w) && k < 10000) {
        (void)piezo_wave_process(&w);
        k++;
    }
    assert_int_equal(k, 500);
    c.chirp_end_word = c.freq_word - 1u;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_EORDER);
}

static void test_multisine_is_sum_of_its_tones(void **state)
{
    (void)state;
    piezo_wave_tone_t tones[2] = {{12000, word_of(5.0), 0u}, {8000, word_of(73.0), 1u << 30}};
    piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_MULTISINE, .offset_q15 = -500, .n_tones = 2, .tones = tones};
    piezo_wave_t w;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
    for (int k = 0; k < 3000; k++) {
        double ideal = -500.0 + 12000.0 * sin(TWO_PI * 5.0 * k / 10000.0) +
                       8000.0 * sin(TWO_PI * 73.0 * k / 10000.0 + TWO_PI / 4.0);
        assert_signed_in_range(piezo_wave_process(&w), (long long)floor(ideal - 3.0), (long long)ceil(ideal + 3.0));
    }
    c.n_tones = PIEZO_WAVE_MAX_TONES + 1u;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_ERANGE);
}

static void test_steps_hold_each_level_for_its_duration(void **state)
{
    (void)state;
    const int16_t levels[3] = {-16384, 16384, 0};
    const uint32_t dur[3] = {3, 1, 5};
    piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_STEPS, .amplitude_q15 = 32767, .cycles = 1,
                          .n_levels = 3, .levels_q15 = levels, .durations = dur};
    piezo_wave_t w;
    /* documented scaling: (amplitude * level + 2^14) >> 15; 32767 * -16384 -> -16383, 32767 * 16384 -> 16384 */
    const int16_t want[10] = {-16383, -16383, -16383, 16384, 0, 0, 0, 0, 0, 0};
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
    for (int k = 0; k < 10; k++) {
        assert_int_equal(piezo_wave_process(&w), want[k]);
    }
    assert_false(piezo_wave_running(&w));
    const uint32_t bad[3] = {3, 0, 5};
    c.durations = bad;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_EINVAL);
}

static void test_arbitrary_table_repeats_with_hold(void **state)
{
    (void)state;
    const int16_t levels[2] = {32767, -32768};
    piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_ARBITRARY, .offset_q15 = 100, .amplitude_q15 = 16384,
                          .n_levels = 2, .levels_q15 = levels, .hold_ticks = 2};
    piezo_wave_t w;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
    const int16_t want[6] = {16484, 16484, -16284, -16284, 16484, 16484};
    for (int k = 0; k < 6; k++) {
        assert_int_equal(piezo_wave_process(&w), want[k]);
    }
    assert_true(piezo_wave_running(&w)); /* cycles = 0: endless */
}

/* The int32 arithmetic of wave.c against the int64 formulas it replaced
 * (wave.h, "Scaling and overflow"): the sine's interpolation on every segment
 * at the fractions' extremes and a spread of others, and the output scaling
 * at the extremes of amplitude, shape and offset. */
static void test_int32_forms_match_the_int64_formulas(void **state)
{
    (void)state;
    static const uint32_t fracs[] = {0u, 1u, 2u, 0x7FFFu, 0x8000u, 0x8001u, 0xFFFEu, 0xFFFFu, 12345u, 54321u};
    int32_t max_step = 0;
    for (uint32_t i = 0; i + 1u < PIEZO_SINE_LUT_N; i++) {
        int32_t y0 = piezo_sine_lut_q15[i], y1 = piezo_sine_lut_q15[i + 1u];
        int32_t step = y1 > y0 ? y1 - y0 : y0 - y1;
        max_step = step > max_step ? step : max_step;
        if (i >= 1024u) {
            continue; /* the last entry closes the period: no segment starts there */
        }
        for (size_t f = 0; f < sizeof fracs / sizeof fracs[0]; f++) {
            uint32_t phase = i << 22 | fracs[f] << 6 | (uint32_t)(f & 63u);
            int16_t want = piezo_sat_q15(y0 + piezo_rshift_rnd64((int64_t)(y1 - y0) * (int32_t)fracs[f], 16u));
            assert_int_equal(piezo_sine_q15(phase), want);
        }
    }
    /* the int32 interpolation needs |step| < 2^15; the table's is about 201 */
    assert_true(max_step < 256);

    static const int16_t amps[] = {-32768, -32767, -1, 0, 1, 16384, 32767};
    static const int16_t levels[] = {-32768, -32767, -16384, -1, 0, 1, 16383, 32767};
    static const int16_t offsets[] = {-32768, -20000, 0, 20000, 32767};
    for (size_t a = 0; a < sizeof amps / sizeof amps[0]; a++) {
        for (size_t o = 0; o < sizeof offsets / sizeof offsets[0]; o++) {
            piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_ARBITRARY, .offset_q15 = offsets[o], .amplitude_q15 = amps[a],
                                  .n_levels = sizeof levels / sizeof levels[0], .levels_q15 = levels, .hold_ticks = 1};
            piezo_wave_t w;
            assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
            for (size_t k = 0; k < sizeof levels / sizeof levels[0]; k++) {
                int16_t want = piezo_sat_q15((int64_t)offsets[o] +
                                             piezo_rshift_rnd64((int64_t)amps[a] * levels[k], 15u));
                assert_int_equal(piezo_wave_process(&w), want);
            }
        }
    }
}

static void test_output_saturates_at_q15(void **state)
{
    (void)state;
    piezo_wave_cfg_t c = {.kind = PIEZO_WAVE_SINE, .offset_q15 = 20000, .amplitude_q15 = 30000,
                          .freq_word = word_of(100.0)};
    piezo_wave_t w;
    int16_t hi = INT16_MIN;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_OK);
    for (int k = 0; k < 100; k++) {
        int16_t v = piezo_wave_process(&w);
        hi = v > hi ? v : hi;
    }
    assert_int_equal(hi, 32767);
    c.kind = 42;
    assert_int_equal(piezo_wave_init(&w, &c), PIEZO_EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sine_tracks_ideal_within_two_lsb),
        cmocka_unit_test(test_sine_is_the_table_rule_and_finishes_after_cycles),
        cmocka_unit_test(test_triangle_is_exact_and_finishes_after_cycles),
        cmocka_unit_test(test_chirp_sweeps_and_stops_at_end_frequency),
        cmocka_unit_test(test_multisine_is_sum_of_its_tones),
        cmocka_unit_test(test_steps_hold_each_level_for_its_duration),
        cmocka_unit_test(test_arbitrary_table_repeats_with_hold),
        cmocka_unit_test(test_output_saturates_at_q15),
        cmocka_unit_test(test_int32_forms_match_the_int64_formulas),
    };
    return cmocka_run_group_tests_name("wave", tests, NULL, NULL);
}
