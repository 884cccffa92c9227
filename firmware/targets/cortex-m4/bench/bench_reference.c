/*
 * bench_reference.c - the reference configuration of the "Targets" issue.
 *
 * "reference" (the first instructions_per_tick line) counts what the
 * firmware computes in one tick: parts 1 and 3 below. Part 2, the EUPI
 * model, is the benchmark's simulated stage (its output is the next tick's
 * ADC sample): it runs every tick too, but outside the counted window, as a
 * real stage would. "reference_with_stage_model" counts all three, for the
 * reading of the contract in which the forward EUPI model also runs in the
 * tick (as an observer).
 *
 *   1. piezo_control_tick(), the function SysTick_Handler calls (control.c):
 *      the ADC seam, piezo_ctl_tick() on the firmware's own instance with a
 *      committed kp_dcc table (KP plane L = 20, 210 operators) in FF_FEEDBACK
 *      mode: wave generator (sine) as reference, the DCC law, PI feedback
 *      (kd = 0) with the notch, clamp and slew limit, the DAC code, the
 *      recorder on (4 channels every tick, triggered at the start), the DAC
 *      seam;
 *   2. the EUPI model (10 CPI + 10 x 3 UPI + 3 polynomial terms) on the
 *      applied drive: the stage observer. Its output is the next tick's ADC
 *      code (the benchmark's stage), so the feedback acts on a hysteretic
 *      plant;
 *   3. the EUPI inverse of the same model (committed as an eupi_inverse
 *      table through piezo_coefset_load, run by piezo_ff_process) on the
 *      reference scaled to 2/3 (0.6 FS, inside the model's range).
 *
 * "reference_steps": the reference with a user's steps as its drive instead
 * of the sine (the wave's STEPS kind, the same 0.9 FS amplitude, levels
 * held 50 ticks): each step moves the DCC's input across many of the KP
 * plane's lines in one tick (up to 1.8 FS, about 18 of the 20 lines), the
 * case the sine never reaches (at most 942 LSB a tick, a line is 3,277).
 *
 * "reference_dyninv32" and "ref_control_dyninv32": the same with the
 * dynamics-inverse FIR on (32 taps, spacing 1: its most taps; the cost does
 * not depend on the spacing), against "reference" and "ref_control" with it
 * off (0 taps: one compare in the tick).
 *
 * The controller runs one feedforward table per tick; the contract's
 * reference counts KP + DCC and EUPI + inverse together, so the DCC table
 * runs inside the controller and the EUPI pair beside it.
 */
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "bench.h"
#include "bench_tables.h"
#include "coefset.h"
#include "control.h"
#include "eupi.h"
#include "piezo_interface.h"
#include "semihost.h"
#include "tick.h"

/* The stage of the benchmark: the EUPI observer's output of the last tick. */
static int32_t stage_code = 1 << 15;
static int32_t dac_code;

void piezo_adc_read(int32_t adc[2])
{
    adc[0] = stage_code;
    adc[1] = 1 << 15;
}

void piezo_dac_write(int32_t code)
{
    dac_code = code;
}

/* The EUPI reference model (forward). */
static const struct piezo_eupi_coef eupi_coef = {
    .cpi = {bench_eupi_r_cpi_q15, NULL, bench_eupi_b_q24, BENCH_EUPI_NCPI, 0},
    .upi = {bench_eupi_r_upi_q15, bench_eupi_a_upi_q24, bench_eupi_d_q24, BENCH_EUPI_NUR, BENCH_EUPI_NUA},
    .p_q24 = bench_eupi_p_q24,
    .a0_q24 = BENCH_EUPI_A0_Q24,
    .p0_q24 = BENCH_EUPI_P0_Q24,
    .n_p = BENCH_EUPI_NP,
};
static struct piezo_eupi eupi;
static int32_t eupi_state[PIEZO_EUPI_STATE_LEN(BENCH_EUPI_NCPI, BENCH_EUPI_NUR, BENCH_EUPI_NUA)];
static int64_t eupi_work[PIEZO_EUPI_WORK_LEN(BENCH_EUPI_NUR, BENCH_EUPI_NUA)];

/* The EUPI inverse, loaded from its table image as a commit would. */
piezo_coefset_t bench_inv_set;
piezo_ff_state_t bench_inv_ff;

static void reference_tick(uint32_t k)
{
    (void)k;
    piezo_control_tick();
    const int16_t u = piezo_axis.sig[PIEZO_SIG_U];
    const int16_t y = piezo_eupi_process(&eupi, u);
    stage_code = (1 << 15) + y;
    const int16_t yr = (int16_t)(((int32_t)piezo_axis.sig[PIEZO_SIG_REF] * 43691) >> 16); /* 2/3 */
    piezo_bench_sink = piezo_ff_process(&bench_inv_ff, &bench_inv_set, yr, 0);
}

/* The reference tick again, with the markers around one of its three parts
 * only: where the reference's count goes. */
static unsigned ref_part;

static void reference_part_tick(void)
{
    if (ref_part == 0u) {
        piezo_bench_begin();
    }
    piezo_control_tick();
    if (ref_part == 0u) {
        piezo_bench_end();
    }
    const int16_t u = piezo_axis.sig[PIEZO_SIG_U];
    if (ref_part == 1u) {
        piezo_bench_begin();
    }
    const int16_t y = piezo_eupi_process(&eupi, u);
    if (ref_part == 1u) {
        piezo_bench_end();
    }
    stage_code = (1 << 15) + y;
    const int16_t yr = (int16_t)(((int32_t)piezo_axis.sig[PIEZO_SIG_REF] * 43691) >> 16); /* 2/3 */
    if (ref_part == 2u) {
        piezo_bench_begin();
    }
    piezo_bench_sink = piezo_ff_process(&bench_inv_ff, &bench_inv_set, yr, 0);
    if (ref_part == 2u) {
        piezo_bench_end();
    }
}

/* 1: setup() configures the dynamics-inverse FIR with all its taps */
static unsigned with_dyninv;
/* 1: setup() drives the reference by steps_shape (each level held 50 ticks) */
static unsigned with_steps;

/* The steps' shape (q15, times the 0.9 FS amplitude): jumps of every size
 * from a line to the whole plane, up and down, between the rails and in
 * the middle; 20 levels of 50 ticks cover the 1000 counted ticks. */
#define BENCH_STEPS_N 20u
#define BENCH_STEPS_HOLD 50u
static const int16_t steps_shape[BENCH_STEPS_N] = {
    32767, -32767, 32767, 0, -32767, 16384, -16384, 24576, -32767, 8192,
    -8192, 32767, -24576, 4096, 32767, 12288, -32767, -4096, 28672, -32767,
};

static int setup(void)
{
    piezo_ctl_t *c = &piezo_axis;
    piezo_ctl_cfg_t cfg;
    piezo_control_default_cfg(&cfg);
    if (with_dyninv) {
        /* a lead-lag around unity (taps summing to 8192): the value of the taps costs nothing */
        cfg.dyninv.n_taps = PIEZO_FIR_MAX_TAPS;
        cfg.dyninv.spacing = 1u;
        for (uint32_t i = 0; i < PIEZO_FIR_MAX_TAPS; i++) {
            cfg.dyninv.h_q13[i] = (int16_t)((i & 1u) ? -300 : 300);
        }
        cfg.dyninv.h_q13[3] = 8192;
    }
    cfg.pid = (piezo_pid_coef_t){.kp_q24 = 1 << 22, .ki_q24 = 1 << 19, .kd_q24 = 0,
                                 .out_min_q15 = -8192, .out_max_q15 = 8192};
    /* the notch of bench_kernels.c: about 700 Hz at 10 kHz */
    cfg.notch = (piezo_biquad_coef_t){.b0_q24 = 16106127, .b1_q24 = -28882000, .b2_q24 = 16106127,
                                      .a1_q24 = -28882000, .a2_q24 = 15435038};
    cfg.notch_on = 1u;
    cfg.limit = (piezo_limit_coef_t){.min_q15 = -32000, .max_q15 = 32000, .max_step_q15 = 4000};
    cfg.u_safe_q15 = -32000;
    if (piezo_ctl_init(c, &cfg) != 0 ||
        piezo_ctl_load_image(c, bench_dcc_img, BENCH_DCC_IMG_LEN) != PIEZO_TABLE_REASON_OK) {
        return -1;
    }
    c->wave_cfg = (piezo_wave_cfg_t){.kind = PIEZO_WAVE_SINE, .amplitude_q15 = 29491, /* 0.9 FS */
                                     .freq_word = 21474836u /* 50 Hz */};
    if (with_steps) {
        c->wave_cfg.kind = PIEZO_WAVE_STEPS;
        c->wave_cfg.n_levels = BENCH_STEPS_N;
        for (uint32_t i = 0; i < BENCH_STEPS_N; i++) {
            c->levels_q15[i] = steps_shape[i];
            c->durations[i] = BENCH_STEPS_HOLD;
        }
    }
    const piezo_rec_cfg_t rc = {.n_channels = 4,
                                .signal = {PIEZO_SIG_REF, PIEZO_SIG_Y, PIEZO_SIG_U, PIEZO_SIG_FF},
                                .decimation = 1, .pretrigger = 0, .trigger = PIEZO_REC_IMMEDIATE};
    if (piezo_rec_configure(&c->rec, &rc) != 0 || piezo_ctl_set_mode(c, PIEZO_MODE_FF_FEEDBACK) != 0 ||
        piezo_ctl_start_wave(c) != 0 || piezo_ctl_arm(c, 1u) != 0) {
        return -1;
    }
    if (piezo_eupi_init(&eupi, &eupi_coef, eupi_state, sizeof eupi_state / sizeof eupi_state[0], eupi_work,
                        sizeof eupi_work / sizeof eupi_work[0]) != 0) {
        return -1;
    }
    /* the stage has rested at u_safe */
    stage_code = (1 << 15) + piezo_eupi_process(&eupi, cfg.u_safe_q15);
    piezo_rec_arm(&c->rec);
    piezo_control_tick(); /* the committed table takes over at a tick boundary */
    if (c->active < 0 || c->set[c->active].kind != PIEZO_TABLE_KIND_KP_DCC || c->rec.state != PIEZO_REC_TRIGGERED) {
        return -1;
    }
    if (piezo_coefset_load(&bench_inv_set, &bench_inv_ff, bench_eupi_inv_img, BENCH_EUPI_INV_IMG_LEN) !=
            PIEZO_TABLE_REASON_OK ||
        piezo_ff_bind(&bench_inv_ff, &bench_inv_set) != 0) {
        return -1;
    }
    /* one sample each before the measured ticks, like the controller's set-up
     * tick: the first sample after a reset updates every operator */
    (void)piezo_ff_process(&bench_inv_ff, &bench_inv_set, 0, 0);
    return 0;
}

/* The stage: the EUPI model on the drive the controller applied last tick. */
static void stage_step(void)
{
    stage_code = (1 << 15) + piezo_eupi_process(&eupi, piezo_axis.sig[PIEZO_SIG_U]);
}

/* What the firmware computes in a tick: the controller and the EUPI inverse. */
static void firmware_tick(void)
{
    piezo_control_tick();
    const int16_t yr = (int16_t)(((int32_t)piezo_axis.sig[PIEZO_SIG_REF] * 43691) >> 16); /* 2/3 */
    piezo_bench_sink = piezo_ff_process(&bench_inv_ff, &bench_inv_set, yr, 0);
}

static int check_running(void)
{
    /* the loop really ran: armed, no fault, the recorder still recording */
    if (!piezo_axis.st.armed || piezo_axis.st.faults != 0u || piezo_axis.rec.state != PIEZO_REC_TRIGGERED) {
        char line[96];
        snprintf(line, sizeof line, "reference: armed %u faults 0x%lx recorder state %u\n",
                 (unsigned)piezo_axis.st.armed, (unsigned long)piezo_axis.st.faults,
                 (unsigned)piezo_axis.rec.state);
        piezo_sh_write0(line);
        return -1;
    }
    return 0;
}

/* The whole firmware tick counted, the stage stepped between ticks uncounted;
 * -1 (and the failure counted) when the setup fails. */
static int bench_full(const char *name)
{
    char line[64];
    if (setup() != 0) {
        piezo_bench_failures++;
        piezo_bench_run(name, 0u, NULL);
        return -1;
    }
    snprintf(line, sizeof line, "bench %s %u\n", name, PIEZO_BENCH_TICKS);
    piezo_sh_write0(line);
    for (uint32_t k = 0; k < PIEZO_BENCH_TICKS; k++) {
        if (k > 0u) {
            stage_step(); /* the stage's response to last tick's drive, uncounted */
        }
        piezo_bench_begin();
        firmware_tick();
        piezo_bench_end();
    }
    if (check_running() != 0) {
        piezo_bench_failures++;
    }
    return 0;
}

/* One part of the reference tick (ref_part) counted alone. */
static void bench_part(const char *name)
{
    char line[64];
    if (setup() != 0) {
        piezo_bench_failures++;
        piezo_bench_run(name, 0u, NULL);
        return;
    }
    snprintf(line, sizeof line, "bench %s %u\n", name, PIEZO_BENCH_TICKS);
    piezo_sh_write0(line);
    for (uint32_t k = 0; k < PIEZO_BENCH_TICKS; k++) {
        reference_part_tick();
    }
}

void piezo_bench_reference(void)
{
    if (bench_full("reference") != 0) {
        return;
    }
    if (setup() != 0) {
        piezo_bench_failures++;
        piezo_bench_run("reference_with_stage_model", 0u, NULL);
        return;
    }
    piezo_bench_run("reference_with_stage_model", PIEZO_BENCH_TICKS, reference_tick);
    if (check_running() != 0) {
        piezo_bench_failures++;
    }
    static const char *const part_name[3] = {"ref_control", "ref_eupi", "ref_eupi_inv"};
    for (ref_part = 0u; ref_part < 3u; ref_part++) {
        bench_part(part_name[ref_part]);
    }
    /* the same driven by steps */
    with_steps = 1u;
    (void)bench_full("reference_steps");
    with_steps = 0u;
    /* the same with the dynamics-inverse FIR on, all its taps */
    with_dyninv = 1u;
    (void)bench_full("reference_dyninv32");
    ref_part = 0u;
    bench_part("ref_control_dyninv32");
    with_dyninv = 0u;
}
