/*
 * bench_models.c - each hysteresis model of the reference configuration
 * alone, one call per tick: RKP, the DCC law, the CPI and UPI play banks,
 * the EUPI model and its inverse. Coefficients from bench_tables.h (the host
 * golden models' reference sizes: KP planes L = 10, 20, 30, 10 CPI, 10 x 3 UPI,
 * u^2..u^4, RKP with 13 Gaussians); play banks of 40 thresholds per column
 * made here (their cost against the column's length).
 */
#include <stddef.h>

#include "bench.h"
#include "bench_tables.h"
#include "coefset.h"
#include "dcc.h"
#include "eupi.h"
#include "eupi_inv.h"
#include "play.h"
#include "piezo_interface.h"
#include "rkp.h"

/* 0.6 FS: inside the EUPI reference model's output range (inverse input). */
static int16_t u_small[PIEZO_BENCH_TICKS];

#define GRID_OF(p)                                                                             \
    {                                                                                          \
        .n1_q15 = p##_n1, .n2_q15 = p##_n2, .n_ops = p##_NOPS, .nmin_q15 = p##_NMIN,           \
        .rmax_q15 = p##_RMAX, .slope_q16 = p##_SLOPE, .xsat_q15 = p##_XSAT                     \
    }

/* --- RKP, L = 10 --- */
static const struct piezo_rkp_coeffs rkp_coeffs = {
    .grid = GRID_OF(bench_rkp), .theta_q24 = bench_rkp_theta, .center_q24 = bench_rkp_center,
    .inv_width_q16 = bench_rkp_inv_width, .n_rbf = bench_rkp_NRBF, .alpha_q16 = bench_rkp_ALPHA};
static struct piezo_rkp rkp;
static int16_t rkp_psi[bench_rkp_NOPS];
static int32_t rkp_w[bench_rkp_NOPS];
static void rkp_tick(uint32_t k)
{
    piezo_bench_sink = piezo_rkp_process(&rkp, piezo_bench_u[k]);
}

/* --- DCC law on the KP planes L = 10, 20, 30 (55, 210, 465 operators) --- */
static const struct piezo_dcc_coeffs dcc_coeffs[3] = {
    {.grid = GRID_OF(bench_dcc10), .c_q24 = bench_dcc10_c, .g_q24 = bench_dcc10_G},
    {.grid = GRID_OF(bench_dcc20), .c_q24 = bench_dcc20_c, .g_q24 = bench_dcc20_G},
    {.grid = GRID_OF(bench_dcc30), .c_q24 = bench_dcc30_c, .g_q24 = bench_dcc30_G},
};
static struct piezo_dcc dcc;
static int32_t dcc_cpsi[bench_dcc30_NOPS], dcc_zo[bench_dcc30_NOPS];
static void dcc_tick(uint32_t k)
{
    piezo_bench_sink = piezo_dcc_process(&dcc, piezo_bench_u[k]);
}

/* As the controller's loader does for a kp_dcc table: the weights' prefix
 * sums (coefset.c), then the weights declared constant. */
static struct piezo_dcc_coeffs dcc_summed;
static int32_t dcc_sums[2u * (bench_dcc30_NOPS + 1u)];
static enum piezo_err dcc_init_const(size_t i)
{
    dcc_summed = dcc_coeffs[i];
    const enum piezo_err rc = piezo_dcc_init(&dcc, &dcc_summed, dcc_cpsi, dcc_zo, bench_dcc30_NOPS);
    if (rc == PIEZO_OK) {
        if (piezo_dcc_prefix_sums(&dcc, dcc_sums, sizeof dcc_sums / sizeof dcc_sums[0]) == PIEZO_OK) {
            dcc_summed.csum_q24 = dcc_sums;
        }
        piezo_dcc_const_weights(&dcc);
    }
    return rc;
}

/* --- play banks of the EUPI reference model --- */
static const struct piezo_play_coef cpi_coef = {bench_eupi_r_cpi_q15, NULL, bench_eupi_b_q24, BENCH_EUPI_NCPI, 0};
static const struct piezo_play_coef upi_coef = {bench_eupi_r_upi_q15, bench_eupi_a_upi_q24, bench_eupi_d_q24,
                                                BENCH_EUPI_NUR, BENCH_EUPI_NUA};
static struct piezo_play play;
static int32_t play_f[BENCH_EUPI_NUR * BENCH_EUPI_NUA];
static int64_t play_off[PIEZO_PLAY_WORK_LEN(BENCH_EUPI_NUR, BENCH_EUPI_NUA)];
static void play_tick(uint32_t k)
{
    piezo_bench_sink = (int32_t)(piezo_play_process(&play, piezo_bench_u[k]) >> 24);
}

/* --- longer play banks: the cost against the thresholds per column (40
 * thresholds in [0, 0.9) FS, slopes 0.6, 1.0, 1.45, weights 0.001-0.004) --- */
#define LONG_NR 40u
#define LONG_NA 3u
static int32_t long_r[LONG_NR], long_a[LONG_NA], long_w[LONG_NR * LONG_NA];
static const struct piezo_play_coef long_cpi_coef = {long_r, NULL, long_w, LONG_NR, 0};
static const struct piezo_play_coef long_upi_coef = {long_r, long_a, long_w, LONG_NR, LONG_NA};
#define LONG_F_LEN (LONG_NR * LONG_NA)
#define LONG_OFF_LEN PIEZO_PLAY_WORK_LEN(LONG_NR, LONG_NA)
static int32_t long_f[LONG_F_LEN];
static int64_t long_off[LONG_OFF_LEN];

static void long_banks_fill(void)
{
    for (uint32_t i = 0; i < LONG_NR; i++) {
        long_r[i] = (int32_t)((i * 29491u) / LONG_NR); /* 0.9 FS i / n */
    }
    long_a[0] = 10066330;  /* 0.6 */
    long_a[1] = 16777216;  /* 1.0 */
    long_a[2] = 24326963;  /* 1.45 */
    for (uint32_t k = 0; k < LONG_NR * LONG_NA; k++) {
        long_w[k] = 16777 + (int32_t)((k * 2654435761u) >> 16) % 50331; /* 0.001 .. 0.004 */
    }
}

/* --- EUPI model and its inverse --- */
static const struct piezo_eupi_coef eupi_coef = {
    .cpi = {bench_eupi_r_cpi_q15, NULL, bench_eupi_b_q24, BENCH_EUPI_NCPI, 0},
    .upi = {bench_eupi_r_upi_q15, bench_eupi_a_upi_q24, bench_eupi_d_q24, BENCH_EUPI_NUR, BENCH_EUPI_NUA},
    .p_q24 = bench_eupi_p_q24, .a0_q24 = BENCH_EUPI_A0_Q24, .p0_q24 = BENCH_EUPI_P0_Q24, .n_p = BENCH_EUPI_NP};
static struct piezo_eupi eupi;
static int32_t eupi_state[PIEZO_EUPI_STATE_LEN(BENCH_EUPI_NCPI, BENCH_EUPI_NUR, BENCH_EUPI_NUA)];
static int64_t eupi_work[PIEZO_EUPI_WORK_LEN(BENCH_EUPI_NUR, BENCH_EUPI_NUA)];
static void eupi_tick(uint32_t k)
{
    piezo_bench_sink = piezo_eupi_process(&eupi, piezo_bench_u[k]);
}

/* the reference case's set and state (bench_reference.c), reloaded here:
 * the image has no RAM for a second pair */
extern piezo_coefset_t bench_inv_set;
extern piezo_ff_state_t bench_inv_ff;
#define inv_set bench_inv_set
#define inv_ff bench_inv_ff
static void eupi_inv_tick(uint32_t k)
{
    piezo_bench_sink = piezo_eupi_inv_process(&inv_ff.inv, u_small[k]);
}

static void run_or_fail(const char *name, int ok, piezo_bench_tick_fn tick)
{
    if (ok) {
        piezo_bench_run(name, PIEZO_BENCH_TICKS, tick);
    } else {
        piezo_bench_failures++;
        piezo_bench_run(name, 0u, NULL);
    }
}

void piezo_bench_models(void)
{
    for (uint32_t k = 0; k < PIEZO_BENCH_TICKS; k++) {
        u_small[k] = (int16_t)(((int32_t)piezo_bench_u[k] * 43691) >> 16);
    }
    run_or_fail("rkp_L10", piezo_rkp_init(&rkp, &rkp_coeffs, rkp_psi, rkp_w, bench_rkp_NOPS) == PIEZO_OK,
                rkp_tick);
    /* constant weights (a kp_dcc table) on the three planes: cost against L */
    static const char *const dcc_names[3] = {"dcc_L10", "dcc_L20", "dcc_L30"};
    for (size_t i = 0; i < 3u; i++) {
        run_or_fail(dcc_names[i], dcc_init_const(i) == PIEZO_OK, dcc_tick);
    }
    run_or_fail("dcc_L10_varying_w",
                piezo_dcc_init(&dcc, &dcc_coeffs[0], dcc_cpsi, dcc_zo, bench_dcc30_NOPS) == PIEZO_OK, dcc_tick);
    run_or_fail("play_cpi10", piezo_play_init(&play, &cpi_coef, play_f, BENCH_EUPI_NCPI, NULL, 0u) == PIEZO_OK,
                play_tick);
    run_or_fail("play_upi10x3",
                piezo_play_init(&play, &upi_coef, play_f, BENCH_EUPI_NUR * BENCH_EUPI_NUA, play_off,
                                sizeof play_off / sizeof play_off[0]) == PIEZO_OK,
                play_tick);
    long_banks_fill();
    run_or_fail("play_cpi40",
                piezo_play_init(&play, &long_cpi_coef, long_f, LONG_F_LEN, long_off, LONG_OFF_LEN) == PIEZO_OK,
                play_tick);
    run_or_fail("play_upi40x3",
                piezo_play_init(&play, &long_upi_coef, long_f, LONG_F_LEN, long_off, LONG_OFF_LEN) == PIEZO_OK,
                play_tick);
    run_or_fail("eupi",
                piezo_eupi_init(&eupi, &eupi_coef, eupi_state, sizeof eupi_state / sizeof eupi_state[0],
                                eupi_work, sizeof eupi_work / sizeof eupi_work[0]) == PIEZO_OK,
                eupi_tick);
    run_or_fail("eupi_inv",
                piezo_coefset_load(&inv_set, &inv_ff, bench_eupi_inv_img, BENCH_EUPI_INV_IMG_LEN) ==
                        PIEZO_TABLE_REASON_OK &&
                    piezo_ff_bind(&inv_ff, &inv_set) == PIEZO_OK,
                eupi_inv_tick);
}
