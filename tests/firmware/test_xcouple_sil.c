/* Cross-coupling compensation in closed loop on the two-axis SIL stage
 * (stages/two_axis.json): the controllers of both axes against the C stage
 * model, tick by tick, with the coupling table the host identified from the
 * stage model (piezoctl.golden.xcouple_sil).
 *
 * Axis 1 (index 0) holds its position; axis 2 (index 1) is driven in DIRECT
 * mode with a sine 75 +- 60 V at 1, 10 or 50 Hz. Three runs from the same
 * state and noise seed: "base" (axis 2 held at 75 V), "off" (the sine, the
 * table loaded but bypassed: xcouple_bypass = 1) and "on" (the sine, the
 * compensation applied). The coupling error is axis 1's TRUE displacement
 * minus that of the base run, RMS over whole periods after settling. Axis 1
 * runs either in FEEDFORWARD with no hysteresis table (the setpoint is its
 * drive: the compensation alone) or in FEEDBACK (PI + notch at the 140 Hz
 * mode, crossover 17.5 Hz, holding the setpoint position). The table is
 * printed; the reductions off / on in feedback at 1 and 10 Hz are asserted
 * against floors below the measured values (3.9x, 4.0x). Not asserted, and
 * why (docs/cross-coupling.md): in feedforward alone the compensating drive
 * is a small oscillation on a held axis, and the stage model's Bouc-Wen
 * hysteresis ratchets under small symmetric cycles (0.17 um/s for +-0.23 V
 * at 10 Hz), so the axis drifts by more than the coupling it removes; at
 * 50 Hz the prediction (divided by the static gain) misses the dynamics of
 * the compensation path and the error grows.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "piezo_test.h"
#include "piezo_err.h"
#include "sil_loop.h"
#include "table_image.h"
#include "xcouple_sil_vectors.h"

#define N_FREQ 3
static const double freq_hz[N_FREQ] = {1.0, 10.0, 50.0};
enum { LOOP_FF, LOOP_FB, LOOP_N };
static const char *const loop_name[LOOP_N] = {"feedforward", "feedback"};
enum { RUN_BASE, RUN_OFF, RUN_ON, RUN_N };

/* floors of the reduction (off / on) in feedback, below the measured values;
 * 0: reported, not asserted (see above) */
static const double floor_red[LOOP_N][N_FREQ] = {{0.0, 0.0, 0.0}, {3.0, 3.0, 0.0}};

#define SETTLE_TICKS 5000u   /* arming to wave start: 0.5 s */
#define LEVEL_V 75.0         /* axis 1's drive level (feedforward) */

static piezo_sil_t sil;
static stage_params params;
static double rms[LOOP_N][N_FREQ][2], ptp_coupling[LOOP_N][N_FREQ];
static int measured;

/* One run; x[] gets axis 1's true displacement over the measured ticks. */
static void run(int loop, int fi, int which, double *x, uint32_t n_meas, uint32_t n_wave_settle)
{
    piezo_scale_t sc0, sc1;
    piezo_ctl_cfg_t cfg0, cfg1;
    piezo_ctl_t *c0 = &sil.ctl[0], *c1 = &sil.ctl[1];
    const double f = freq_hz[fi];

    assert_int_equal(piezo_sil_init(&sil, &params, 4242u), PIEZO_OK);
    assert_int_equal(piezo_sil_ctl_config(&params, 0, &cfg0, &sc0), PIEZO_OK);
    assert_int_equal(piezo_sil_ctl_config(&params, 1, &cfg1, &sc1), PIEZO_OK);
    if (loop == LOOP_FB) {
        const piezo_biquad_coef_t notch = {XC_SIL_N_B0_Q24, XC_SIL_N_B1_Q24, XC_SIL_N_B2_Q24,
                                           XC_SIL_N_A1_Q24, XC_SIL_N_A2_Q24};
        /* a PI: kd stays 0, as piezo_sil_ctl_config left it */
        piezo_sil_set_feedback(&cfg0, XC_SIL_KP_Q24, XC_SIL_KI_Q24, 0, &notch);
    }
    cfg0.xcouple_bypass = (uint8_t)(which != RUN_ON);
    assert_int_equal(piezo_ctl_init(c0, &cfg0), PIEZO_OK);
    assert_int_equal(piezo_ctl_load_image(c0, xc_sil_table, XC_SIL_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    piezo_sil_tick(&sil); /* the committed coupling table becomes active here */
    assert_true(c0->xc_active >= 0 && c0->active < 0);
    assert_int_equal(piezo_ctl_coupling_crc(c0), piezo_le32(xc_sil_table + XC_SIL_TABLE_LEN - 4u));

    /* axis 1: holds 75 V of drive (feedforward) or the position it has there (feedback) */
    assert_int_equal(piezo_ctl_set_mode(c0, loop == LOOP_FB ? PIEZO_MODE_FEEDBACK : PIEZO_MODE_FEEDFORWARD), PIEZO_OK);
    c0->setpoint_q15 = piezo_scale_volts_to_q15(&sc0, LEVEL_V);
    if (loop == LOOP_FB) {
        /* the position axis 1 settles at under 75 V: from a feedforward run's level */
        c0->setpoint_q15 = (int16_t)XC_SIL_HOLD_Q15;
    }
    /* axis 2: DIRECT, its drive's offset first */
    assert_int_equal(piezo_ctl_set_mode(c1, PIEZO_MODE_DIRECT), PIEZO_OK);
    c1->setpoint_q15 = piezo_scale_volts_to_q15(&sc1, 75.0);
    assert_int_equal(piezo_ctl_arm(c0, 1), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(c1, 1), PIEZO_OK);
    for (uint32_t k = 0; k < SETTLE_TICKS; k++) {
        piezo_sil_tick(&sil);
    }
    if (which != RUN_BASE) {
        memset(&c1->wave_cfg, 0, sizeof c1->wave_cfg);
        c1->wave_cfg.kind = PIEZO_WAVE_SINE;
        c1->wave_cfg.offset_q15 = c1->setpoint_q15;
        c1->wave_cfg.amplitude_q15 = (int16_t)lround(60.0 / (sc1.drive_max_v - sc1.drive_min_v) * 65536.0);
        c1->wave_cfg.freq_word = (uint32_t)llround(f / 10000.0 * 4294967296.0);
        assert_int_equal(piezo_ctl_start_wave(c1), PIEZO_OK);
    }
    for (uint32_t k = 0; k < n_wave_settle + n_meas; k++) {
        piezo_sil_tick(&sil);
        if (k >= n_wave_settle) {
            x[k - n_wave_settle] = stage_true_um(&sil.stage, 0);
        }
    }
    assert_true(c0->st.armed && c1->st.armed);
    assert_int_equal(c0->st.faults | c1->st.faults, 0);
    if (which != RUN_ON) {
        assert_int_equal(c0->xc_q15, 0); /* bypassed: nothing applied */
    }
}

static double xbuf[RUN_N][20000];

static void measure_all(void)
{
    char err[256];
    if (measured) {
        return;
    }
    if (stage_params_load_json(STAGE_FILE, &params, err, sizeof err) != STAGE_OK) {
        fail_msg("%s", err);
    }
    for (int loop = 0; loop < LOOP_N; loop++) {
        for (int fi = 0; fi < N_FREQ; fi++) {
            const uint32_t period = (uint32_t)lround(10000.0 / freq_hz[fi]);
            const uint32_t n_meas = period * (fi == 0 ? 2u : (fi == 1 ? 10u : 25u));
            const uint32_t n_settle = period > 2000u ? period : 2000u;
            double lo = 1e9, hi = -1e9;
            for (int w = 0; w < RUN_N; w++) {
                run(loop, fi, w, xbuf[w], n_meas, n_settle);
            }
            for (int w = RUN_OFF; w <= RUN_ON; w++) {
                double se = 0.0;
                for (uint32_t k = 0; k < n_meas; k++) {
                    double e = xbuf[w][k] - xbuf[RUN_BASE][k];
                    se += e * e;
                    if (w == RUN_OFF) {
                        lo = e < lo ? e : lo;
                        hi = e > hi ? e : hi;
                    }
                }
                rms[loop][fi][w - RUN_OFF] = sqrt(se / n_meas);
            }
            ptp_coupling[loop][fi] = hi - lo;
        }
    }
    measured = 1;
    printf("cross-coupling from axis 2 (75 +- 60 V sine) into axis 1, two-axis stage, RMS [nm]:\n");
    printf("%-12s %6s %12s %10s %10s %9s\n", "axis 1", "f[Hz]", "coupling p-p", "off", "on", "reduction");
    for (int loop = 0; loop < LOOP_N; loop++) {
        for (int fi = 0; fi < N_FREQ; fi++) {
            printf("%-12s %6.0f %12.1f %10.2f %10.2f %8.1fx\n", loop_name[loop], freq_hz[fi],
                   1e3 * ptp_coupling[loop][fi], 1e3 * rms[loop][fi][0], 1e3 * rms[loop][fi][1],
                   rms[loop][fi][0] / rms[loop][fi][1]);
        }
    }
}

static void test_compensation_reduces_the_coupling(void **state)
{
    (void)state;
    measure_all();
    for (int loop = 0; loop < LOOP_N; loop++) {
        for (int fi = 0; fi < N_FREQ; fi++) {
            double red = rms[loop][fi][0] / rms[loop][fi][1];
            if (red < floor_red[loop][fi]) {
                fail_msg("%s %.0f Hz: reduction %.2fx below %.1fx", loop_name[loop], freq_hz[fi], red,
                         floor_red[loop][fi]);
            }
        }
    }
}

/* In feedforward the uncompensated error is the stage's coupling: 0.3 % of
 * axis 2's stroke at 1 Hz, growing with frequency (docs/stage-model.md). */
static void test_uncompensated_coupling_is_the_stages(void **state)
{
    (void)state;
    measure_all();
    assert_true(ptp_coupling[LOOP_FF][0] > 0.03 && ptp_coupling[LOOP_FF][0] < 0.06);
    assert_true(ptp_coupling[LOOP_FF][2] > 4.0 * ptp_coupling[LOOP_FF][0]);
    /* feedback alone already rejects the slow coupling better than the fast */
    assert_true(rms[LOOP_FB][0][0] < 0.5 * rms[LOOP_FF][0][0]);
}

/* The coupling table has slots of its own: commit, refusal and rollback
 * leave the feedforward slot alone; rollback after a coupling commit acts on
 * the coupling slot (to none when there was no previous coupling table). */
/* A rollback from session 1, unlocked with a provisioned key. */
static uint16_t rollback_s1(piezo_ctl_t *c)
{
    piezo_ctl_set_key(c, 0x5EC0A71Du);
    assert_int_equal(piezo_ctl_unlock(c, 1u, 0x5EC0A71Du, 0u), PIEZO_OK);
    return piezo_ctl_rollback(c, 1u);
}

static void test_coupling_slot_commit_and_rollback(void **state)
{
    (void)state;
    static uint8_t bad[XC_SIL_TABLE_LEN];
    piezo_ctl_t *c;
    char err[256];
    if (stage_params_load_json(STAGE_FILE, &params, err, sizeof err) != STAGE_OK) {
        fail_msg("%s", err);
    }
    assert_int_equal(piezo_sil_init(&sil, &params, 1u), PIEZO_OK);
    c = &sil.ctl[0];
    assert_int_equal(piezo_ctl_coupling_crc(c), 0u);
    assert_int_equal(piezo_ctl_load_image(c, xc_sil_table, XC_SIL_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    piezo_sil_tick(&sil);
    assert_true(c->xc_active >= 0 && c->active < 0 && c->previous < 0);
    assert_int_equal(piezo_ctl_active_crc(c), 0u); /* the feedforward slot: still empty */
    /* a corrupted coupling image is refused; the running one stays */
    memcpy(bad, xc_sil_table, sizeof bad);
    bad[XC_SIL_TABLE_LEN / 2u] ^= 0x40u;
    assert_int_equal(piezo_ctl_load_image(c, bad, XC_SIL_TABLE_LEN), PIEZO_TABLE_REASON_BAD_CRC);
    piezo_sil_tick(&sil);
    assert_int_equal(piezo_ctl_coupling_crc(c), piezo_le32(xc_sil_table + XC_SIL_TABLE_LEN - 4u));
    /* the same table again: the first becomes the coupling rollback target */
    assert_int_equal(piezo_ctl_load_image(c, xc_sil_table, XC_SIL_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    piezo_sil_tick(&sil);
    assert_true(c->xc_previous >= 0 && c->xc_previous != c->xc_active);
    assert_int_equal(rollback_s1(c), PIEZO_TABLE_REASON_OK);
    piezo_sil_tick(&sil);
    assert_true(c->xc_active >= 0 && c->xc_previous < 0);
    /* a second rollback is a feedforward rollback: there is none */
    assert_int_equal(rollback_s1(c), PIEZO_TABLE_REASON_NO_PREVIOUS);
    assert_true(c->xc_active >= 0);
    /* a commit then a rollback with no previous coupling table: compensation off */
    assert_int_equal(piezo_sil_init(&sil, &params, 1u), PIEZO_OK);
    assert_int_equal(piezo_ctl_load_image(c, xc_sil_table, XC_SIL_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    piezo_sil_tick(&sil);
    /* applied while armed in FEEDFORWARD with the other axis driven: a term */
    assert_int_equal(piezo_ctl_set_mode(c, PIEZO_MODE_FEEDFORWARD), PIEZO_OK);
    assert_int_equal(piezo_ctl_set_mode(&sil.ctl[1], PIEZO_MODE_DIRECT), PIEZO_OK);
    sil.ctl[1].setpoint_q15 = 16000;
    assert_int_equal(piezo_ctl_arm(c, 1), PIEZO_OK);
    assert_int_equal(piezo_ctl_arm(&sil.ctl[1], 1), PIEZO_OK);
    for (uint32_t k = 0; k < 200u; k++) {
        /* the kernel's input: the position the table names (x_source, both
         * ways here), y or y2 as the tick recorded them; a copy of the
         * kernel's state, run on them, gives the term the tick applied */
        static struct piezo_xc before;
        int16_t want;
        c->xset[c->xc_active].x_source = (uint8_t)((k / 20u) & 1u);
        before = c->xc[c->xc_active];
        piezo_sil_tick(&sil);
        want = piezo_xc_process(&before, c->sig[PIEZO_SIG_U2],
                                c->sig[c->xset[c->xc_active].x_source ? PIEZO_SIG_Y2 : PIEZO_SIG_Y]);
        assert_int_equal(c->xc_q15, want);
        assert_true(k < 100u || c->sig[PIEZO_SIG_Y] != c->sig[PIEZO_SIG_Y2]);
    }
    assert_true(c->xc_q15 != 0);
    assert_int_equal(rollback_s1(c), PIEZO_TABLE_REASON_OK);
    piezo_sil_tick(&sil);
    assert_true(c->xc_active < 0);
    assert_int_equal(c->xc_q15, 0); /* the slot gone, no term */
    assert_int_equal(piezo_ctl_coupling_crc(c), 0u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_coupling_slot_commit_and_rollback),
        cmocka_unit_test(test_uncompensated_coupling_is_the_stages),
        cmocka_unit_test(test_compensation_reduces_the_coupling),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
