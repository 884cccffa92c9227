/* The DAQ target's configuration file (daq_config.h): a full file, defaults,
 * and every kind of error with its file name and line. */
#include <comedi.h>
#include <stdio.h>
#include <string.h>

#include "daq_config.h"
#include "piezo_test.h"

#define GOOD                                                                                                \
    "# two-axis stage on a PCI-6221\n"                                                                      \
    "device = /dev/comedi0\n"                                                                               \
    "flash = /var/lib/piezoctl/stage.flash   # tables\n"                                                    \
    "calibration = /etc/comedi/cal#1.txt\n"                                                                 \
    "tick_hz = 5000\n"                                                                                      \
    "priority = 0\n"                                                                                        \
    "\n"                                                                                                    \
    "[axis 0]\n"                                                                                            \
    "ao.subdevice = 1\n"                                                                                    \
    "ao.channel = 0\n"                                                                                      \
    "ao.range = 0\n"                                                                                        \
    "  ai.channel = 3\n"                                                                                    \
    "ai.range = 1\n"                                                                                        \
    "ai.aref = diff\n"                                                                                      \
    "amplifier.gain = 15\n"                                                                                 \
    "amplifier.offset_v = -0.5\n"                                                                           \
    "sensor.um_per_v = 1.2\n"                                                                               \
    "sensor.offset_um = 10\n"                                                                               \
    "drive.min_v = -20\n"                                                                                   \
    "drive.max_v = 150\n"                                                                                   \
    "[ axis 1 ]\n"                                                                                          \
    "ao.channel = 1\n"                                                                                      \
    "ao.range = 0\n"                                                                                        \
    "ai.subdevice = auto\n"                                                                                 \
    "ai.channel = 4\n"                                                                                      \
    "ai.range = 0\n"                                                                                        \
    "ai.aref = other\n"                                                                                     \
    "amplifier.gain = -7.5\n"                                                                               \
    "sensor.um_per_v = 2e0\n"                                                                               \
    "drive.safe_v = 1.5\n"

static piezo_daq_config_t cfg;
static char err[512];

static void test_a_full_file(void **state)
{
    (void)state;
    assert_int_equal(piezo_daq_config_parse(GOOD, "good.cfg", &cfg, err, sizeof err), 0);
    assert_string_equal(cfg.device, "/dev/comedi0");
    assert_string_equal(cfg.flash, "/var/lib/piezoctl/stage.flash");
    assert_int_equal(cfg.calibration, PIEZO_DAQ_CAL_FILE);
    assert_string_equal(cfg.calibration_path, "/etc/comedi/cal#1.txt"); /* '#' inside a value stays */
    assert_int_equal(cfg.tick_hz, 5000);
    assert_int_equal(cfg.priority, 0);
    assert_int_equal(cfg.n_axes, 2);
    assert_int_equal(cfg.axis[0].ao.subdevice, 1);
    assert_int_equal(cfg.axis[0].ai.subdevice, -1);
    assert_int_equal(cfg.axis[0].ai.channel, 3);
    assert_int_equal(cfg.axis[0].ai.range, 1);
    assert_int_equal(cfg.axis[0].ai.aref, AREF_DIFF);
    assert_int_equal(cfg.axis[0].ao.aref, AREF_GROUND);
    assert_true(cfg.axis[0].amp_gain == 15.0 && cfg.axis[0].amp_offset_v == -0.5);
    assert_true(cfg.axis[0].sensor_um_per_v == 1.2 && cfg.axis[0].sensor_offset_um == 10.0);
    assert_true(cfg.axis[0].has_drive_min && cfg.axis[0].drive_min_v == -20.0);
    assert_true(cfg.axis[0].has_drive_max && cfg.axis[0].drive_max_v == 150.0);
    assert_true(cfg.axis[0].safe_v == 0.0);
    assert_int_equal(cfg.axis[1].ao.channel, 1);
    assert_int_equal(cfg.axis[1].ai.aref, AREF_OTHER);
    assert_true(cfg.axis[1].amp_gain == -7.5 && cfg.axis[1].sensor_um_per_v == 2.0);
    assert_true(cfg.axis[1].safe_v == 1.5);
    assert_false(cfg.axis[1].has_drive_min || cfg.axis[1].has_drive_max);
}

static void test_defaults(void **state)
{
    (void)state;
    assert_int_equal(piezo_daq_config_parse("device=/dev/comedi1\nflash=f\n[axis 0]\nao.channel=0\nao.range=0\n"
                                            "ai.channel=0\nai.range=0\namplifier.gain=1\nsensor.um_per_v=1\n",
                                            "min.cfg", &cfg, err, sizeof err),
                     0);
    assert_int_equal(cfg.n_axes, 1);
    assert_int_equal(cfg.calibration, PIEZO_DAQ_CAL_AUTO);
    assert_int_equal(cfg.tick_hz, 10000);
    assert_int_equal(cfg.priority, 80);
    assert_int_equal(cfg.axis[0].ao.subdevice, -1);
    assert_int_equal(cfg.axis[0].ai.aref, AREF_GROUND);
    assert_true(cfg.axis[0].amp_offset_v == 0.0 && cfg.axis[0].sensor_offset_um == 0.0);
    assert_int_equal(piezo_daq_config_parse("device=d\nflash=f\ncalibration = none\n[axis 0]\nao.channel=0\n"
                                            "ao.range=0\nai.channel=0\nai.range=0\namplifier.gain=1\n"
                                            "sensor.um_per_v=1\n",
                                            "none.cfg", &cfg, err, sizeof err),
                     0);
    assert_int_equal(cfg.calibration, PIEZO_DAQ_CAL_NONE);
}

/* Replaces line `line` (1-based) of GOOD with `text` ("" removes it) and
 * expects the error message `want`. */
static void expect_error(int line, const char *text, const char *want)
{
    static char buf[4096];
    const char *p = GOOD;
    size_t n = 0;
    for (int k = 1; *p != '\0'; k++) {
        const char *nl = strchr(p, '\n');
        size_t len = (size_t)(nl - p) + 1u;
        if (k == line) {
            n += (size_t)snprintf(buf + n, sizeof buf - n, "%s%s", text, text[0] != '\0' ? "\n" : "");
        } else {
            memcpy(buf + n, p, len);
            n += len;
        }
        p += len;
    }
    buf[n] = '\0';
    memset(err, 0, sizeof err);
    if (piezo_daq_config_parse(buf, "stage.cfg", &cfg, err, sizeof err) == 0) {
        fail_msg("line %d = \"%s\" was accepted", line, text);
    }
    if (strcmp(err, want) != 0) {
        fail_msg("line %d = \"%s\": got \"%s\", want \"%s\"", line, text, err, want);
    }
}

static void test_errors_name_the_file_and_line(void **state)
{
    (void)state;
    expect_error(10, "ao.chanel = 0", "stage.cfg:10: unknown key 'ao.chanel'");
    expect_error(10, "ao.channel 0", "stage.cfg:10: expected \"key = value\", got \"ao.channel 0\"");
    expect_error(10, "ao.channel = -1", "stage.cfg:10: ao.channel: '-1' is not a number in 0..65535");
    expect_error(10, "ao.channel = 2x", "stage.cfg:10: ao.channel: '2x' is not a number in 0..65535");
    expect_error(10, "ao.channel = 0\nao.channel = 1", "stage.cfg:11: 'ao.channel' given twice");
    expect_error(9, "ao.subdevice = first", "stage.cfg:9: ao.subdevice: 'first' is not a subdevice number (0..255) or auto");
    expect_error(14, "ai.aref = differential", "stage.cfg:14: ai.aref: 'differential' is not one of ground, common, diff, other");
    expect_error(15, "amplifier.gain = 0", "stage.cfg:15: amplifier.gain: must not be 0");
    expect_error(15, "amplifier.gain = nan", "stage.cfg:15: amplifier.gain: 'nan' is not a number");
    expect_error(15, "amplifier.gain =", "stage.cfg:15: amplifier.gain: '' is not a number");
    expect_error(5, "tick_hz = 99", "stage.cfg:5: tick_hz: '99' is not a rate in 100..100000 Hz");
    expect_error(6, "priority = 100", "stage.cfg:6: priority: '100' is not a SCHED_FIFO priority in 0..99 (0: none)");
    expect_error(2, "device =", "stage.cfg:2: device: needs a path");
    expect_error(10, "device = /dev/comedi1", "stage.cfg:10: 'device' belongs before the first [axis N] section");
    expect_error(7, "ao.channel = 0", "stage.cfg:7: 'ao.channel' belongs in an [axis N] section");
    expect_error(8, "[axis 1]", "stage.cfg:8: [axis 1]: expected [axis 0] here (axes in order, each once)");
    expect_error(21, "[axis 2]", "stage.cfg:21: [axis 2]: axes are 0 and 1");
    expect_error(21, "[axis 0]", "stage.cfg:21: [axis 0]: expected [axis 1] here (axes in order, each once)");
    expect_error(21, "[stage]", "stage.cfg:21: unknown section [stage] (only [axis 0] and [axis 1])");
    expect_error(21, "[axis 1", "stage.cfg:21: a section is \"[axis N]\"");
    /* missing keys: reported at the section's header (or the first section for the globals) */
    expect_error(11, "", "stage.cfg:8: [axis 0]: missing key 'ao.range'");
    expect_error(29, "", "stage.cfg:21: [axis 1]: missing key 'sensor.um_per_v'");
    expect_error(2, "", "stage.cfg:7: missing key 'device'");
    expect_error(20, "drive.max_v = -30", "stage.cfg:8: [axis 0]: drive.min_v must be below drive.max_v");
    expect_error(30, "drive.safe_v = -1\ndrive.min_v = 0", "stage.cfg:21: [axis 1]: drive.safe_v -1 V outside drive.min_v..drive.max_v");
}

static void test_no_axis_and_empty(void **state)
{
    (void)state;
    assert_int_equal(piezo_daq_config_parse("device = /dev/comedi0\nflash = f\n", "g.cfg", &cfg, err, sizeof err), -1);
    assert_string_equal(err, "g.cfg:2: no [axis 0] section");
    assert_int_equal(piezo_daq_config_parse("", "e.cfg", &cfg, err, sizeof err), -1);
    assert_string_equal(err, "e.cfg: missing key 'device'");
}

static void test_files(void **state)
{
    char path[512];
    FILE *f;
    (void)state;
    assert_int_equal(piezo_daq_config_load("/nonexistent/daq.cfg", &cfg, err, sizeof err), -1);
    assert_string_equal(err, "/nonexistent/daq.cfg: cannot read: No such file or directory");
    snprintf(path, sizeof path, "%s/test_daq_config.cfg", DAQ_TMP_DIR);
    f = fopen(path, "w");
    assert_non_null(f);
    fputs(GOOD, f);
    fclose(f);
    assert_int_equal(piezo_daq_config_load(path, &cfg, err, sizeof err), 0);
    assert_int_equal(cfg.n_axes, 2);
    f = fopen(path, "w");
    assert_non_null(f);
    fputs("device = /dev/comedi0\nflash\n", f);
    fclose(f);
    assert_int_equal(piezo_daq_config_load(path, &cfg, err, sizeof err), -1);
    {
        char want[600];
        snprintf(want, sizeof want, "%s:2: expected \"key = value\", got \"flash\"", path);
        assert_string_equal(err, want);
    }
    remove(path);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_a_full_file),
        cmocka_unit_test(test_defaults),
        cmocka_unit_test(test_errors_name_the_file_and_line),
        cmocka_unit_test(test_no_axis_and_empty),
        cmocka_unit_test(test_files),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
