/* The DAQ target's comedi I/O (daq_io.h) against the fake comedilib
 * (fake_comedi.h; the conversion functions are the real library's):
 * a missing device, configurations the board cannot do, the calls a tick
 * makes, conversion round trips through the boards' ranges with and without
 * calibration, and what an I/O error does. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daq_io.h"
#include "fake_comedi.h"
#include "piezo_err.h"
#include "piezo_test.h"

static piezo_daq_t daq;
static piezo_daq_config_t cfg;
static char err[1024];

#define CFG_6221                                                                                            \
    "device = /dev/comedi0\nflash = /tmp/unused.flash\n"                                                   \
    "[axis 0]\nao.channel = 0\nao.range = 0\nai.channel = 3\nai.range = 0\nai.aref = diff\n"              \
    "amplifier.gain = 15\nsensor.um_per_v = 1.2\nsensor.offset_um = 10\n"                                  \
    "[axis 1]\nao.subdevice = 1\nao.channel = 1\nao.range = 0\nai.subdevice = 0\nai.channel = 5\n"         \
    "ai.range = 1\nai.aref = common\namplifier.gain = 15\nsensor.um_per_v = 1.2\nsensor.offset_um = 10\n"

static void parse(const char *text)
{
    if (piezo_daq_config_parse(text, "test.cfg", &cfg, err, sizeof err) != 0) {
        fail_msg("%s", err);
    }
}

static void no_violation(void)
{
    const char *v = fake_comedi_violation();
    if (v != NULL) {
        fail_msg("fake comedi: %s", v);
    }
}

static void open_6221(const char *cal_path, int omit, double ai_gain_err, double ai_off, double ao_gain_err,
                      double ao_off)
{
    fake_board_t b = fake_board_pci6221();
    b.sub[0].gain_error = ai_gain_err;
    b.sub[0].offset_v = ai_off;
    b.sub[1].gain_error = ao_gain_err;
    b.sub[1].offset_v = ao_off;
    fake_comedi_reset();
    fake_comedi_set_board("/dev/comedi0", &b);
    fake_comedi_set_calibration(cal_path, omit);
    if (piezo_daq_open(&daq, &cfg, err, sizeof err) != 0) {
        fail_msg("%s", err);
    }
}

static void test_missing_device_is_a_clear_error(void **state)
{
    int32_t codes[2] = {0, 0};
    (void)state;
    parse(CFG_6221);
    fake_comedi_reset(); /* no board anywhere */
    assert_int_equal(piezo_daq_open(&daq, &cfg, err, sizeof err), -1);
    assert_string_equal(err, "cannot open comedi device /dev/comedi0: No such file or directory (is the board's "
                             "driver loaded and attached with comedi_config?)");
    assert_null(daq.dev);
    /* nothing else reaches the library, and the I/O calls refuse without crashing */
    assert_int_equal(piezo_daq_read(&daq, codes), -1);
    assert_int_equal(piezo_daq_write(&daq, codes), -1);
    assert_int_equal(piezo_daq_write_safe(&daq), -1);
    piezo_daq_close(&daq);
    assert_int_equal(fake_comedi_stats()->opens, 1);
    assert_int_equal(fake_comedi_stats()->closes, 0);
    assert_int_equal(fake_comedi_stats()->insnlists, 0);
    no_violation();
}

/* A configuration the board cannot do: the message, and the device closed. */
static void expect_open_error(const char *text, const char *want)
{
    fake_board_t b = fake_board_pci6221();
    parse(text);
    fake_comedi_reset();
    fake_comedi_set_board("/dev/comedi0", &b);
    assert_int_equal(piezo_daq_open(&daq, &cfg, err, sizeof err), -1);
    if (strcmp(err, want) != 0) {
        fail_msg("got \"%s\", want \"%s\"", err, want);
    }
    assert_null(daq.dev);
    assert_int_equal(fake_comedi_stats()->opens, 1);
    assert_int_equal(fake_comedi_stats()->closes, 1);
    assert_int_equal(fake_comedi_stats()->insnlists, 0);
    no_violation();
}

#define AXIS0(ao, ai)                                                                                       \
    "device = /dev/comedi0\nflash = f\ncalibration = none\n[axis 0]\n" ao ai                               \
    "amplifier.gain = 15\nsensor.um_per_v = 1.2\n"
#define AO_OK "ao.channel = 0\nao.range = 0\n"
#define AI_OK "ai.channel = 0\nai.range = 0\n"

static void test_configurations_the_board_cannot_do(void **state)
{
    (void)state;
    expect_open_error(AXIS0("ao.channel = 2\nao.range = 0\n", AI_OK),
                      "/dev/comedi0: axis 0 ao: channel 2, subdevice 1 has 2 channels");
    expect_open_error(AXIS0("ao.channel = 0\nao.range = 1\n", AI_OK),
                      "/dev/comedi0: axis 0 ao: range 1, channel 0 of subdevice 1 has 1 ranges");
    expect_open_error(AXIS0(AO_OK "ao.aref = diff\n", AI_OK),
                      "/dev/comedi0: axis 0 ao: subdevice 1 does not support aref diff");
    expect_open_error(AXIS0(AO_OK, "ai.subdevice = 2\n" AI_OK),
                      "/dev/comedi0: axis 0 ai: subdevice 2 is not an analog input (type 5)");
    expect_open_error(AXIS0(AO_OK, "ai.subdevice = 9\n" AI_OK),
                      "/dev/comedi0: axis 0 ai: no subdevice 9 (the device has 3)");
    expect_open_error(AXIS0(AO_OK, "ai.channel = 0\nai.range = 4\n"),
                      "/dev/comedi0: axis 0 ai: range 4, channel 0 of subdevice 0 has 4 ranges");
    expect_open_error("device = /dev/comedi0\nflash = f\n[axis 0]\n" AO_OK AI_OK
                      "amplifier.gain = 1\nsensor.um_per_v = 1\n[axis 1]\n" AO_OK AI_OK
                      "amplifier.gain = 1\nsensor.um_per_v = 1\n",
                      "/dev/comedi0: axes 0 and 1 drive the same output (subdevice 1 channel 0)");
    /* an explicit calibration file that is not there */
    expect_open_error("device = /dev/comedi0\nflash = f\ncalibration = /nonexistent/cal\n[axis 0]\n" AO_OK AI_OK
                      "amplifier.gain = 1\nsensor.um_per_v = 1\n",
                      "/nonexistent/cal: cannot read the calibration file: No such file or directory");
}

static void test_a_tick_is_two_instruction_lists_on_the_configured_channels(void **state)
{
    int32_t in[2], out[2] = {1000, 64000};
    piezo_ctl_cfg_t cc;
    piezo_scale_t sc;
    (void)state;
    parse(CFG_6221);
    open_6221(NULL, -1, 0.0, 0.0, 0.0, 0.0);
    fake_comedi_expect_io(1, 0, 0, AREF_GROUND);
    fake_comedi_expect_io(1, 1, 0, AREF_GROUND);
    fake_comedi_expect_io(0, 3, 0, AREF_DIFF);
    fake_comedi_expect_io(0, 5, 1, AREF_COMMON);
    assert_int_equal(daq.ao[0].subdevice, 1); /* auto: the first analog output */
    assert_int_equal(daq.ai[0].subdevice, 0);
    for (int i = 0; i < 2; i++) {
        assert_int_equal(piezo_daq_ctl_config(&daq, &cfg, i, &cc, &sc), PIEZO_OK);
    }
    assert_int_equal(piezo_daq_write_safe(&daq), 0);
    assert_int_equal(fake_comedi_output_raw(1, 0), 32768); /* 0 V drive: q15 0 on a +-10 V output */
    assert_int_equal(fake_comedi_output_raw(1, 1), 32768);
    fake_comedi_set_input_volts(0, 3, 2.5);
    fake_comedi_set_input_volts(0, 5, -1.25);
    assert_int_equal(piezo_daq_read(&daq, in), 0);
    assert_int_equal(piezo_daq_write(&daq, out), 0);
    assert_int_equal(fake_comedi_stats()->insnlists, 3);
    assert_int_equal(fake_comedi_stats()->insns, 6);
    assert_int_equal(fake_comedi_stats()->data_reads, 0);
    assert_int_equal(fake_comedi_stats()->data_writes, 0);
    assert_int_equal(fake_comedi_last_chanspec(0, 3), CR_PACK(3, 0, AREF_DIFF));
    assert_int_equal(fake_comedi_last_chanspec(0, 5), CR_PACK(5, 1, AREF_COMMON));
    assert_int_equal(fake_comedi_last_chanspec(1, 1), CR_PACK(1, 0, AREF_GROUND));
    /* 16-bit board, ideal conversion: the codes are the raw samples */
    assert_int_equal(in[0], 40959);                        /* 2.5 V of +-10 V: 0.625 * 65535 rounded */
    assert_int_equal(in[1], 24576);                        /* -1.25 V of +-5 V: 0.375 * 65535 rounded */
    assert_int_equal(fake_comedi_output_raw(1, 0), 1000);
    assert_int_equal(fake_comedi_output_raw(1, 1), 64000);
    no_violation();
    /* after close nothing reaches the library */
    piezo_daq_close(&daq);
    assert_int_equal(fake_comedi_stats()->closes, 1);
    assert_int_equal(piezo_daq_read(&daq, in), -1);
    assert_int_equal(piezo_daq_write(&daq, out), -1);
    assert_int_equal(piezo_daq_write_safe(&daq), -1);
    assert_int_equal(fake_comedi_stats()->insnlists, 3);
    no_violation();
}

static void test_the_fake_catches_a_wrong_channel(void **state)
{
    int32_t in[2];
    (void)state;
    parse(CFG_6221);
    open_6221(NULL, -1, 0.0, 0.0, 0.0, 0.0);
    fake_comedi_expect_io(1, 0, 0, AREF_GROUND);
    fake_comedi_expect_io(1, 1, 0, AREF_GROUND);
    fake_comedi_expect_io(0, 3, 0, AREF_DIFF);
    fake_comedi_expect_io(0, 5, 0, AREF_COMMON); /* the code uses range 1: must be caught */
    assert_int_equal(piezo_daq_read(&daq, in), -1);
    assert_non_null(fake_comedi_violation());
    assert_string_equal(fake_comedi_violation(),
                        "comedi_do_insnlist: unexpected channel: subdevice 0 channel 5 range 1 aref 1");
    piezo_daq_close(&daq);
}

static void test_round_trips_through_the_ranges(void **state)
{
    static const char *const boards[2] = {"6221", "1716"};
    (void)state;
    for (int bi = 0; bi < 2; bi++) {
        fake_board_t b = bi == 0 ? fake_board_pci6221() : fake_board_pci1716();
        /* 6221: +-10 V out, +-0.2 V in; 1716: 0..5 V out, 0..2.5 V in */
        parse(bi == 0 ? AXIS0("ao.channel = 1\nao.range = 0\n", "ai.channel = 7\nai.range = 3\n")
                      : AXIS0("ao.channel = 1\nao.range = 0\n", "ai.channel = 7\nai.range = 7\n"));
        fake_comedi_reset();
        fake_comedi_set_board("/dev/comedi0", &b);
        assert_int_equal(piezo_daq_open(&daq, &cfg, err, sizeof err), 0);
        assert_int_equal(daq.ao[0].conv, bi == 0 ? PIEZO_DAQ_CONV_IDEAL : PIEZO_DAQ_CONV_HARDCAL);
        for (int32_t c = 0; c <= PIEZO_DAQ_CODE_MAX; c++) {
            lsampl_t raw = piezo_daq_ao_raw(&daq.ao[0], c);
            if (raw != (lsampl_t)c || piezo_daq_ai_code(&daq.ai[0], (lsampl_t)c) != c) {
                fail_msg("pci-%s: code %d -> raw %u -> code %d", boards[bi], c, raw,
                         piezo_daq_ai_code(&daq.ai[0], (lsampl_t)c));
            }
        }
        /* codes beyond the scale clamp */
        assert_int_equal(piezo_daq_ao_raw(&daq.ao[0], -5), 0);
        assert_int_equal(piezo_daq_ao_raw(&daq.ao[0], 70000), 65535);
        /* through the board: the volts of a code come out of the output */
        for (int32_t c = 0; c <= PIEZO_DAQ_CODE_MAX; c += 4369) {
            int32_t out[1] = {c};
            assert_int_equal(piezo_daq_write(&daq, out), 0);
            assert_true(fabs(fake_comedi_output_volts(1, 1) - piezo_daq_code_volts(&daq.ao[0], c)) < 1e-9);
        }
        piezo_daq_close(&daq);
        no_violation();
    }
}

static void test_a_12_bit_board(void **state)
{
    fake_board_t b = fake_board_pci1716();
    (void)state;
    b.sub[0].maxdata = 4095;
    b.sub[1].maxdata = 4095;
    parse(AXIS0("ao.channel = 0\nao.range = 1\n", "ai.channel = 0\nai.range = 5\n"));
    fake_comedi_reset();
    fake_comedi_set_board("/dev/comedi0", &b);
    assert_int_equal(piezo_daq_open(&daq, &cfg, err, sizeof err), 0);
    for (int32_t c = 0; c <= PIEZO_DAQ_CODE_MAX; c++) {
        lsampl_t raw = piezo_daq_ao_raw(&daq.ao[0], c);
        int32_t back = piezo_daq_ai_code(&daq.ai[0], raw);
        /* one raw step is 65535 / 4095 = 16.004 codes: back within half a step */
        if (raw > 4095u || abs(back - c) > 8) {
            fail_msg("code %d -> raw %u -> code %d", c, raw, back);
        }
    }
    for (lsampl_t r = 1; r < 4095u; r++) {
        assert_int_equal(piezo_daq_ao_raw(&daq.ao[0], piezo_daq_ai_code(&daq.ai[0], r)), r);
    }
    piezo_daq_close(&daq);
    no_violation();
}

/* Input and output accuracy against the board's converter errors: exact up
 * to quantization with the calibration file, the errors themselves without. */
static void test_calibration_undoes_the_converter_errors(void **state)
{
    const double g_in = 0.004, o_in = 0.003, g_out = -0.0025, o_out = -0.002;
    const double lsb = 20.0 / 65535.0;
    (void)state;
    for (int cal = 0; cal < 2; cal++) {
        parse(CFG_6221);
        open_6221(cal ? "/usr/var/lib/comedi/calibrations/ni_pcimio_pci-6221_comedi0" : NULL, -1, g_in, o_in,
                  g_out, o_out);
        assert_int_equal(daq.ai[0].conv, cal ? PIEZO_DAQ_CONV_SOFTCAL : PIEZO_DAQ_CONV_IDEAL);
        assert_int_equal(daq.ao[1].conv, cal ? PIEZO_DAQ_CONV_SOFTCAL : PIEZO_DAQ_CONV_IDEAL);
        assert_int_equal(fake_comedi_stats()->calibrations_parsed, (unsigned long)cal);
        assert_int_equal(fake_comedi_stats()->calibrations_freed, (unsigned long)cal);
        if (cal) {
            assert_string_equal(daq.notes, "");
        } else {
            assert_non_null(strstr(daq.notes, "axis 0 ao: subdevice 1 is calibrated in software but no calibration "
                                              "file was found"));
        }
        for (double v = -9.0; v <= 9.0; v += 0.75) {
            int32_t in[2], out[2];
            double got_in, got_out, want_in, want_out;
            fake_comedi_set_input_volts(0, 3, v);
            assert_int_equal(piezo_daq_read(&daq, in), 0);
            got_in = piezo_daq_code_volts(&daq.ai[0], in[0]);
            out[0] = (int32_t)floor((v + 10.0) / 20.0 * 65535.0 + 0.5);
            out[1] = out[0];
            assert_int_equal(piezo_daq_write(&daq, out), 0);
            got_out = fake_comedi_output_volts(1, 0);
            want_in = cal ? v : v * (1.0 + g_in) + o_in;
            want_out = piezo_daq_code_volts(&daq.ao[0], out[0]);
            if (!cal) {
                want_out = want_out * (1.0 + g_out) + o_out;
            }
            /* two roundings (the board's and the conversion to a code) on the
             * input, one on the output (the raw sample) */
            if (fabs(got_in - want_in) > lsb * (cal ? 1.0 + 1e-6 : 0.5 + 1e-6) ||
                fabs(got_out - want_out) > lsb * 0.5 * (1.0 + fabs(g_out)) + 1e-12) {
                fail_msg("%s at %.3f V: input %.6f V (want %.6f), output %.6f V (want %.6f)",
                         cal ? "calibrated" : "uncalibrated", v, got_in, want_in, got_out, want_out);
            }
        }
        piezo_daq_close(&daq);
        no_violation();
    }
}

static void test_calibration_lacking_a_subdevice(void **state)
{
    (void)state;
    /* auto: that channel is uncalibrated, with a note */
    parse(CFG_6221);
    open_6221("/cal/6221", 1, 0.0, 0.0, 0.0, 0.0);
    assert_int_equal(daq.ai[0].conv, PIEZO_DAQ_CONV_SOFTCAL);
    assert_int_equal(daq.ao[0].conv, PIEZO_DAQ_CONV_IDEAL);
    assert_non_null(strstr(daq.notes, "axis 0 ao: subdevice 1 is calibrated in software but the calibration file "
                                      "lacks this channel/range"));
    piezo_daq_close(&daq);
    /* an explicit file must cover every channel */
    parse("device = /dev/comedi0\nflash = f\ncalibration = /cal/6221\n[axis 0]\n" AO_OK AI_OK
          "amplifier.gain = 1\nsensor.um_per_v = 1\n");
    {
        fake_board_t b = fake_board_pci6221();
        fake_comedi_reset();
        fake_comedi_set_board("/dev/comedi0", &b);
        fake_comedi_set_calibration("/cal/6221", 1);
        assert_int_equal(piezo_daq_open(&daq, &cfg, err, sizeof err), -1);
        assert_string_equal(err, "/cal/6221: axis 0 ao: no calibration of subdevice 1 channel 0 range 0");
        assert_int_equal(fake_comedi_stats()->calibrations_freed, 1);
        assert_int_equal(fake_comedi_stats()->closes, 1);
    }
    /* calibration = none ignores a file that is there */
    parse(AXIS0(AO_OK, AI_OK));
    open_6221("/cal/6221", -1, 0.0, 0.0, 0.0, 0.0);
    assert_int_equal(daq.ao[0].conv, PIEZO_DAQ_CONV_IDEAL);
    assert_int_equal(fake_comedi_stats()->calibrations_parsed, 0);
    piezo_daq_close(&daq);
    no_violation();
}

static void test_scale_and_safe_code(void **state)
{
    piezo_ctl_cfg_t cc;
    piezo_scale_t sc;
    (void)state;
    parse("device = /dev/comedi0\nflash = f\n[axis 0]\n" AO_OK AI_OK
          "amplifier.gain = 15\namplifier.offset_v = 1\nsensor.um_per_v = 1.2\nsensor.offset_um = 10\n"
          "drive.safe_v = 30\ndrive.min_v = -20\ndrive.max_v = 120\n");
    open_6221(NULL, -1, 0.0, 0.0, 0.0, 0.0);
    assert_int_equal(piezo_daq_ctl_config(&daq, &cfg, 0, &cc, &sc), PIEZO_OK);
    assert_true(fabs(sc.drive_min_v - (-149.0)) < 1e-9);
    assert_true(fabs(sc.drive_max_v - (1.0 + 15.0 * (-10.0 + 20.0 * 65536.0 / 65535.0))) < 1e-9);
    assert_true(fabs(sc.position_min_um - (-2.0)) < 1e-12);
    assert_true(fabs(sc.position_max_um - (10.0 + 1.2 * (-10.0 + 20.0 * 65536.0 / 65535.0))) < 1e-9);
    assert_int_equal(cc.u_safe_q15, piezo_scale_volts_to_q15(&sc, 30.0));
    assert_int_equal(daq.safe_code[0], 32768 + cc.u_safe_q15);
    assert_int_equal(cc.limit.min_q15, piezo_scale_volts_to_q15(&sc, -20.0));
    assert_int_equal(cc.limit.max_q15, piezo_scale_volts_to_q15(&sc, 120.0));
    /* the safe drive through the board: 30 V within one output step (20 V / 65535 * 15) */
    assert_int_equal(piezo_daq_write_safe(&daq), 0);
    assert_true(fabs(15.0 * fake_comedi_output_volts(1, 0) + 1.0 - 30.0) <= 15.0 * 20.0 / 65535.0);
    /* an inverting amplifier swaps the clamp's ends */
    cfg.axis[0].amp_gain = -15.0;
    assert_int_equal(piezo_daq_ctl_config(&daq, &cfg, 0, &cc, &sc), PIEZO_OK);
    assert_true(sc.drive_min_v > sc.drive_max_v);
    assert_int_equal(cc.limit.min_q15, piezo_scale_volts_to_q15(&sc, 120.0));
    assert_int_equal(cc.limit.max_q15, piezo_scale_volts_to_q15(&sc, -20.0));
    assert_true(cc.limit.min_q15 < cc.limit.max_q15);
    /* a safe drive the output range cannot reach */
    cfg.axis[0].amp_gain = 15.0;
    cfg.axis[0].has_drive_min = 0;
    cfg.axis[0].has_drive_max = 0;
    cfg.axis[0].safe_v = 400.0;
    assert_int_equal(piezo_daq_ctl_config(&daq, &cfg, 0, &cc, &sc), PIEZO_OK); /* clamps to the top */
    assert_int_equal(cc.u_safe_q15, 32767);
    cfg.axis[0].has_drive_max = 1;
    cfg.axis[0].drive_max_v = 100.0;
    assert_int_equal(piezo_daq_ctl_config(&daq, &cfg, 0, &cc, &sc), PIEZO_ERANGE);
    piezo_daq_close(&daq);
    no_violation();
}

static void test_io_errors_leave_the_safe_drive(void **state)
{
    static piezo_ctl_t ctl[2];
    piezo_ctl_cfg_t cc;
    piezo_scale_t sc;
    piezo_daq_loop_t loop;
    (void)state;
    parse(CFG_6221);
    open_6221(NULL, -1, 0.0, 0.0, 0.0, 0.0);
    memset(&loop, 0, sizeof loop);
    loop.daq = &daq;
    for (int i = 0; i < 2; i++) {
        assert_int_equal(piezo_daq_ctl_config(&daq, &cfg, i, &cc, &sc), PIEZO_OK);
        assert_int_equal(piezo_ctl_init(&ctl[i], &cc), PIEZO_OK);
        loop.ctl[i] = &ctl[i];
        ctl[i].setpoint_q15 = 12000;
        assert_int_equal(piezo_ctl_set_mode(&ctl[i], PIEZO_MODE_OPEN_LOOP), PIEZO_OK);
        assert_int_equal(piezo_ctl_arm(&ctl[i], 1), PIEZO_OK);
    }
    fake_comedi_set_input_volts(0, 3, 0.5);
    fake_comedi_set_input_volts(0, 5, 0.5);
    assert_int_equal(piezo_daq_write_safe(&daq), 0);
    for (int k = 0; k < 5; k++) {
        assert_int_equal(piezo_daq_loop_tick(&loop), 0);
    }
    assert_int_equal(fake_comedi_output_raw(1, 0), 32768 + 12000); /* open loop, no table: u = r */
    /* the write list fails once: the safe drive goes out with the next list */
    fake_comedi_fail_insnlist(2, 1, 0);
    assert_int_equal(piezo_daq_loop_tick(&loop), -1);
    assert_int_equal(fake_comedi_output_raw(1, 0), 32768);
    assert_int_equal(fake_comedi_output_raw(1, 1), 32768);
    assert_int_equal(daq.io_errors, 1);
    /* the read fails: the drive is made safe before anything else */
    assert_int_equal(piezo_daq_loop_tick(&loop), 0);
    assert_int_equal(fake_comedi_output_raw(1, 0), 32768 + 12000);
    fake_comedi_fail_insnlist(1, 1, 0);
    assert_int_equal(piezo_daq_loop_tick(&loop), -1);
    assert_int_equal(fake_comedi_output_raw(1, 0), 32768);
    /* lists keep failing: channel by channel with comedi_data_write */
    assert_int_equal(piezo_daq_loop_tick(&loop), 0);
    fake_comedi_fail_insnlist(1, 1000, 0);
    assert_int_equal(piezo_daq_loop_tick(&loop), -1);
    assert_int_equal(fake_comedi_stats()->data_writes, 2);
    assert_int_equal(fake_comedi_output_raw(1, 0), 32768);
    assert_int_equal(fake_comedi_output_raw(1, 1), 32768);
    /* nothing gets through: reported, no crash */
    fake_comedi_fail_insnlist(1, 1000, 1);
    assert_int_equal(piezo_daq_write_safe(&daq), -1);
    piezo_daq_close(&daq);
    no_violation();
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_missing_device_is_a_clear_error),
        cmocka_unit_test(test_configurations_the_board_cannot_do),
        cmocka_unit_test(test_a_tick_is_two_instruction_lists_on_the_configured_channels),
        cmocka_unit_test(test_the_fake_catches_a_wrong_channel),
        cmocka_unit_test(test_round_trips_through_the_ranges),
        cmocka_unit_test(test_a_12_bit_board),
        cmocka_unit_test(test_calibration_undoes_the_converter_errors),
        cmocka_unit_test(test_calibration_lacking_a_subdevice),
        cmocka_unit_test(test_scale_and_safe_code),
        cmocka_unit_test(test_io_errors_leave_the_safe_drive),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
