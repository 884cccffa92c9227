/* The wave's learned feedforward (controller.h, piezo_ctl_wave_ff_*): played
 * in sync with the wave, interpolated by the documented rule, added to the
 * loop's reference but not to the recorded error; bad commits refused and
 * the played table never half-written. */
#include <string.h>

#include "piezo_test.h"
#include "controller.h"
#include "ctl_test_cfg.h"
#include "piezo_err.h"

static piezo_ctl_t ctl; /* large: not on the stack */

#define PERIOD_TICKS 64u
#define FW (1u << 26) /* 2^32 / 64: one period in 64 ticks */

static int32_t tick(int32_t adc)
{
    int32_t in[2] = {adc, 0}, dac = 0;
    piezo_ctl_tick(&ctl, in, &dac);
    return dac;
}

/* A wave of constant 0 (triangle of amplitude 0) playing from phase 0. */
static void setup_wave(uint8_t mode, uint8_t preview)
{
    piezo_ctl_cfg_t cfg = unit_cfg();
    cfg.preview_ticks = preview;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, mode), PIEZO_OK);
    ctl.wave_cfg.kind = PIEZO_WAVE_TRIANGLE;
    ctl.wave_cfg.amplitude_q15 = 0;
    ctl.wave_cfg.offset_q15 = 0;
    ctl.wave_cfg.freq_word = FW;
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    assert_int_equal(piezo_ctl_start_wave(&ctl), PIEZO_OK);
}

/* The rule written out apart: entry i at phase i / n, linear in between,
 * rounded half up, the last entry running into the first. */
static int32_t expected(const int16_t *t, uint32_t n, uint32_t k)
{
    uint32_t per_entry = PERIOD_TICKS / n, i = (k % PERIOD_TICKS) / per_entry, j = (i + 1u) % n;
    int64_t num = (int64_t)(t[j] - t[i]) * (int64_t)(k % per_entry), den = per_entry;
    int64_t x = 2 * num + den, d = 2 * den; /* round(num / den) half up = floor(x / d) */
    int64_t q = x >= 0 ? x / d : -((-x + d - 1) / d);
    return t[i] + (int32_t)q;
}

static void test_played_in_sync_with_the_wave_by_the_rounding_rule(void **state)
{
    (void)state;
    static const int16_t table[4] = {0, 1000, 2000, -1001};
    setup_wave(PIEZO_MODE_DIRECT, 0u); /* DIRECT: the drive is r_ahead, so the correction itself */
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, table, 4u, FW), PIEZO_OK);
    assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 4u);
    ctl.wave_cfg.amplitude_q15 = 0;
    assert_int_equal(piezo_ctl_start_wave(&ctl), PIEZO_OK); /* phase 0 again */
    for (uint32_t k = 0; k < 3u * PERIOD_TICKS; k++) {
        int32_t u = tick(0);
        assert_int_equal(u, expected(table, 4u, k));
    }
}

static void test_loop_sees_the_correction_the_recorder_the_true_error(void **state)
{
    (void)state;
    static const int16_t table[2] = {1200, 1200};
    setup_wave(PIEZO_MODE_FEEDBACK, 3u);
    ctl.cfg.pid.kp_q24 = 1 << 24; /* u = e */
    assert_int_equal(piezo_pid_init(&ctl.pid, &ctl.cfg.pid), PIEZO_OK);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, table, 2u, FW), PIEZO_OK);
    for (uint32_t k = 0; k < 10u; k++) {
        int32_t u = tick(0);
        assert_int_equal(u, 1200);                 /* PID of (r + c) - y */
        assert_int_equal(ctl.sig[PIEZO_SIG_ERR], 0); /* recorded: r - y */
        assert_int_equal(ctl.sig[PIEZO_SIG_REF], 0);
    }
    piezo_ctl_stop_wave(&ctl);
    tick(0);
    assert_int_equal(ctl.wave_ff_q15, 0); /* no wave, no correction */
}

static void test_bad_commits_are_refused_and_change_nothing(void **state)
{
    (void)state;
    static int16_t big[PIEZO_CTL_WAVE_FF_MAX];
    static const int16_t a[2] = {500, 500};
    setup_wave(PIEZO_MODE_DIRECT, 0u);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, a, 2u, FW), PIEZO_OK);
    assert_int_equal(tick(0), 500);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, big, 0u, FW), PIEZO_EINVAL);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, big, (uint16_t)(PIEZO_CTL_WAVE_FF_MAX + 1u), FW), PIEZO_EINVAL);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, big, 8u, 0u), PIEZO_EINVAL);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, NULL, 8u, FW), PIEZO_EINVAL);
    assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 2u);
    for (uint32_t k = 0; k < 5u; k++) {
        assert_int_equal(tick(0), 500);
    }
}

static void test_the_played_table_is_never_half_written(void **state)
{
    (void)state;
    static int16_t a[PIEZO_CTL_WAVE_FF_MAX], b[PIEZO_CTL_WAVE_FF_MAX];
    int8_t played;
    for (uint32_t i = 0; i < PIEZO_CTL_WAVE_FF_MAX; i++) {
        a[i] = 700;
        b[i] = -900;
    }
    setup_wave(PIEZO_MODE_DIRECT, 0u);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, a, PIEZO_CTL_WAVE_FF_MAX, FW), PIEZO_OK);
    assert_int_equal(tick(0), 700);
    played = ctl.wave_ff_active;
    /* a second commit before a tick took the first one is refused */
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, b, PIEZO_CTL_WAVE_FF_MAX, FW), PIEZO_OK);
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, a, PIEZO_CTL_WAVE_FF_MAX, FW), PIEZO_EBUSY);
    assert_int_equal(piezo_ctl_wave_ff_off(&ctl), PIEZO_EBUSY);
    /* the commit filled the other slot: the one played is whole and unchanged */
    assert_int_equal(ctl.wave_ff_active, played);
    for (uint32_t i = 0; i < PIEZO_CTL_WAVE_FF_MAX; i++) {
        assert_int_equal(ctl.wave_ff[played].c_q15[i], 700);
    }
    assert_int_equal(tick(0), -900); /* the next tick plays the new one whole */
    b[0] = 5; /* the staged entries are copied: later writes change nothing played */
    for (uint32_t k = 0; k < PERIOD_TICKS; k++) {
        assert_int_equal(tick(0), -900);
    }
    assert_int_equal(ctl.wave_ff_q15, -900);
    assert_int_equal(piezo_ctl_wave_ff_off(&ctl), PIEZO_OK);
    assert_int_equal(tick(0), 0);
    assert_int_equal(ctl.wave_ff_q15, 0); /* switched off: no correction (the slot's last one gone) */
    assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 0u);
}

static void test_wave_starts_in_step_with_the_other_axis(void **state)
{
    (void)state;
    piezo_rec_cfg_t rc = {0};
    setup_wave(PIEZO_MODE_DIRECT, 0u);
    piezo_ctl_stop_wave(&ctl);
    ctl.ref_source = PIEZO_REF_WAVE;
    ctl.setpoint_q15 = 3000; /* replaced by the wave's offset (0) when armed */
    ctl.wave_cfg.amplitude_q15 = 20000;
    rc.n_channels = 1u;
    rc.signal[0] = PIEZO_SIG_U;
    rc.decimation = 1u;
    rc.trigger = PIEZO_REC_RISING;
    rc.trigger_signal = PIEZO_SIG_U2;
    rc.trigger_level_q15 = 0;
    assert_int_equal(piezo_rec_configure(&ctl.rec, &rc), PIEZO_OK);
    piezo_rec_arm(&ctl.rec);
    ctl.wave_cfg.kind = 99; /* a wave that does not check is refused, nothing armed */
    assert_int_equal(piezo_ctl_start_wave_on_trigger(&ctl), PIEZO_EINVAL);
    assert_int_equal(ctl.wave_on_trigger, 0);
    assert_int_equal(ctl.setpoint_q15, 3000);
    ctl.wave_cfg.kind = PIEZO_WAVE_TRIANGLE;
    assert_int_equal(piezo_ctl_start_wave_on_trigger(&ctl), PIEZO_OK);
    ctl.sig[PIEZO_SIG_U2] = -500;
    for (uint32_t k = 0; k < 7u; k++) {
        assert_int_equal(tick(0), 0); /* the wave's offset until the other axis' drive rises through 0 */
        assert_int_equal(ctl.ref_source, PIEZO_REF_SETPOINT);
    }
    ctl.sig[PIEZO_SIG_U2] = 500;
    assert_int_equal(tick(0), 0); /* the trigger tick: the wave starts after it */
    assert_int_equal(ctl.ref_source, PIEZO_REF_WAVE);
    assert_int_equal(tick(0), 0);    /* sample 0: the triangle starts at 0 rising */
    assert_int_equal(tick(0), 1250); /* sample 1: 20000 * 2048 / 32768 */
    piezo_ctl_stop_wave(&ctl);
    assert_int_equal(ctl.wave_on_trigger, 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_played_in_sync_with_the_wave_by_the_rounding_rule),
        cmocka_unit_test(test_loop_sees_the_correction_the_recorder_the_true_error),
        cmocka_unit_test(test_bad_commits_are_refused_and_change_nothing),
        cmocka_unit_test(test_the_played_table_is_never_half_written),
        cmocka_unit_test(test_wave_starts_in_step_with_the_other_axis),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
