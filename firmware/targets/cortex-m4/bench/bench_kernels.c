/*
 * bench_kernels.c - each kernel of the core alone, one process() call per
 * tick on the 50 Hz test sine, coefficients in their documented ranges.
 * Set-up may divide (it is not the tick); the measured windows do not.
 */
#include <stddef.h>

#include "bench.h"
#include "kp.h"
#include "pid.h"
#include "recorder.h"
#include "wave.h"

/* --- wave generator: a sine --- */
static piezo_wave_t wave;
static const piezo_wave_cfg_t wave_cfg = {.kind = PIEZO_WAVE_SINE, .amplitude_q15 = 30000,
                                          .freq_word = 21474836u};
static void wave_tick(uint32_t k)
{
    (void)k;
    piezo_bench_sink = piezo_wave_process(&wave);
}

/* --- PID, notch, limiter --- */
static piezo_pid_t pid;
static const piezo_pid_coef_t pid_coef = {.kp_q24 = 1 << 23, .ki_q24 = 1 << 18, .kd_q24 = 1 << 20,
                                          .out_min_q15 = -32768, .out_max_q15 = 32767};
static void pid_tick(uint32_t k)
{
    piezo_bench_sink = piezo_pid_process(&pid, piezo_bench_u[k]);
}

static piezo_biquad_t notch;
/* A notch near 700 Hz at 10 kHz (b0 = b2 ~ 0.96, b1 = a1 ~ -1.72, a2 ~ 0.92). */
static const piezo_biquad_coef_t notch_coef = {.b0_q24 = 16106127, .b1_q24 = -28882000,
                                               .b2_q24 = 16106127, .a1_q24 = -28882000,
                                               .a2_q24 = 15435038};
static void notch_tick(uint32_t k)
{
    piezo_bench_sink = piezo_biquad_process(&notch, piezo_bench_u[k]);
}

static piezo_limit_t limit;
static const piezo_limit_coef_t limit_coef = {.min_q15 = -30000, .max_q15 = 30000, .max_step_q15 = 500};
static void limit_tick(uint32_t k)
{
    piezo_bench_sink = piezo_limit_process(&limit, piezo_bench_u[k]);
}

/* --- recorder: 4 of 8 signals, every tick, rising trigger --- */
#define REC_FRAMES 256u
static piezo_rec_t rec;
static int16_t rec_buf[REC_FRAMES * 4u];
static int16_t rec_signals[8];
static void rec_tick(uint32_t k)
{
    rec_signals[0] = piezo_bench_u[k];
    piezo_rec_process(&rec, rec_signals);
}

/* --- KP operators on an L x L Preisach grid (L(L+1)/2 operators) --- */
#define KP_MAX_L 30u
#define KP_MAX_OPS (KP_MAX_L * (KP_MAX_L + 1u) / 2u)
static int16_t kp_n1[KP_MAX_OPS], kp_n2[KP_MAX_OPS], kp_psi[KP_MAX_OPS];
static int32_t kp_w[KP_MAX_OPS];
static struct piezo_kp_coeffs kp_coeffs;
static struct piezo_kp kp;

/* The cell convention of kp.h: midpoints n1 = nmin + (i - 1/2) h,
 * n2 = nmin + (j - 1/2) h, i <= j, ridge saturating over one cell. */
static int kp_setup(uint32_t L)
{
    const int32_t nmin = -32768, span = 65535, rmax = 32767;
    const int32_t h = span / (int32_t)L;
    uint16_t n = 0;
    for (uint32_t i = 1; i <= L; i++) {
        for (uint32_t j = i; j <= L; j++) {
            kp_n1[n] = (int16_t)(nmin + (int32_t)(2u * i - 1u) * h / 2);
            kp_n2[n] = (int16_t)(nmin + (int32_t)(2u * j - 1u) * h / 2);
            kp_w[n] = (int32_t)((1 << 24) / (int32_t)(L * L)) * ((n & 1u) ? 1 : 2);
            n++;
        }
    }
    int32_t slope = (int32_t)(((int64_t)rmax * 65536 + h / 2) / h);
    int32_t xsat = 1;
    while (((int64_t)xsat * slope + 32768) >> 16 < rmax) {
        xsat++;
    }
    kp_coeffs.grid = (struct piezo_kp_grid){.n1_q15 = kp_n1, .n2_q15 = kp_n2, .n_ops = n,
                                            .nmin_q15 = (int16_t)nmin, .rmax_q15 = (int16_t)rmax,
                                            .slope_q16 = slope, .xsat_q15 = xsat};
    kp_coeffs.w_q24 = kp_w;
    return piezo_kp_init(&kp, &kp_coeffs, kp_psi, KP_MAX_OPS) == PIEZO_OK;
}

static void kp_tick(uint32_t k)
{
    piezo_bench_sink = piezo_kp_process(&kp, piezo_bench_u[k]);
}

static void fail(const char *what)
{
    piezo_bench_failures++;
    piezo_bench_run(what, 0u, NULL); /* "bench <what> 0": bench-target reports it */
}

void piezo_bench_kernels(void)
{
    if (piezo_wave_init(&wave, &wave_cfg) == 0) {
        piezo_bench_run("wave_sine", PIEZO_BENCH_TICKS, wave_tick);
    } else {
        fail("wave_sine:init-failed");
    }
    if (piezo_pid_init(&pid, &pid_coef) == 0) {
        piezo_bench_run("pid", PIEZO_BENCH_TICKS, pid_tick);
    } else {
        fail("pid:init-failed");
    }
    if (piezo_biquad_init(&notch, &notch_coef) == 0) {
        piezo_bench_run("notch_biquad", PIEZO_BENCH_TICKS, notch_tick);
    } else {
        fail("notch_biquad:init-failed");
    }
    if (piezo_limit_init(&limit, &limit_coef, 0) == 0) {
        piezo_bench_run("limit", PIEZO_BENCH_TICKS, limit_tick);
    } else {
        fail("limit:init-failed");
    }
    piezo_rec_cfg_t rc = {.n_channels = 4, .signal = {0, 1, 2, 3}, .decimation = 1, .pretrigger = 64,
                          .trigger = PIEZO_REC_RISING, .trigger_signal = 0, .trigger_level_q15 = 10000};
    if (piezo_rec_init(&rec, rec_buf, (uint32_t)(sizeof rec_buf / sizeof rec_buf[0]), 8) == 0 &&
        piezo_rec_configure(&rec, &rc) == 0) {
        piezo_rec_arm(&rec);
        piezo_bench_run("recorder", PIEZO_BENCH_TICKS, rec_tick);
    } else {
        fail("recorder:init-failed");
    }
    static const uint32_t sizes[] = {5u, 10u, 20u, 30u};
    static const char *const names[] = {"kp_L5", "kp_L10", "kp_L20", "kp_L30"};
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++) {
        if (kp_setup(sizes[s])) {
            piezo_bench_run(names[s], PIEZO_BENCH_TICKS, kp_tick);
        } else {
            fail(names[s]);
        }
    }
}
