/* sil_bench: simulated seconds per wall second of the SIL loop (the firmware
 * controller against the C stage model, tick by tick).
 *
 *   sil_bench PARAMS.json [eupi|dcc] [SIM_SECONDS]
 *
 * Every axis runs the full reference configuration: the table built for the
 * default stage (piezoctl.golden.sil_tables: EUPI inverse or KP/DCC), mode
 * FF_FEEDBACK with PI + notch, a 10 Hz triangle over 80 % of the stroke from
 * the wave generator and the recorder taking four signals every tick
 * (continuous: a RISING trigger that never fires keeps it ARMED). On a stage
 * other than the default the table and the feedback are not tuned for it:
 * the PI runs with kp = 0 and ki / 32 (the notch unchanged), which keeps a
 * stage with a low first mode stable and costs the same per tick. This
 * measures speed, not tracking. Wall time is CLOCK_MONOTONIC over the ticks.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "piezo_err.h"
#include "sil_loop.h"
#include "sil_tables_vectors.h"

#define RAMP_TICKS 2500u

static piezo_sil_t sil; /* large: not on the stack */

static int setup_axis(piezo_sil_t *s, const stage_params *p, int axis, int dcc, int tuned)
{
    piezo_ctl_cfg_t cfg;
    piezo_scale_t sc;
    piezo_ctl_t *c = &s->ctl[axis];
    const uint8_t *img = dcc ? sil_dcc_img : sil_eupi_img;
    uint32_t len = dcc ? SIL_DCC_IMG_LEN : SIL_EUPI_IMG_LEN;
    piezo_rec_cfg_t rc;
    uint16_t r;
    const piezo_biquad_coef_t notch = {SIL_NOTCH_B0_Q24, SIL_NOTCH_B1_Q24, SIL_NOTCH_B2_Q24,
                                       SIL_NOTCH_A1_Q24, SIL_NOTCH_A2_Q24};

    if (piezo_sil_ctl_config(p, axis, &cfg, &sc) != PIEZO_OK) {
        return -1;
    }
    piezo_sil_set_feedback(&cfg, tuned ? SIL_FB_KP_Q24 : 0, tuned ? SIL_FB_KI_Q24 : SIL_FB_KI_Q24 / 32,
                           SIL_FB_KD_Q24, &notch);
    if (piezo_ctl_init(c, &cfg) != PIEZO_OK) {
        return -1;
    }
    if ((r = piezo_ctl_load_image(c, img, len)) != PIEZO_TABLE_REASON_OK) {
        fprintf(stderr, "sil_bench: table refused (reason %u)\n", r);
        return -1;
    }
    memset(&rc, 0, sizeof rc);
    rc.n_channels = 4;
    rc.signal[0] = PIEZO_SIG_REF;
    rc.signal[1] = PIEZO_SIG_Y;
    rc.signal[2] = PIEZO_SIG_U;
    rc.signal[3] = PIEZO_SIG_ERR;
    rc.decimation = 1;
    rc.pretrigger = 1000;
    rc.trigger = PIEZO_REC_RISING;
    rc.trigger_signal = PIEZO_SIG_REF;
    rc.trigger_level_q15 = 32767; /* never crossed: records continuously into the ring */
    if (piezo_rec_configure(&c->rec, &rc) != PIEZO_OK || piezo_ctl_set_mode(c, PIEZO_MODE_FF_FEEDBACK) != PIEZO_OK) {
        return -1;
    }
    piezo_rec_arm(&c->rec);
    memset(&c->wave_cfg, 0, sizeof c->wave_cfg);
    c->wave_cfg.kind = PIEZO_WAVE_TRIANGLE;
    c->wave_cfg.offset_q15 = SIL_REF_OFFSET_Q15;
    c->wave_cfg.amplitude_q15 = SIL_REF_AMPLITUDE_Q15;
    c->wave_cfg.freq_word = (uint32_t)llround(10.0 / p->sample_rate_hz * 4294967296.0);
    return 0;
}

int main(int argc, char **argv)
{
    stage_params p;
    char err[512];
    int dcc = argc > 2 && strcmp(argv[2], "dcc") == 0;
    int tuned;
    double sim_s = argc > 3 ? strtod(argv[3], NULL) : 20.0;
    uint64_t n, k;
    int64_t sum = 0;
    struct timespec t0, t1;
    double wall;

    if (argc < 2 || (argc > 2 && !dcc && strcmp(argv[2], "eupi") != 0) || !(sim_s > 0.0)) {
        fprintf(stderr, "usage: sil_bench PARAMS.json [eupi|dcc] [SIM_SECONDS]\n");
        return 2;
    }
    if (stage_params_load_json(argv[1], &p, err, sizeof err) != STAGE_OK) {
        fprintf(stderr, "sil_bench: %s\n", err);
        return 2;
    }
    tuned = strcmp(p.name, "default") == 0;
    if (piezo_sil_init(&sil, &p, 1) != PIEZO_OK) {
        fprintf(stderr, "sil_bench: piezo_sil_init failed\n");
        return 2;
    }
    for (int a = 0; a < sil.n_axes; a++) {
        if (setup_axis(&sil, &p, a, dcc, tuned) != 0) {
            fprintf(stderr, "sil_bench: axis %d: setup failed\n", a);
            return 2;
        }
    }
    piezo_sil_tick(&sil); /* the committed tables take over at this tick boundary */
    for (int a = 0; a < sil.n_axes; a++) {
        if (piezo_ctl_arm(&sil.ctl[a], 1) != PIEZO_OK) {
            fprintf(stderr, "sil_bench: axis %d: arm failed\n", a);
            return 2;
        }
    }
    /* from rest to the wave's first sample in 0.25 s (not timed) */
    for (k = 0; k < RAMP_TICKS; k++) {
        for (int a = 0; a < sil.n_axes; a++) {
            piezo_ctl_t *c = &sil.ctl[a];
            double w = 0.5 - 0.5 * cos(3.14159265358979 * (double)(k + 1u) / RAMP_TICKS);
            c->setpoint_q15 = (int16_t)lround(c->sig[PIEZO_SIG_Y] * (1.0 - w) + SIL_REF_OFFSET_Q15 * w);
        }
        piezo_sil_tick(&sil);
    }
    for (int a = 0; a < sil.n_axes; a++) {
        if (piezo_ctl_start_wave(&sil.ctl[a]) != PIEZO_OK) {
            fprintf(stderr, "sil_bench: axis %d: wave failed\n", a);
            return 2;
        }
    }
    n = (uint64_t)llround(sim_s * p.sample_rate_hz);
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (k = 0; k < n; k++) {
        piezo_sil_tick(&sil);
        sum += sil.adc[0];
        if (!sil.ctl[0].st.armed) {
            fprintf(stderr, "sil_bench: disarmed at tick %llu\n", (unsigned long long)k);
            break;
        }
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    wall = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    for (int a = 0; a < sil.n_axes; a++) {
        if (!sil.ctl[a].st.armed || sil.ctl[a].rec.state != PIEZO_REC_ARMED) {
            fprintf(stderr, "sil_bench: axis %d stopped (faults 0x%x)\n", a, (unsigned)sil.ctl[a].st.faults);
            return 1;
        }
    }
    printf("%s: %d axis, %s table + PI%s + notch + recorder: %.1f s simulated in %.3f s wall: "
           "%.0fx real time, %.3f us per tick (checksum %lld)\n",
           p.name, p.num_axes, dcc ? "DCC" : "EUPI", tuned ? "" : " (detuned)", (double)n / p.sample_rate_hz, wall,
           (double)n / p.sample_rate_hz / wall, 1e6 * wall / (double)n, (long long)sum);
    return 0;
}
