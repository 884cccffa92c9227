/* The closed loop through the DAQ target's code path: configuration text,
 * piezo_daq_open, the controller configured by piezo_daq_ctl_config, ticks
 * by piezo_daq_loop_tick (one comedi_do_insnlist to read, one to write), a
 * fake comedi board (fake_comedi.c) whose outputs drive the C stage model
 * and whose inputs read its sensor. Simulated time: no sleeping.
 *
 * 1. PCI-1716-like board, 0..10 V output into the default stage's amplifier
 *    (x15), sensor scaled onto a 0..10 V input. The board's converters and
 *    the stage's have the same steps (the stage's DAC spans 10 V * 65536 /
 *    65535 over 2^16 codes, as comedi maps 0..maxdata onto the range), so
 *    the DAQ path must reproduce the SIL loop exactly: the same controller
 *    configuration, and tick for tick the same DAC codes reaching the stage,
 *    while tables from the host's calibration pipeline (the SIL tables)
 *    compensate a 10 Hz (and 1 Hz) triangle over 80 % of the stroke. The RMS
 *    error against the true displacement is printed and its reduction
 *    against the uncompensated straight line asserted against the SIL
 *    targets (5x at 10 Hz, 10x at 1 Hz).
 * 2. PCI-6221-like board (+-10 V output, soft-calibrated converters with
 *    gain and offset errors): in FEEDBACK the loop holds the MEASURED
 *    position on the setpoint, so the sensor's true output sits on the
 *    setpoint with the calibration file and off it by exactly the input
 *    converter's error without.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "daq_io.h"
#include "fake_comedi.h"
#include "piezo_err.h"
#include "piezo_test.h"
#include "sil_loop.h"
#include "sil_tables_vectors.h"

#define RAMP_TICKS 2500u
#define SEED 4242u

enum cfg_id { CFG_NONE, CFG_EUPI_FB, CFG_DCC_FB, CFG_N };
static const char *const cfg_name[CFG_N] = {"none", "eupi+fb", "dcc+fb"};

static stage_params params;
static stage_t stage;   /* behind the fake board */
static piezo_sil_t sil; /* the SIL reference */
static piezo_daq_t daq;
static piezo_daq_config_t dcfg;
static piezo_ctl_t ctl;
static piezo_daq_loop_t loop;
static char err[1024];

/* sensor: um = -2 + 2.4 * 65535 / 65536 * volts, so stage ADC code s is s * 10 / 65535 V */
#define CFG_1716                                                                                            \
    "device = /dev/comedi0\nflash = unused\n"                                                              \
    "[axis 0]\nao.subdevice = 1\nao.channel = 0\nao.range = 1\n"                                           \
    "ai.subdevice = 0\nai.channel = 3\nai.range = 5\nai.aref = diff\n"                                     \
    "amplifier.gain = 15\nsensor.um_per_v = 2.39996337890625\nsensor.offset_um = -2\n"

static void load_params(void)
{
    if (stage_params_load_json(STAGE_FILE, &params, err, sizeof err) != STAGE_OK) {
        fail_msg("%s", err);
    }
    /* code 65535 is 10 V, as comedi maps a 0..10 V range */
    params.axis[0].dac.v_max = 10.0 * 65536.0 / 65535.0;
}

/* The SIL's PI + notch; the PID gains divided by gain_div (a drive span
 * gain_div times the SIL's per q15). */
static void set_fb(piezo_ctl_cfg_t *c, int32_t gain_div)
{
    const piezo_biquad_coef_t notch = {SIL_NOTCH_B0_Q24, SIL_NOTCH_B1_Q24, SIL_NOTCH_B2_Q24,
                                       SIL_NOTCH_A1_Q24, SIL_NOTCH_A2_Q24};
    piezo_sil_set_feedback(c, SIL_FB_KP_Q24 / gain_div, SIL_FB_KI_Q24 / gain_div, SIL_FB_KD_Q24 / gain_div,
                           &notch);
}

static void no_violation(void)
{
    const char *v = fake_comedi_violation();
    if (v != NULL) {
        fail_msg("fake comedi: %s", v);
    }
}

/* The board, the stage behind it and the DAQ controller, at rest under the safe drive. */
static piezo_scale_t bring_up(const char *text, const fake_board_t *b, const char *cal, const fake_wire_t *w,
                                  int32_t fb_div, piezo_ctl_cfg_t *cc_out)
{
    piezo_ctl_cfg_t cc;
    piezo_scale_t sc;
    if (piezo_daq_config_parse(text, "closed-loop.cfg", &dcfg, err, sizeof err) != 0) {
        fail_msg("%s", err);
    }
    fake_comedi_reset();
    fake_comedi_set_board("/dev/comedi0", b);
    fake_comedi_set_calibration(cal, -1);
    assert_int_equal(stage_init(&stage, &params, SEED), STAGE_OK);
    fake_comedi_attach_stage(&stage, w, 1);
    fake_comedi_expect_io(w->ao_subdev, w->ao_chan, dcfg.axis[0].ao.range, dcfg.axis[0].ao.aref);
    fake_comedi_expect_io(w->ai_subdev, w->ai_chan, dcfg.axis[0].ai.range, dcfg.axis[0].ai.aref);
    if (piezo_daq_open(&daq, &dcfg, err, sizeof err) != 0) {
        fail_msg("%s", err);
    }
    assert_int_equal(piezo_daq_ctl_config(&daq, &dcfg, 0, &cc, &sc), PIEZO_OK);
    set_fb(&cc, fb_div);
    assert_int_equal(piezo_ctl_init(&ctl, &cc), PIEZO_OK);
    memset(&loop, 0, sizeof loop);
    loop.daq = &daq;
    loop.ctl[0] = &ctl;
    assert_int_equal(piezo_daq_write_safe(&daq), 0); /* as daq-controller does after the open */
    assert_int_equal(fake_comedi_stats()->steps, 1);
    if (cc_out != NULL) {
        *cc_out = cc;
    }
    return sc;
}

static void both_tick(int with_sil, uint32_t k)
{
    assert_int_equal(piezo_daq_loop_tick(&loop), 0);
    if (with_sil) {
        piezo_sil_tick(&sil);
        if (fake_comedi_stage_dac(0) != sil.dac[0] || loop.dac[0] != sil.dac[0] || loop.adc[0] != sil.ctl[0].sig[PIEZO_SIG_Y] + 32768) {
            fail_msg("tick %u: DAQ path DAC %d (stage got %d, sensor code %d), SIL DAC %d (sensor q15 %d)", k,
                     loop.dac[0], fake_comedi_stage_dac(0), loop.adc[0], sil.dac[0], sil.ctl[0].sig[PIEZO_SIG_Y]);
        }
    }
}

/* One triangle run through the DAQ path, the SIL loop alongside; RMS error
 * against the true displacement [um]. */
static double run_1716(int ci, double f)
{
    static const fake_wire_t w = {1, 0, 0, 3, -2.0, 2.39996337890625};
    fake_board_t b = fake_board_pci1716();
    piezo_ctl_cfg_t cc, sil_cc;
    piezo_scale_t ssc;
    piezo_scale_t sc;
    piezo_ctl_t *c[2];
    const uint32_t period = (uint32_t)lround(10000.0 / f);
    const uint32_t n_settle = period * (f < 5.0 ? 2u : 4u), n_meas = n_settle;
    uint8_t mode = ci == CFG_NONE ? PIEZO_MODE_OPEN_LOOP : PIEZO_MODE_FF_FEEDBACK;
    double se = 0.0;

    sc = bring_up(CFG_1716, &b, NULL, &w, 1, &cc);
    assert_int_equal(daq.ao[0].conv, PIEZO_DAQ_CONV_HARDCAL);
    assert_int_equal(daq.ai[0].conv, PIEZO_DAQ_CONV_HARDCAL);
    /* the SIL reference on the same stage and seed, with the same feedback */
    assert_int_equal(piezo_sil_init(&sil, &params, SEED), PIEZO_OK);
    assert_int_equal(piezo_sil_ctl_config(&params, 0, &sil_cc, &ssc), PIEZO_OK);
    set_fb(&sil_cc, 1);
    assert_memory_equal(&cc, &sil_cc, sizeof cc); /* the DAQ target configures the controller alike */
    assert_int_equal(piezo_ctl_init(&sil.ctl[0], &sil_cc), PIEZO_OK);
    assert_true(fabs(sc.drive_max_v - ssc.drive_max_v) < 1e-9 && fabs(sc.position_max_um - ssc.position_max_um) < 1e-9);

    c[0] = &ctl;
    c[1] = &sil.ctl[0];
    for (int i = 0; i < 2; i++) {
        assert_int_equal(piezo_ctl_load_image(c[i], ci == CFG_EUPI_FB ? sil_eupi_img : sil_dcc_img,
                                ci == CFG_EUPI_FB ? SIL_EUPI_IMG_LEN : SIL_DCC_IMG_LEN),
                         PIEZO_TABLE_REASON_OK);
        assert_int_equal(piezo_ctl_set_mode(c[i], mode), PIEZO_OK);
    }
    both_tick(1, 0); /* the committed table becomes active at a tick boundary */
    assert_true(ctl.active >= 0);
    for (int i = 0; i < 2; i++) {
        assert_int_equal(piezo_ctl_arm(c[i], 1), PIEZO_OK);
    }
    {
        const double y0 = (double)ctl.sig[PIEZO_SIG_Y], y1 = (double)SIL_REF_OFFSET_Q15;
        for (uint32_t k = 0; k < RAMP_TICKS; k++) {
            double a = 0.5 - 0.5 * cos(3.14159265358979323846 * (double)(k + 1u) / RAMP_TICKS);
            double s = floor(y0 + (y1 - y0) * a + 0.5);
            for (int i = 0; i < 2; i++) {
                c[i]->setpoint_q15 = (int16_t)(s < -32768.0 ? -32768.0 : (s > 32767.0 ? 32767.0 : s));
            }
            both_tick(1, k + 1u);
        }
    }
    for (int i = 0; i < 2; i++) {
        memset(&c[i]->wave_cfg, 0, sizeof c[i]->wave_cfg);
        c[i]->wave_cfg.kind = PIEZO_WAVE_TRIANGLE;
        c[i]->wave_cfg.offset_q15 = SIL_REF_OFFSET_Q15;
        c[i]->wave_cfg.amplitude_q15 = SIL_REF_AMPLITUDE_Q15;
        c[i]->wave_cfg.freq_word = (uint32_t)llround(f / 10000.0 * 4294967296.0);
        assert_int_equal(piezo_ctl_start_wave(c[i]), PIEZO_OK);
    }
    for (uint32_t k = 0; k < n_settle + n_meas; k++) {
        both_tick(1, RAMP_TICKS + 1u + k);
        if (k >= n_settle) {
            double e = piezo_scale_q15_to_um(&sc, ctl.sig[PIEZO_SIG_REF]) - stage_true_um(&stage, 0);
            se += e * e;
        }
    }
    assert_true(fabs(stage_true_um(&stage, 0) - stage_true_um(&sil.stage, 0)) == 0.0);
    assert_true(ctl.st.armed);
    assert_int_equal(ctl.st.faults, 0);
    /* two lists per tick, nothing else */
    assert_int_equal(fake_comedi_stats()->insnlists, 1u + 2u * (1u + RAMP_TICKS + n_settle + n_meas));
    assert_int_equal(fake_comedi_stats()->steps, 1u + 1u + RAMP_TICKS + n_settle + n_meas);
    assert_int_equal(fake_comedi_stats()->data_writes + fake_comedi_stats()->data_reads, 0);
    piezo_daq_close(&daq);
    no_violation();
    return sqrt(se / n_meas);
}

static void tracking_at(double f, double target)
{
    double rms[CFG_N];
    load_params();
    for (int ci = 0; ci < CFG_N; ci++) {
        rms[ci] = run_1716(ci, f);
    }
    printf("DAQ path (pci-1716 fake, default stage), %.0f Hz triangle, RMS error vs true displacement:\n", f);
    for (int ci = 0; ci < CFG_N; ci++) {
        printf("  %-8s %.4f um  %5.1fx\n", cfg_name[ci], rms[ci], rms[CFG_NONE] / rms[ci]);
    }
    for (int ci = 1; ci < CFG_N; ci++) {
        if (!(rms[CFG_NONE] / rms[ci] >= target)) {
            fail_msg("%s at %.0f Hz: %.4f um against %.4f um uncompensated, %.2fx < %.0fx", cfg_name[ci], f, rms[ci],
                     rms[CFG_NONE], rms[CFG_NONE] / rms[ci], target);
        }
    }
}

static void test_tracking_10hz_same_as_sil(void **state)
{
    (void)state;
    tracking_at(10.0, 5.0);
}

static void test_tracking_1hz_same_as_sil(void **state)
{
    (void)state;
    tracking_at(1.0, 10.0);
}

/* PCI-6221: FEEDBACK to a setpoint; mean sensor output (before the stage's
 * own ADC) against the setpoint [um]. */
static double hold_6221(int calibrated, double setpoint_um, double *predicted_um)
{
    static const fake_wire_t w = {1, 0, 0, 3, 10.0, 1.2};
    const double g_in = 0.004, o_in = 0.003;
    fake_board_t b = fake_board_pci6221();
    piezo_scale_t sc;
    double sum = 0.0, v_set;
    const uint32_t n_settle = 5000u, n_meas = 2000u;
    b.sub[0].gain_error = g_in;
    b.sub[0].offset_v = o_in;
    b.sub[1].gain_error = -0.0025;
    b.sub[1].offset_v = -0.002;
    /* +-10 V output: twice the SIL's drive volts per q15; half the PI gains keep the loop gain */
    sc = bring_up("device = /dev/comedi0\nflash = unused\n[axis 0]\nao.channel = 0\nao.range = 0\n"
                  "ai.channel = 3\nai.range = 0\nai.aref = diff\namplifier.gain = 15\n"
                  "sensor.um_per_v = 1.2\nsensor.offset_um = 10\n",
                  &b, calibrated ? "/usr/var/lib/comedi/calibrations/ni_pcimio_pci-6221_comedi0" : NULL, &w, 2,
                  NULL);
    assert_int_equal(daq.ai[0].conv, calibrated ? PIEZO_DAQ_CONV_SOFTCAL : PIEZO_DAQ_CONV_IDEAL);
    assert_int_equal(daq.ao[0].conv, calibrated ? PIEZO_DAQ_CONV_SOFTCAL : PIEZO_DAQ_CONV_IDEAL);
    assert_int_equal(piezo_ctl_set_mode(&ctl, PIEZO_MODE_FEEDBACK), PIEZO_OK);
    ctl.setpoint_q15 = piezo_scale_um_to_q15(&sc, setpoint_um);
    assert_int_equal(piezo_ctl_arm(&ctl, 1), PIEZO_OK);
    for (uint32_t k = 0; k < n_settle + n_meas; k++) {
        assert_int_equal(piezo_daq_loop_tick(&loop), 0);
        if (!ctl.st.armed) {
            fail_msg("%s, setpoint %.2f um: disarmed at tick %u (faults 0x%x, sensor code %d, drive code %d)",
                     calibrated ? "calibrated" : "uncalibrated", setpoint_um, k, (unsigned)ctl.st.faults,
                     loop.adc[0], loop.dac[0]);
        }
        if (k >= n_settle) {
            sum += stage_sensor_um(&stage, 0);
        }
    }
    assert_true(ctl.st.armed);
    assert_int_equal(ctl.st.faults, 0);
    /* uncalibrated, the loop puts the input's reading v (1 + g) + o on the setpoint */
    v_set = (piezo_scale_q15_to_um(&sc, ctl.setpoint_q15) - 10.0) / 1.2;
    *predicted_um = calibrated ? 0.0 : 1.2 * ((v_set - o_in) / (1.0 + g_in) - v_set);
    piezo_daq_close(&daq);
    no_violation();
    return sum / n_meas - piezo_scale_q15_to_um(&sc, ctl.setpoint_q15);
}

static void test_calibration_in_the_loop(void **state)
{
    /* bound: one step of the board's input (1.2 um * 20 V / 65535) and one
     * of the stage's ADC (24 um / 65536) */
    const double bound = 1.2 * 20.0 / 65535.0 + 24.0 / 65536.0;
    (void)state;
    load_params();
    for (int sp = 0; sp < 3; sp++) {
        const double setpoint = sp == 0 ? 3.0 : (sp == 1 ? 12.0 : 16.0);
        double pred[2], e[2];
        for (int cal = 0; cal < 2; cal++) {
            e[cal] = hold_6221(cal, setpoint, &pred[cal]);
        }
        printf("pci-6221 fake, FEEDBACK at %4.1f um: sensor - setpoint %+.4f um uncalibrated (predicted %+.4f), "
               "%+.4f um calibrated\n",
               setpoint, e[0], pred[0], e[1]);
        assert_true(fabs(pred[0]) > 4.0 * bound); /* the converter error is visible at all */
        if (!(fabs(e[0] - pred[0]) <= bound) || !(fabs(e[1]) <= bound)) {
            fail_msg("at %.1f um: uncalibrated %.5f um (predicted %.5f), calibrated %.5f um, bound %.5f um", setpoint,
                     e[0], pred[0], e[1], bound);
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_tracking_10hz_same_as_sil),
        cmocka_unit_test(test_tracking_1hz_same_as_sil),
        cmocka_unit_test(test_calibration_in_the_loop),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
