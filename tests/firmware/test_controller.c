/* The controller: feedforward bit-exact with the kernels' golden models,
 * transactional table commits, rollback, persistence, safety. */
#include <string.h>

#include "piezo_test.h"
#include "controller.h"
#include "ctl_test_cfg.h"
#include "ctl_vectors.h"
#include "nor_flash.h"
#include "piezo_err.h"

static piezo_ctl_t ctl; /* large: not on the stack */

static int32_t tick(int16_t setpoint, int32_t adc)
{
    int32_t in[2] = {adc, 0}, dac = 0;
    ctl.setpoint_q15 = setpoint;
    piezo_ctl_tick(&ctl, in, &dac);
    return dac;
}

/* session 1 holds the provisioned key */
static void unlock_s1(void)
{
    piezo_ctl_set_key(&ctl, TEST_UNLOCK_KEY);
    assert_int_equal(piezo_ctl_unlock(&ctl, 1, TEST_UNLOCK_KEY, 0), PIEZO_OK);
}

static uint16_t upload(const uint8_t *img, uint32_t len)
{
    unlock_s1();
    /* in register-window sized chunks, as the protocol writes them */
    for (uint32_t off = 0; off < len; off += 246u) {
        uint32_t n = len - off < 246u ? len - off : 246u;
        assert_int_equal(piezo_ctl_stage_write(&ctl, 1, off, img + off, n), PIEZO_OK);
    }
    return piezo_ctl_commit(&ctl, 1, 0);
}

static void setup_armed(uint8_t mode)
{
    piezo_ctl_cfg_t cfg = unit_cfg();
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, mode), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
}

static void run_and_compare(const int16_t *want, const char *name)
{
    for (uint32_t k = 0; k < CTL_N; k++) {
        assert_golden_i32(name, k, tick(ctl_ref_q15[k], 0), want[k]);
    }
}

static void test_dcc_table_drives_bit_exact(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(upload(ctl_dcc_img, CTL_DCC_IMG_LEN), PIEZO_TABLE_REASON_OK);
    run_and_compare(ctl_dcc_u_q15, "dcc");
    assert_int_equal(piezo_ctl_active_version(&ctl), 1);
}

static void test_eupi_inverse_table_drives_bit_exact(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(upload(ctl_eupi_img, CTL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OK);
    run_and_compare(ctl_eupi_u_q15, "eupi_inverse");
}

static void test_refused_images_leave_the_active_table_running(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(upload(ctl_dcc_img, CTL_DCC_IMG_LEN), PIEZO_TABLE_REASON_OK);
    uint32_t crc = piezo_ctl_active_crc(&ctl);
    uint32_t half = CTL_N / 2u;
    for (uint32_t k = 0; k < half; k++) {
        assert_golden_i32("before", k, tick(ctl_ref_q15[k], 0), ctl_dcc_u_q15[k]);
    }
    for (unsigned i = 0; i < CTL_BAD_N; i++) {
        uint16_t r = upload(ctl_bad[i].img, ctl_bad[i].len);
        if (r != ctl_bad[i].reason) {
            fail_msg("%s: reason %u, want %u", ctl_bad[i].name, r, ctl_bad[i].reason);
        }
        assert_int_equal(ctl.st.table_result, ctl_bad[i].reason);
        assert_true(piezo_ctl_active_crc(&ctl) == crc);
    }
    /* a truncated upload and one with a flipped bit are refused too */
    assert_int_equal(upload(ctl_dcc_img, CTL_DCC_IMG_LEN - 9u), PIEZO_TABLE_REASON_BAD_LENGTH);
    static uint8_t flipped[CTL_DCC_IMG_LEN];
    memcpy(flipped, ctl_dcc_img, sizeof flipped);
    flipped[100] ^= 0x10;
    assert_int_equal(upload(flipped, sizeof flipped), PIEZO_TABLE_REASON_BAD_CRC);
    /* the drive carries on exactly as if nothing had been sent */
    for (uint32_t k = half; k < CTL_N; k++) {
        assert_golden_i32("after", k, tick(ctl_ref_q15[k], 0), ctl_dcc_u_q15[k]);
    }
}

static void test_commit_needs_unlock_and_an_upload(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(piezo_ctl_commit(&ctl, 1, 0), PIEZO_TABLE_REASON_LOCKED);
    assert_int_equal(piezo_ctl_stage_write(&ctl, 1, 0, ctl_dcc_img, 10), PIEZO_EPERM);
    piezo_ctl_set_key(&ctl, TEST_UNLOCK_KEY);
    assert_int_equal(piezo_ctl_unlock(&ctl, 1, 0x1234, 0), PIEZO_EKEY);
    assert_int_equal(ctl.st.bad_unlocks, 1);
    unlock_s1();
    assert_int_equal(piezo_ctl_commit(&ctl, 1, 0), PIEZO_TABLE_REASON_NOTHING_STAGED);
    assert_int_equal(piezo_ctl_rollback(&ctl, 1), PIEZO_TABLE_REASON_NO_PREVIOUS);
    assert_int_equal(piezo_ctl_active_crc(&ctl), 0);
}

static void test_swap_happens_at_the_next_tick_and_rolls_back(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(upload(ctl_dcc_img, CTL_DCC_IMG_LEN), PIEZO_TABLE_REASON_OK);
    assert_int_equal(ctl.active, -1);      /* not before a tick boundary */
    (void)tick(0, 0);
    assert_true(ctl.active >= 0);
    uint32_t crc_dcc = piezo_ctl_active_crc(&ctl);
    assert_int_equal(upload(ctl_eupi_img, CTL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OK);
    assert_int_equal(piezo_ctl_commit(&ctl, 1, 0), PIEZO_TABLE_REASON_BUSY); /* swap pending */
    (void)tick(0, 0);
    assert_int_equal(piezo_ctl_commit(&ctl, 1, 0), PIEZO_TABLE_REASON_NOTHING_STAGED);
    assert_int_equal(ctl.set[ctl.active].kind, PIEZO_TABLE_KIND_EUPI_INVERSE);
    assert_int_equal(piezo_ctl_rollback(&ctl, 1), PIEZO_TABLE_REASON_OK);
    assert_int_equal(piezo_ctl_rollback(&ctl, 1), PIEZO_TABLE_REASON_BUSY);
    (void)tick(0, 0);
    assert_true(piezo_ctl_active_crc(&ctl) == crc_dcc);
    assert_int_equal(piezo_ctl_rollback(&ctl, 1), PIEZO_TABLE_REASON_NO_PREVIOUS); /* one level */
}

static void test_tables_persist_across_reboot(void **state)
{
    (void)state;
    static uint8_t mem[2 * (PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES)];
    nor_flash_t f;
    nor_flash_init(&f, mem, sizeof mem);
    piezo_storage_t io = nor_flash_storage(&f, PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES);
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(piezo_ctl_attach_store(&ctl, &io), PIEZO_TABLE_REASON_OK);
    assert_int_equal(upload(ctl_dcc_img, CTL_DCC_IMG_LEN), PIEZO_TABLE_REASON_OK);
    (void)tick(0, 0);
    uint32_t crc_dcc = piezo_ctl_active_crc(&ctl);
    assert_int_equal(upload(ctl_eupi_img, CTL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OK);
    (void)tick(0, 0);
    uint32_t crc_eupi = piezo_ctl_active_crc(&ctl);
    /* reboot: the EUPI table runs again, the DCC table is the rollback target */
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(piezo_ctl_attach_store(&ctl, &io), PIEZO_TABLE_REASON_OK);
    assert_true(piezo_ctl_active_crc(&ctl) == crc_eupi);
    run_and_compare(ctl_eupi_u_q15, "eupi after reboot");
    unlock_s1();
    assert_int_equal(piezo_ctl_rollback(&ctl, 1), PIEZO_TABLE_REASON_OK);
    (void)tick(0, 0);
    assert_true(piezo_ctl_active_crc(&ctl) == crc_dcc);
    /* a flash write that fails refuses the commit and keeps the running table */
    f.ops_left = 1;
    assert_int_equal(upload(ctl_eupi_img, CTL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_STORAGE_FAILED);
    (void)tick(0, 0);
    assert_true(piezo_ctl_active_crc(&ctl) == crc_dcc);
    f.dead = 0;
    f.ops_left = -1;
    /* after a reboot the DCC table runs; the slot the failed write erased held
     * the only older copy, so there is nothing left to roll back to */
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(piezo_ctl_attach_store(&ctl, &io), PIEZO_TABLE_REASON_OK);
    assert_true(piezo_ctl_active_crc(&ctl) == crc_dcc);
    run_and_compare(ctl_dcc_u_q15, "dcc after reboot");
    unlock_s1();
    assert_int_equal(piezo_ctl_rollback(&ctl, 1), PIEZO_TABLE_REASON_NO_PREVIOUS);
}

static void test_sensor_fault_disarms_and_ramps_down(void **state)
{
    (void)state;
    piezo_ctl_cfg_t cfg = unit_cfg();
    cfg.u_safe_q15 = 0;
    cfg.adc_min_ok = -30000;
    cfg.adc_max_ok = 30000;
    cfg.limit.max_step_q15 = 1000;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_OPEN_LOOP), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    int32_t u = 0;
    for (int k = 0; k < 20; k++) {
        u = tick(10000, 0);
    }
    assert_int_equal(u, 10000); /* slewed up at 1000 per tick */
    /* two bad samples are tolerated, the third raises the fault */
    (void)tick(10000, 32767);
    (void)tick(10000, 32767);
    assert_true(ctl.st.armed);
    u = tick(10000, 32767);
    assert_true(ctl.st.faults & PIEZO_FAULT_SENSOR_IMPLAUSIBLE);
    assert_false(ctl.st.armed);
    assert_int_equal(u, 9000); /* ramping down, not jumping */
    for (int k = 0; k < 20; k++) {
        u = tick(10000, 0);
    }
    assert_int_equal(u, 0);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_EORDER); /* faults first */
    piezo_ctl_clear_faults(&ctl);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
}

static void test_overruns_are_counted_and_repeated_ones_fault(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_OPEN_LOOP);
    for (int k = 0; k < 8; k++) {
        piezo_ctl_overrun(&ctl);
        (void)tick(0, 0);
    }
    assert_int_equal(ctl.st.overruns, 8);
    assert_int_equal(ctl.st.faults, 0); /* isolated overruns only count */
    /* a run of 4 (the limit is 5) ended by a tick: the next run starts at 1 */
    for (int k = 0; k < 4; k++) {
        piezo_ctl_overrun(&ctl);
    }
    (void)tick(0, 0);
    for (int k = 0; k < 4; k++) {
        piezo_ctl_overrun(&ctl);
    }
    assert_int_equal(ctl.st.faults, 0);
    (void)tick(0, 0);
    for (int k = 0; k < 5; k++) {
        piezo_ctl_overrun(&ctl);
    }
    assert_true(ctl.st.faults & PIEZO_FAULT_OVERRUN);
    (void)tick(0, 0);
    assert_false(ctl.st.armed);
}

static void test_feedback_removes_a_static_error(void **state)
{
    (void)state;
    piezo_ctl_cfg_t cfg = unit_cfg();
    cfg.pid.kp_q24 = 1 << 23;   /* 0.5 */
    cfg.pid.ki_q24 = 1 << 21;   /* 0.125 per tick */
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_FEEDBACK), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    /* plant: y = u / 2 + 500, one tick late */
    int32_t y = 0, u = 0;
    for (int k = 0; k < 400; k++) {
        u = tick(8000, y);
        y = u / 2 + 500;
    }
    assert_signed_in_range(y, 7999, 8001);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_IDLE), PIEZO_EORDER); /* not while armed */
}

static void test_recorder_captures_the_wave_run(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_OPEN_LOOP);
    const int16_t peak = (int16_t)((20000 * 32767 + 16384) >> 15); /* triangle top is 32767 */
    piezo_rec_cfg_t rc = {.n_channels = 2, .signal = {PIEZO_SIG_REF, PIEZO_SIG_U}, .decimation = 1,
                          .trigger = PIEZO_REC_SOFTWARE};
    assert_int_equal(piezo_rec_configure(&ctl.rec, &rc), PIEZO_OK);
    piezo_rec_arm(&ctl.rec);
    ctl.wave_cfg.kind = PIEZO_WAVE_TRIANGLE;
    ctl.wave_cfg.amplitude_q15 = 20000;
    ctl.wave_cfg.freq_word = 1u << 26; /* 64 ticks a period */
    ctl.wave_cfg.cycles = 3;
    assert_int_equal(piezo_ctl_start_wave(&ctl), PIEZO_OK);
    for (int k = 0; k < 300; k++) {
        int32_t in[2] = {0, 0}, dac;
        piezo_ctl_tick(&ctl, in, &dac);
    }
    assert_int_equal(piezo_rec_frames(&ctl.rec), 300);
    int16_t f[2];
    assert_int_equal(piezo_rec_read(&ctl.rec, 16, f), PIEZO_OK);
    assert_int_equal(f[0], peak);   /* triangle peak at a quarter period */
    assert_int_equal(f[1], peak);   /* open loop with no table: u = r */
    assert_int_equal(piezo_rec_read(&ctl.rec, 250, f), PIEZO_OK);
    assert_int_equal(f[0], 0);      /* after 3 periods the wave has ended */
    assert_int_equal(f[1], 0);
}

static void test_preview_feeds_the_reference_early(void **state)
{
    (void)state;
    piezo_ctl_cfg_t cfg = unit_cfg();
    cfg.preview_ticks = 3;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_DIRECT), PIEZO_OK);
    ctl.wave_cfg.kind = PIEZO_WAVE_TRIANGLE;
    ctl.wave_cfg.amplitude_q15 = 20000;
    ctl.wave_cfg.freq_word = 1u << 26;
    assert_int_equal(piezo_ctl_start_wave(&ctl), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    int16_t u_hist[64], r_hist[64];
    for (int k = 0; k < 64; k++) {
        int32_t in[2] = {0, 0}, dac;
        piezo_ctl_tick(&ctl, in, &dac);
        u_hist[k] = ctl.sig[PIEZO_SIG_U];
        r_hist[k] = ctl.sig[PIEZO_SIG_REF];
    }
    for (int k = 0; k < 3; k++) {
        assert_int_equal(r_hist[k], 0); /* the line starts at the wave's offset */
    }
    for (int k = 3; k < 64; k++) {
        assert_int_equal(r_hist[k], u_hist[k - 3]); /* drive leads the reference by 3 ticks */
    }
    cfg.preview_ticks = PIEZO_CTL_MAX_PREVIEW + 1u;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_EINVAL);
}

static void test_shaper_spreads_a_step_over_its_taps(void **state)
{
    (void)state;
    piezo_ctl_cfg_t cfg = unit_cfg();
    cfg.shaper_ticks = 2;
    cfg.shaper_q15[0] = 8192;  /* ZVD of an undamped mode: 1/4, 1/2, 1/4 */
    cfg.shaper_q15[1] = 16384;
    cfg.shaper_q15[2] = 8192;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_DIRECT), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    const int32_t want[7] = {4000, 4000, 12000, 12000, 16000, 16000, 16000};
    for (int k = 0; k < 7; k++) {
        assert_int_equal(tick(16000, 0), want[k]);
        assert_int_equal(ctl.sig[PIEZO_SIG_REF], 16000); /* the reference itself is not shaped */
    }
    cfg.shaper_ticks = PIEZO_CTL_MAX_SHAPER + 1u;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_EINVAL);
}

/* The dynamics-inverse FIR on the early reference (after the shaper): a lead
 * 1.5 x(t) - 0.5 x(t - 2) (spacing 2), its saturation, and 0 taps = off. */
static void test_dyninv_filters_the_early_reference(void **state)
{
    (void)state;
    piezo_ctl_cfg_t cfg = unit_cfg();
    cfg.dyninv.n_taps = 2;
    cfg.dyninv.spacing = 2;
    cfg.dyninv.h_q13[0] = 12288; /* 1.5 */
    cfg.dyninv.h_q13[1] = -4096; /* -0.5 */
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_DIRECT), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    const int32_t want[5] = {24000, 24000, 16000, 16000, 16000}; /* overshoot for 2 ticks, then DC gain 1 */
    for (int k = 0; k < 5; k++) {
        assert_int_equal(tick(16000, 0), want[k]);
        assert_int_equal(ctl.sig[PIEZO_SIG_REF], 16000); /* the reference itself is not filtered */
    }
    assert_int_equal(tick(-30000, 0), -32768); /* 1.5 (-30000) - 0.5 (16000): saturated */
    assert_int_equal(tick(-30000, 0), -32768);
    assert_int_equal(tick(-30000, 0), -30000);
    /* with a shaper before it: the FIR sees the shaped reference (1/2, 1/2 at 0 and 1 tick) */
    cfg.shaper_ticks = 1;
    cfg.shaper_q15[0] = 16384;
    cfg.shaper_q15[1] = 16384;
    cfg.shaper_q15[2] = 0;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_DIRECT), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    const int32_t want_shaped[5] = {12000, 24000, 20000, 16000, 16000}; /* shaped: 8000, 16000, 16000 */
    for (int k = 0; k < 5; k++) {
        assert_int_equal(tick(16000, 0), want_shaped[k]);
    }
    /* 0 taps: off, whatever the taps hold */
    cfg.shaper_ticks = 0;
    cfg.dyninv.n_taps = 0;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_DIRECT), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    assert_int_equal(tick(16000, 0), 16000);
    /* more taps or a wider spacing than the filter holds: refused */
    cfg.dyninv.n_taps = PIEZO_FIR_MAX_TAPS + 1u;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_EINVAL);
    cfg.dyninv.n_taps = 1;
    cfg.dyninv.spacing = PIEZO_FIR_MAX_SPACING + 1u;
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_EINVAL);
}

static void test_load_image_commits_or_names_the_refusal(void **state)
{
    (void)state;
    setup_armed(PIEZO_MODE_FEEDFORWARD);
    assert_int_equal(piezo_ctl_load_image(&ctl, ctl_dcc_img, CTL_DCC_IMG_LEN), PIEZO_TABLE_REASON_OK);
    (void)tick(0, 0);
    uint32_t crc = piezo_ctl_active_crc(&ctl);
    assert_int_equal(piezo_ctl_load_image(&ctl, ctl_bad[0].img, ctl_bad[0].len), ctl_bad[0].reason);
    assert_int_equal(piezo_ctl_load_image(&ctl, NULL, 10), PIEZO_TABLE_REASON_BAD_LENGTH);
    assert_int_equal(piezo_ctl_load_image(&ctl, ctl_dcc_img, PIEZO_TABLE_MAX_BYTES + 1u), PIEZO_TABLE_REASON_BAD_LENGTH);
    (void)tick(0, 0);
    assert_true(piezo_ctl_active_crc(&ctl) == crc);
}

/* The tick's mode dispatch (a mask of the running mode since round 15)
 * against the rule it implements, written here as plain tests of the mode:
 * for every mode, armed or not, with and without a table, the first tick's
 * feedforward and feedback signals. */
enum { FF_ZERO, FF_REF, FF_LINE, FF_TABLE };
/* The sensor's scaling, y and y2: sat_q15(rshift_rnd64((code - adc_zero)
 * gain, 16)) as the int64 formula, for random zeros, gains (both signs, up to
 * the int32 range) and codes, the saturation's edges included (s = 2^31 - 1,
 * 2^31, -2^31, -2^31 - 1 before the shift). */
static int16_t sensor_formula(int32_t d, int32_t gain)
{
    int64_t v = ((int64_t)d * gain + 32768) >> 16;
    return (int16_t)(v > 32767 ? 32767 : (v < -32768 ? -32768 : v));
}

static void test_sensor_scale_matches_int64_formula(void **state)
{
    (void)state;
    uint32_t x = 12345u;
    /* the edges, d and gain: d gain + 2^15 = 2^31 - 1, 2^31, -2^31, -2^31 - 2, -1, 0 */
    const int32_t edge[][2] = {{INT32_MAX - 32768, 1}, {INT32_MAX - 32767, 1}, {-(1 << 30) - (1 << 14), 2},
                               {-(1 << 30) - (1 << 14) - 1, 2}, {-32769, 1}, {-32768, 1}};
    for (int i = 0; i < 2000; i++) {
        piezo_ctl_cfg_t cfg = unit_cfg();
        int32_t in[2], dac = 0, d0, d1;
        uint32_t sh;
        cfg.adc_zero = (int32_t)(piezo_test_lcg(&x) >> 8) - (1 << 23);
        sh = piezo_test_lcg(&x) % 31u;
        cfg.sensor_gain_q16 = (int32_t)piezo_test_lcg(&x) >> sh;
        cfg.adc_min_ok = INT32_MIN;
        cfg.adc_max_ok = INT32_MAX;
        if (i < 6) {
            cfg.adc_zero = 0;
            cfg.sensor_gain_q16 = edge[i][1];
            d0 = d1 = edge[i][0];
        } else {
            /* a difference of two values in [0, 2^31): no int32 overflow; then
             * a random magnitude */
            d0 = (int32_t)(piezo_test_lcg(&x) >> 1);
            d0 -= (int32_t)(piezo_test_lcg(&x) >> 1);
            d0 >>= piezo_test_lcg(&x) % 32u;
            d1 = (int32_t)(piezo_test_lcg(&x) >> 1);
            d1 -= (int32_t)(piezo_test_lcg(&x) >> 1);
            d1 >>= piezo_test_lcg(&x) % 32u;
        }
        /* codes whose difference from the zero does not overflow int32 */
        if ((cfg.adc_zero > 0 && d0 > INT32_MAX - cfg.adc_zero) || (cfg.adc_zero < 0 && d0 < INT32_MIN - cfg.adc_zero) ||
            (cfg.adc_zero > 0 && d1 > INT32_MAX - cfg.adc_zero) || (cfg.adc_zero < 0 && d1 < INT32_MIN - cfg.adc_zero)) {
            cfg.adc_zero = 0;
        }
        assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
        in[0] = cfg.adc_zero + d0;
        in[1] = cfg.adc_zero + d1;
        piezo_ctl_tick(&ctl, in, &dac);
        assert_int_equal(ctl.sig[PIEZO_SIG_Y], sensor_formula(d0, cfg.sensor_gain_q16));
        assert_int_equal(ctl.sig[PIEZO_SIG_Y2], sensor_formula(d1, cfg.sensor_gain_q16));
    }
}

/* The DAC code against the int64 rule, clamp(sat_i32(dac_zero +
 * rshift_rnd64(u gain, 16)), dac_min, dac_max): random drives (DIRECT, the
 * setpoint is u), gains, zeros and limits, and the edges (u and the gain at
 * their extremes, the rounding's ties of both signs). */
static void test_dac_code_matches_int64_formula(void **state)
{
    (void)state;
    uint32_t x = 4242u;
    const int32_t edge_u[] = {-32768, 32767, 1, -1, 0, -32768, 32767, 3, -3};
    const int32_t edge_g[] = {INT32_MIN, INT32_MIN, INT32_MAX, INT32_MAX, INT32_MAX, INT32_MAX, INT32_MIN, 1 << 15,
                              1 << 15}; /* (+-3) 2^15: ties at +-1.5 */
    for (int i = 0; i < 3000; i++) {
        piezo_ctl_cfg_t cfg = unit_cfg();
        int32_t u;
        if (i < (int)(sizeof edge_u / sizeof edge_u[0])) {
            u = edge_u[i];
            cfg.dac_gain_q16 = edge_g[i];
            cfg.dac_zero = 0;
            cfg.dac_min = INT32_MIN;
            cfg.dac_max = INT32_MAX;
        } else {
            u = (int32_t)(piezo_test_lcg(&x) >> 16) - 32768;
            cfg.dac_gain_q16 = (int32_t)piezo_test_lcg(&x) >> (piezo_test_lcg(&x) % 32u);
            cfg.dac_zero = (int32_t)piezo_test_lcg(&x) >> (piezo_test_lcg(&x) % 32u);
            int32_t a = (int32_t)piezo_test_lcg(&x), b = (int32_t)piezo_test_lcg(&x);
            cfg.dac_min = a < b ? a : b;
            cfg.dac_max = a < b ? b : a;
            if (i % 4 == 0) {
                cfg.dac_min = INT32_MIN; /* the int32 saturation itself */
                cfg.dac_max = INT32_MAX;
            }
        }
        assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
        assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_DIRECT), PIEZO_OK);
        assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
        const int32_t dac = tick((int16_t)u, 0);
        assert_int_equal(ctl.sig[PIEZO_SIG_U], u);
        int64_t want = cfg.dac_zero + (((int64_t)u * cfg.dac_gain_q16 + 32768) >> 16);
        want = want > INT32_MAX ? INT32_MAX : (want < INT32_MIN ? INT32_MIN : want);
        want = want < cfg.dac_min ? cfg.dac_min : (want > cfg.dac_max ? cfg.dac_max : want);
        if (dac != (int32_t)want) {
            fail_msg("u %ld gain %ld zero %ld [%ld, %ld]: code %ld, rule %lld", (long)u, (long)cfg.dac_gain_q16,
                     (long)cfg.dac_zero, (long)cfg.dac_min, (long)cfg.dac_max, (long)dac, (long long)want);
        }
    }
}

/* The sensor's plausibility against the rule written as plain tests: a code
 * outside [adc_min_ok, adc_max_ok], or, with max_jump > 0 and a good sample
 * seen, |y - y_prev| > max_jump, holds the last good value; random codes,
 * and max_jump changed (off, on, negative) between ticks through
 * piezo_ctl_config_changed, as the register map does. */
static void test_sensor_plausibility_matches_the_rule(void **state)
{
    (void)state;
    uint32_t x = 777u;
    for (int run = 0; run < 50; run++) {
        piezo_ctl_cfg_t cfg = unit_cfg();
        int16_t y_prev = 0;
        int have_y = 0;
        uint16_t bad_run = 0;
        cfg.bad_limit = 1000;
        cfg.adc_min_ok = -20000;
        cfg.adc_max_ok = 20000;
        cfg.max_jump_q15 = (int16_t)(run % 3 == 0 ? 0 : 50 * run);
        assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
        for (int k = 0; k < 200; k++) {
            int32_t in[2] = {0, 0}, dac = 0, code;
            int bad;
            if (k % 50 == 49) { /* a configuration change between two ticks */
                (void)piezo_test_lcg(&x);
                ctl.cfg.max_jump_q15 = (int16_t)((int32_t)(x >> 22) - 256); /* -256 .. 767 */
                piezo_ctl_config_changed(&ctl);
            }
            (void)piezo_test_lcg(&x);
            code = (int32_t)(x >> 16) - 32768;
            if ((x & 3u) != 0u) {
                code = y_prev + (int32_t)((x >> 8) & 1023u) - 512; /* mostly near the last good value */
            }
            in[0] = code;
            piezo_ctl_tick(&ctl, in, &dac);
            bad = code < cfg.adc_min_ok || code > cfg.adc_max_ok ||
                  (ctl.cfg.max_jump_q15 > 0 && have_y &&
                   (code - y_prev > ctl.cfg.max_jump_q15 || y_prev - code > ctl.cfg.max_jump_q15));
            if (bad) {
                bad_run++;
            } else {
                bad_run = 0;
                y_prev = (int16_t)code;
                have_y = 1;
            }
            assert_int_equal(ctl.sig[PIEZO_SIG_Y], y_prev);
            assert_int_equal(ctl.bad_run, bad_run);
        }
    }
}

static int want_ff(uint8_t mode, int armed, int table)
{
    if (!armed || mode == PIEZO_MODE_IDLE || mode == PIEZO_MODE_FEEDBACK) {
        return FF_ZERO;
    }
    if (mode == PIEZO_MODE_DIRECT || !table) {
        return FF_REF;
    }
    return mode == PIEZO_MODE_OPEN_LOOP ? FF_LINE : FF_TABLE;
}

static void test_mode_dispatch_matches_the_rule(void **state)
{
    (void)state;
    const int16_t r = ctl_ref_q15[0];
    const int32_t y = -1000; /* r - y != 0: the PI's output is not 0 */
    for (uint8_t mode = PIEZO_MODE_IDLE; mode <= PIEZO_MODE_DIRECT; mode++) {
        for (int armed = 0; armed <= 1; armed++) {
            for (int table = 0; table <= 1; table++) {
                piezo_ctl_cfg_t cfg = unit_cfg();
                cfg.pid.kp_q24 = 1 << 23; /* 0.5 */
                assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
                assert_int_equal(piezo_ctl_set_mode(&ctl, mode), PIEZO_OK);
                if (armed) {
                    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
                }
                if (table) {
                    assert_int_equal(upload(ctl_dcc_img, CTL_DCC_IMG_LEN), PIEZO_TABLE_REASON_OK);
                }
                (void)tick(r, y);
                int run = armed && mode != PIEZO_MODE_IDLE, k = want_ff(mode, armed, table);
                int16_t ff = ctl.sig[PIEZO_SIG_FF], fb = ctl.sig[PIEZO_SIG_FB];
                if (k == FF_ZERO) {
                    assert_int_equal(ff, 0);
                } else if (k == FF_REF) {
                    assert_int_equal(ff, r);
                } else {
                    int16_t line = piezo_line_q15(r, ctl.set_act->open_loop_gain_q24,
                                                  ctl.set_act->open_loop_offset_q15);
                    assert_true(line != ctl_dcc_u_q15[0]); /* the two are told apart */
                    assert_int_equal(ff, k == FF_LINE ? line : ctl_dcc_u_q15[0]);
                }
                if (run && (mode == PIEZO_MODE_FF_FEEDBACK || mode == PIEZO_MODE_FEEDBACK)) {
                    assert_true(fb != 0);
                } else {
                    assert_int_equal(fb, 0);
                }
                if (!run) {
                    assert_int_equal(ctl.sig[PIEZO_SIG_U], cfg.u_safe_q15);
                }
            }
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_dcc_table_drives_bit_exact),
        cmocka_unit_test(test_mode_dispatch_matches_the_rule),
        cmocka_unit_test(test_sensor_scale_matches_int64_formula),
        cmocka_unit_test(test_dac_code_matches_int64_formula),
        cmocka_unit_test(test_sensor_plausibility_matches_the_rule),
        cmocka_unit_test(test_eupi_inverse_table_drives_bit_exact),
        cmocka_unit_test(test_refused_images_leave_the_active_table_running),
        cmocka_unit_test(test_commit_needs_unlock_and_an_upload),
        cmocka_unit_test(test_swap_happens_at_the_next_tick_and_rolls_back),
        cmocka_unit_test(test_tables_persist_across_reboot),
        cmocka_unit_test(test_sensor_fault_disarms_and_ramps_down),
        cmocka_unit_test(test_overruns_are_counted_and_repeated_ones_fault),
        cmocka_unit_test(test_feedback_removes_a_static_error),
        cmocka_unit_test(test_recorder_captures_the_wave_run),
        cmocka_unit_test(test_preview_feeds_the_reference_early),
        cmocka_unit_test(test_shaper_spreads_a_step_over_its_taps),
        cmocka_unit_test(test_dyninv_filters_the_early_reference),
        cmocka_unit_test(test_load_image_commits_or_names_the_refusal),
    };
    return cmocka_run_group_tests_name("controller", tests, NULL, NULL);
}
