/* The CPI/UPI play operator bank against the host golden model, bit for bit. */
#include <string.h>

#include "piezo_test.h"
#include "fixed_q.h"
#include "play.h"
#include "play_vectors.h"

static int32_t f_buf[PIEZO_PLAY_MAX_OPS];
#define OFF_LEN (PIEZO_PLAY_MAX_OPS + 64)
static int64_t off_buf[OFF_LEN];

static const struct piezo_play_coef cpi_coef = {
    golden_play_cpi_r_q15, golden_play_cpi_a_q24, golden_play_cpi_w_q24,
    GOLDEN_PLAY_CPI_NR, GOLDEN_PLAY_CPI_NA,
};
static const struct piezo_play_coef upi_coef = {
    golden_play_upi_r_q15, golden_play_upi_a_q24, golden_play_upi_w_q24,
    GOLDEN_PLAY_UPI_NR, GOLDEN_PLAY_UPI_NA,
};
static const struct piezo_play_coef wide_coef = {
    golden_play_wide_r_q15, golden_play_wide_a_q24, golden_play_wide_w_q24,
    GOLDEN_PLAY_WIDE_NR, GOLDEN_PLAY_WIDE_NA,
};

/* Run one case from reset: the weighted sum of every sample and every
 * operator output of the first nf samples must equal the golden model's. */
static void run_case(const char *name, const struct piezo_play_coef *coef,
                     const int32_t *u, const int64_t *acc, size_t n,
                     const int32_t *f, size_t nf)
{
    struct piezo_play p;
    assert_int_equal(piezo_play_init(&p, coef, f_buf, PIEZO_PLAY_MAX_OPS,
                                     off_buf, OFF_LEN), PIEZO_OK);
    const size_t n_ops = PIEZO_PLAY_N_OPS(coef->n_r, coef->n_a);
    for (size_t k = 0; k < n; k++) {
        /* assert_golden_i32 compares as long long: exact for int64 too */
        assert_golden_i32(name, k, piezo_play_process(&p, u[k]), acc[k]);
        for (size_t i = 0; k < nf && i < n_ops; i++) {
            assert_golden_i32(name, k * n_ops + i, piezo_play_output(&p, i), f[k * n_ops + i]);
        }
    }
}

#define BANK_CASES(bank, BANK, coef)                                              \
    static void test_##bank##_matches_golden(void **state)                        \
    {                                                                             \
        (void)state;                                                              \
        run_case(#bank " random", &(coef), golden_play_##bank##_random_u,         \
                 golden_play_##bank##_random_acc, GOLDEN_PLAY_##BANK##_RANDOM_N,  \
                 golden_play_##bank##_random_f, GOLDEN_PLAY_##BANK##_RANDOM_NF);  \
        run_case(#bank " realistic", &(coef), golden_play_##bank##_realistic_u,   \
                 golden_play_##bank##_realistic_acc,                              \
                 GOLDEN_PLAY_##BANK##_REALISTIC_N,                                \
                 golden_play_##bank##_realistic_f,                                \
                 GOLDEN_PLAY_##BANK##_REALISTIC_NF);                              \
        run_case(#bank " steps", &(coef), golden_play_##bank##_steps_u,           \
                 golden_play_##bank##_steps_acc, GOLDEN_PLAY_##BANK##_STEPS_N,    \
                 golden_play_##bank##_steps_f, GOLDEN_PLAY_##BANK##_STEPS_NF);    \
        run_case(#bank " reversals", &(coef), golden_play_##bank##_reversals_u,   \
                 golden_play_##bank##_reversals_acc,                              \
                 GOLDEN_PLAY_##BANK##_REVERSALS_N,                                \
                 golden_play_##bank##_reversals_f,                                \
                 GOLDEN_PLAY_##BANK##_REVERSALS_NF);                              \
        run_case(#bank " constant", &(coef), golden_play_##bank##_constant_u,     \
                 golden_play_##bank##_constant_acc,                               \
                 GOLDEN_PLAY_##BANK##_CONSTANT_N,                                 \
                 golden_play_##bank##_constant_f,                                 \
                 GOLDEN_PLAY_##BANK##_CONSTANT_NF);                               \
        run_case(#bank " edges", &(coef), golden_play_##bank##_edges_u,           \
                 golden_play_##bank##_edges_acc, GOLDEN_PLAY_##BANK##_EDGES_N,    \
                 golden_play_##bank##_edges_f, GOLDEN_PLAY_##BANK##_EDGES_NF);    \
    }

BANK_CASES(cpi, CPI, cpi_coef)
BANK_CASES(upi, UPI, upi_coef)
BANK_CASES(wide, WIDE, wide_coef)

/* Two instances share one coefficient set: the realistic run goes on across
 * the split without reset while a second instance runs other input in between
 * and is reset; the golden model continued from its state at the split. */
static void test_split_run_carries_state(void **state)
{
    (void)state;
    static int32_t f2[PIEZO_PLAY_MAX_OPS];
    static int64_t off2[OFF_LEN];
    struct piezo_play a;
    struct piezo_play b;
    assert_int_equal(piezo_play_init(&a, &upi_coef, f_buf, PIEZO_PLAY_MAX_OPS,
                                     off_buf, OFF_LEN), PIEZO_OK);
    assert_int_equal(piezo_play_init(&b, &upi_coef, f2, PIEZO_PLAY_MAX_OPS,
                                     off2, OFF_LEN), PIEZO_OK);
    for (size_t k = 0; k < GOLDEN_PLAY_SPLIT_HALF; k++) {
        assert_golden_i32("split block 1", k, piezo_play_process(&a, golden_play_split_u[k]),
                          golden_play_split_acc[k]);
        (void)piezo_play_process(&b, golden_play_split_u[GOLDEN_PLAY_SPLIT_N - 1u - k]);
    }
    piezo_play_reset(&b);
    for (size_t k = GOLDEN_PLAY_SPLIT_HALF; k < GOLDEN_PLAY_SPLIT_N; k++) {
        (void)piezo_play_process(&b, -golden_play_split_u[k]);
        assert_golden_i32("split block 2", k, piezo_play_process(&a, golden_play_split_u[k]),
                          golden_play_split_acc[k]);
    }
}

static void test_reset_zeroes_state(void **state)
{
    (void)state;
    struct piezo_play p;
    assert_int_equal(piezo_play_init(&p, &upi_coef, f_buf, PIEZO_PLAY_MAX_OPS,
                                     off_buf, OFF_LEN), PIEZO_OK);
    (void)piezo_play_process(&p, 30000);
    (void)piezo_play_process(&p, -30000);
    piezo_play_reset(&p);
    for (size_t k = 0; k < p.n_ops; k++) {
        assert_int_equal(piezo_play_output(&p, k), 0);
    }
    /* From reset the first sample equals the golden first sample. */
    assert_true(piezo_play_process(&p, golden_play_upi_random_u[0]) ==
                golden_play_upi_random_acc[0]);
}

static void test_init_refuses_bad_coefficients(void **state)
{
    (void)state;
    struct piezo_play p;
    int32_t r[3] = {0, 100, 200};
    int32_t a[2] = {PIEZO_Q24_ONE, PIEZO_Q24_ONE / 2};
    int32_t w[6] = {1, 2, 3, 4, 5, 6};
    struct piezo_play_coef c = {r, a, w, 3, 2};
    int32_t f[6];
    int64_t off[7]; /* 6 operators, then the 2 columns' rest counts (one word) */

    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_OK);
    assert_int_equal(piezo_play_init(NULL, &c, f, 6, off, 7), PIEZO_EINVAL);
    assert_int_equal(piezo_play_init(&p, NULL, f, 6, off, 7), PIEZO_EINVAL);
    assert_int_equal(piezo_play_init(&p, &c, NULL, 6, off, 7), PIEZO_EINVAL);
    assert_int_equal(piezo_play_init(&p, &c, f, 6, NULL, 0), PIEZO_EINVAL);
    assert_int_equal(piezo_play_init(&p, &c, f, 5, off, 7), PIEZO_ERANGE);
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 6), PIEZO_ERANGE);
    r[1] = 300; /* not ascending */
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_EORDER);
    r[1] = 200; /* equal thresholds are allowed */
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_OK);
    r[0] = -1;
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_EINVAL);
    r[0] = 0;
    r[2] = PIEZO_PLAY_WIDE_MAX_Q15 + 1;
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_EINVAL);
    r[2] = PIEZO_PLAY_WIDE_MAX_Q15;
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_OK);
    a[1] = 0;
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_EINVAL);
    a[1] = -5;
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_EINVAL);
    a[1] = 5;
    c.w_q24 = NULL;
    assert_int_equal(piezo_play_init(&p, &c, f, 6, off, 7), PIEZO_EINVAL);
    c.w_q24 = w;
    c.n_r = 129; /* 129 x 2 > PIEZO_PLAY_MAX_OPS */
    assert_int_equal(piezo_play_init(&p, &c, f, 1000, off, 1000), PIEZO_ERANGE);
    /* A classical bank needs no work array. */
    c.n_r = 3;
    c.n_a = 0;
    assert_int_equal(piezo_play_init(&p, &c, f, 3, NULL, 0), PIEZO_OK);
}

/* The branches by hand: classical play with r = 0.25 follows the issue's
 * example of the float reference, and a UPI operator's upper branch. */
static void test_branches_by_hand(void **state)
{
    (void)state;
    struct piezo_play p;
    int32_t r[1] = {8192};               /* 0.25 */
    int32_t w[1] = {PIEZO_Q24_ONE};
    int32_t a[1] = {PIEZO_Q24_ONE / 2};  /* 0.5 */
    struct piezo_play_coef c = {r, a, w, 1, 0};
    int32_t f[1];
    int64_t off[2]; /* 1 operator, then its column's rest count */
    const int32_t u[5] = {0, 16384, 32767, 16384, 0};
    const int32_t want[5] = {0, 8192, 24575, 24575, 8192};
    assert_int_equal(piezo_play_init(&p, &c, f, 1, NULL, 0), PIEZO_OK);
    for (size_t k = 0; k < 5; k++) {
        (void)piezo_play_process(&p, u[k]);
        assert_golden_i32("cpi by hand", k, piezo_play_output(&p, 0), want[k]);
    }
    c.n_a = 1; /* F = max(u - 0.25, min(0.5 (u + 0.25), F)) */
    assert_int_equal(piezo_play_init(&p, &c, f, 1, off, 2), PIEZO_OK);
    assert_true(piezo_play_process(&p, -16384) == (int64_t)-4096 * PIEZO_Q24_ONE);
    assert_int_equal(piezo_play_output(&p, 0), -4096);                    /* 0.5 (-0.5 + 0.25) */
    (void)piezo_play_process(&p, 32767);
    assert_int_equal(piezo_play_output(&p, 0), 24575);                    /* lower branch u - r */
    (void)piezo_play_process(&p, 3);
    assert_int_equal(piezo_play_output(&p, 0), 4098);                     /* 0.5 (3 + 8192) = 4097.5 -> up */
}

/* Lazy runs against the eager formula: random banks (thresholds with
 * repeats, slopes below, at and above 1, weights of both signs and full
 * range, inputs up to the wide limit) on random inputs made of monotone runs
 * of random lengths and steps, pauses and reversals every sample; every
 * operator output and the sum after every sample. */
static uint32_t lcg_state;
static uint32_t lcg(void)
{
    return piezo_test_lcg(&lcg_state) >> 8; /* 24 bits */
}

static int32_t lcg_range(int32_t lo, int32_t hi) /* [lo, hi], hi - lo < 2^24 */
{
    return lo + (int32_t)(lcg() % (uint32_t)(hi - lo + 1));
}

/* one_rounding: the unparallel upper branch as before round 17,
 * rshift_rnd(a (u + r), 24); else (the bank's) rshift_rnd(a u, 24) +
 * rshift_rnd(a r, 24). */
static void eager_step(const struct piezo_play_coef *c, int32_t *f, int32_t u, int one_rounding)
{
    const size_t n_a = c->n_a;
    for (size_t i = 0; i < c->n_r; i++) {
        for (size_t j = 0; j < (n_a ? n_a : 1u); j++) {
            const int32_t r = c->r_q15[i];
            const int64_t a = n_a ? c->a_q24[j] : 0;
            const int32_t hi = !n_a ? u + r
                             : one_rounding ? (int32_t)piezo_rshift_rnd64(a * (u + r), 24u)
                                            : (int32_t)(piezo_rshift_rnd64(a * u, 24u) + piezo_rshift_rnd64(a * r, 24u));
            const int32_t lo = u - r;
            int32_t *y = &f[i * (n_a ? n_a : 1u) + j];
            *y = *y < hi ? *y : hi;
            *y = *y > lo ? *y : lo;
        }
    }
}

static void test_runs_equal_eager_formula(void **state)
{
    (void)state;
    static int32_t r[PIEZO_PLAY_MAX_OPS], a[PIEZO_PLAY_MAX_OPS], w[PIEZO_PLAY_MAX_OPS];
    static int32_t eager[PIEZO_PLAY_MAX_OPS], eager1[PIEZO_PLAY_MAX_OPS];
    size_t n_apart = 0u;
    static const uint16_t shapes[][3] = {
        /* n_r, n_a, input span (log2 of the q15-scaled bound) */
        {10, 0, 15}, {1, 0, 20}, {40, 0, 20}, {10, 3, 15}, {16, 8, 15},
        {1, 1, 15}, {7, 5, 20}, {128, 2, 20}, {25, 10, 16},
    };
    lcg_state = 12345u;
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        const uint16_t n_r = shapes[s][0], n_a = shapes[s][1];
        const int32_t span = (int32_t)1 << shapes[s][2];
        const size_t n_ops = PIEZO_PLAY_N_OPS(n_r, n_a);
        int32_t t = 0;
        for (size_t i = 0; i < n_r; i++) {
            if (i == 0u || lcg() % 4u != 0u) { /* one in four repeats the last */
                t += lcg_range(0, span / (int32_t)n_r);
            }
            r[i] = t < span ? t : span;
        }
        for (size_t j = 0; j < n_a; j++) {
            const uint32_t pick = lcg() % 4u; /* a = 1 exactly, below, above */
            a[j] = pick == 0u ? PIEZO_Q24_ONE
                 : pick == 1u ? lcg_range(1, PIEZO_Q24_ONE - 1)
                              : lcg_range(PIEZO_Q24_ONE + 1, 4 * PIEZO_Q24_ONE);
        }
        for (size_t k = 0; k < n_ops; k++) {
            w[k] = (int32_t)(lcg() << 8 ^ lcg()); /* any int32 */
        }
        const struct piezo_play_coef c = {r, a, w, n_r, n_a};
        struct piezo_play p;
        assert_int_equal(piezo_play_init(&p, &c, f_buf, PIEZO_PLAY_MAX_OPS, off_buf,
                                         OFF_LEN), PIEZO_OK);
        memset(eager, 0, sizeof eager);
        memset(eager1, 0, sizeof eager1);
        int32_t u = 0;
        int32_t dir = 1, left = 0, step = 1;
        for (size_t k = 0; k < 2000u; k++) {
            if (left-- <= 0) { /* a new run: direction, length, step size */
                const uint32_t kind = lcg() % 8u;
                dir = lcg() % 2u ? 1 : -1;
                left = kind == 0u ? 1 : lcg_range(1, 200);
                step = kind == 1u ? 0 : kind == 2u ? lcg_range(0, span) : lcg_range(0, span / 64);
            }
            const int32_t jitter = lcg() % 16u == 0u ? -dir * lcg_range(0, 3) : 0; /* small reversals */
            int64_t next = (int64_t)u + dir * step + jitter;
            next = next > span ? span : next < -span ? -span : next;
            u = (int32_t)next;
            eager_step(&c, eager, u, 0);
            eager_step(&c, eager1, u, 1);
            int64_t want = 0;
            for (size_t q = 0; q < n_ops; q++) {
                want += (int64_t)w[q] * eager[q];
            }
            assert_golden_i32("runs: sum", s * 100000u + k, piezo_play_process(&p, u), want);
            for (size_t q = 0; q < n_ops; q++) {
                assert_golden_i32("runs: output", (s * 100000u + k) * 1000u + q,
                                  piezo_play_output(&p, q), eager[q]);
                /* round 17's rounding within one LSB of the one-rounding form */
                assert_true(eager[q] - eager1[q] <= 1 && eager1[q] - eager[q] <= 1);
                n_apart += eager[q] != eager1[q];
            }
        }
    }
    assert_true(n_apart > 0u); /* the two forms differ somewhere: the bound is tested */
}

/* The classical scan as it was before the runs (round 12: every sample scans
 * from operator 0, one multiply-add per moving operator), kept as the oracle
 * of the runs' sum: the same state (f, acc, u_prev) advanced by the formula's
 * prefix property alone. */
static int64_t cpi_scan_oracle(const struct piezo_play_coef *c, int32_t *f, int64_t acc, int32_t u_prev,
                               int32_t u)
{
    for (size_t i = 0; i < c->n_r && u != u_prev; i++) {
        const int32_t v = u > u_prev ? u - c->r_q15[i] : u + c->r_q15[i];
        const int32_t d = v - f[i];
        if (u > u_prev ? d <= 0 : d >= 0) {
            break;
        }
        f[i] = v;
        acc += (int64_t)c->w_q24[i] * d;
    }
    return acc;
}

/* The run tests' drive in [-span, span]: runs of 1-3 or 1-400 samples, still,
 * jumping (span/8 to span a sample) or creeping, with a small reversal one
 * sample in 32. */
struct walk {
    int32_t u, dir, left, step;
};

static int32_t walk_next(struct walk *w, int32_t span)
{
    if (w->left-- <= 0) {
        const uint32_t kind = lcg() % 6u;
        w->dir = lcg() % 2u ? 1 : -1;
        w->left = kind == 0u ? lcg_range(1, 3) : lcg_range(1, 400);
        w->step = kind == 1u ? 0 : kind == 2u ? lcg_range(span / 8, span) : lcg_range(1, 1 + span / 512);
    }
    const int32_t jitter = lcg() % 32u == 0u ? -w->dir * lcg_range(1, 3) : 0;
    int64_t next = (int64_t)w->u + w->dir * w->step + jitter;
    next = next > span ? span : next < -span ? -span : next;
    w->u = (int32_t)next;
    return w->u;
}

/* A random classical bank for the run tests: n_r nondecreasing thresholds in
 * [0, span] with repeats (a quarter of the steps are 0), weights at the int32
 * extremes half the time, then any int32. */
static void random_bank(int32_t *r, int32_t *w, uint16_t n_r, int32_t span)
{
    int32_t t = 0;
    for (size_t i = 0; i < n_r; i++) {
        if (i == 0u || lcg() % 4u != 0u) {
            t += lcg_range(0, span / (int32_t)n_r);
        }
        r[i] = t < span ? t : span;
    }
    for (size_t i = 0; i < n_r; i++) {
        const uint32_t pick = lcg() % 4u;
        w[i] = pick == 0u ? INT32_MAX : pick == 1u ? INT32_MIN : (int32_t)(lcg() << 8 ^ lcg());
    }
}

/* Classical banks (round 13: the last sample's run moved as one, d * run_w)
 * against the scan above and against the formula on every operator, every
 * sample: random walks of long monotone runs of small steps (the run grows
 * by a few operators a sample), of large steps, pauses, small reversals of
 * 1-3 LSB inside a run and large ones that wipe the bank; weights of both
 * signs up to the int32 limits (the run's int64 weight sum); a reset in the
 * middle of a run. Mutations that fail it: the run's sum off by one operator
 * (run_n - 1), the run kept across a reversal, the run not dropped by reset. */
static void test_classical_runs_equal_scan(void **state)
{
    (void)state;
    static int32_t r[PIEZO_PLAY_MAX_OPS], w[PIEZO_PLAY_MAX_OPS];
    static int32_t eager[PIEZO_PLAY_MAX_OPS], scan[PIEZO_PLAY_MAX_OPS];
    static const uint16_t shapes[][2] = {{10, 15}, {10, 20}, {1, 15}, {2, 16}, {32, 15}, {256, 20}};
    lcg_state = 777u;
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        const uint16_t n_r = shapes[s][0];
        const int32_t span = (int32_t)1 << shapes[s][1];
        random_bank(r, w, n_r, span);
        const struct piezo_play_coef c = {r, NULL, w, n_r, 0u};
        struct piezo_play p;
        assert_int_equal(piezo_play_init(&p, &c, f_buf, PIEZO_PLAY_MAX_OPS, NULL, 0u), PIEZO_OK);
        memset(eager, 0, sizeof eager);
        memset(scan, 0, sizeof scan);
        int64_t scan_acc = 0;
        int32_t u = 0, u_prev = 0;
        struct walk wk = {0, 1, 0, 1};
        int primed = 0;
        for (size_t k = 0; k < 20000u; k++) {
            u = walk_next(&wk, span);
            if (k == 10007u) { /* a reset in the middle of a run */
                piezo_play_reset(&p);
                memset(eager, 0, sizeof eager);
                memset(scan, 0, sizeof scan);
                scan_acc = 0;
                primed = 0;
            }
            eager_step(&c, eager, u, 0);
            if (!primed) { /* the first sample: the formula on every operator */
                memcpy(scan, eager, n_r * sizeof scan[0]);
                scan_acc = 0;
                for (size_t q = 0; q < n_r; q++) {
                    scan_acc += (int64_t)w[q] * eager[q];
                }
                primed = 1;
            } else {
                scan_acc = cpi_scan_oracle(&c, scan, scan_acc, u_prev, u);
            }
            u_prev = u;
            assert_golden_i32("classical runs: sum", s * 100000u + k, piezo_play_process(&p, u), scan_acc);
            for (size_t q = 0; q < n_r; q++) {
                assert_golden_i32("classical runs: output", (s * 100000u + k) * 1000u + q,
                                  piezo_play_output(&p, q), eager[q]);
                assert_golden_i32("classical runs: scan", (s * 100000u + k) * 1000u + q, scan[q], eager[q]);
            }
        }
    }
}

/* The classical step as this target runs it (on the Cortex-M4 the Thumb-2
 * cpi_m4, round 15) against the C step (piezo_play_process_cpi_c) from the
 * same state: the walks of test_classical_runs_equal_scan (long runs, pauses,
 * small and large reversals, weights at the int32 extremes so that the run's
 * int64 sum and d * run_w use their high words), banks of 1, 2, 9, 10, 11, 32
 * and 256 thresholds (odd and even runs for the paired stores), and every
 * field of the instance compared after every sample: the sum, each output,
 * u_prev, run_dir, run_n and run_w. On sil and sanitize both entries are the
 * C step. */
static void test_cpi_step_matches_c_step(void **state)
{
    (void)state;
    static int32_t r[PIEZO_PLAY_MAX_OPS], w[PIEZO_PLAY_MAX_OPS];
    static int32_t f_c[PIEZO_PLAY_MAX_OPS];
    static const uint16_t shapes[][2] = {{10, 15}, {9, 16}, {11, 20}, {1, 15}, {2, 16}, {32, 15}, {256, 20}};
    lcg_state = 4242u;
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        const uint16_t n_r = shapes[s][0];
        const int32_t span = (int32_t)1 << shapes[s][1];
        random_bank(r, w, n_r, span);
        const struct piezo_play_coef c = {r, NULL, w, n_r, 0u};
        struct piezo_play p, q;
        assert_int_equal(piezo_play_init(&p, &c, f_buf, PIEZO_PLAY_MAX_OPS, NULL, 0u), PIEZO_OK);
        assert_int_equal(piezo_play_init(&q, &c, f_c, PIEZO_PLAY_MAX_OPS, NULL, 0u), PIEZO_OK);
        int32_t u = 0;
        struct walk wk = {0, 1, 0, 1};
        size_t runs_kept = 0u;
        for (size_t k = 0; k < 20000u; k++) {
            u = walk_next(&wk, span);
            const size_t at = s * 100000u + k;
            runs_kept += p.run_n > 0u && p.run_dir == (u > p.u_prev_q15 ? 1 : -1) && u != p.u_prev_q15;
            assert_golden_i32("cpi step: sum", at, piezo_play_process_cpi(&p, u), piezo_play_process_cpi_c(&q, u));
            assert_golden_i32("cpi step: acc", at, p.acc_q39, q.acc_q39);
            assert_golden_i32("cpi step: u_prev", at, p.u_prev_q15, q.u_prev_q15);
            assert_golden_i32("cpi step: run_dir", at, p.run_dir, q.run_dir);
            assert_golden_i32("cpi step: run_n", at, p.run_n, q.run_n);
            assert_golden_i32("cpi step: run_w", at, p.run_w_q24, q.run_w_q24);
            for (size_t i = 0; i < n_r; i++) {
                assert_golden_i32("cpi step: output", at * 1000u + i, f_buf[i], f_c[i]);
            }
        }
        /* the walk moved runs as one often enough to test them */
        assert_true(runs_kept >= 1000u);
    }
}

/* The unparallel step as this target runs it (on the Cortex-M4 the Thumb-2
 * upi_fall_m4 and rise_m4) against the C steps (piezo_play_process_upi_c)
 * from the same state (round 16: the falling step's column state moved to
 * LDM/STM): the run tests' walks (long runs, pauses, jumps, small
 * reversals), columns of odd and even length (the falling loop's pairs),
 * slopes at exactly 1, below and above (the lower branch's choice per
 * column), weights at the int32 extremes half the time; the sum, acc,
 * u_prev and every output compared after every sample. On sil and sanitize
 * both entries are the C step. */
static void test_upi_step_matches_c_step(void **state)
{
    (void)state;
    static int32_t r[PIEZO_PLAY_MAX_OPS], a[PIEZO_PLAY_MAX_OPS], w[PIEZO_PLAY_MAX_OPS];
    static int32_t f_c[PIEZO_PLAY_MAX_OPS];
    static int64_t off_c[OFF_LEN];
    static const uint16_t shapes[][3] = {
        /* n_r, n_a, input span (log2) */
        {10, 3, 15}, {9, 3, 16}, {1, 1, 15}, {2, 4, 15}, {11, 2, 20}, {16, 8, 15}, {40, 3, 15},
    };
    lcg_state = 777u;
    for (size_t s = 0; s < sizeof shapes / sizeof shapes[0]; s++) {
        const uint16_t n_r = shapes[s][0], n_a = shapes[s][1];
        const int32_t span = (int32_t)1 << shapes[s][2];
        const size_t n_ops = PIEZO_PLAY_N_OPS(n_r, n_a);
        random_bank(r, w, n_r, span);
        for (size_t k = n_r; k < n_ops; k++) { /* the weights past the first column's */
            const uint32_t pick = lcg() % 4u;
            w[k] = pick == 0u ? INT32_MAX : pick == 1u ? INT32_MIN : (int32_t)(lcg() << 8 ^ lcg());
        }
        for (size_t j = 0; j < n_a; j++) {
            const uint32_t pick = lcg() % 3u; /* a = 1 exactly, below, above */
            a[j] = pick == 0u ? PIEZO_Q24_ONE
                 : pick == 1u ? lcg_range(1, PIEZO_Q24_ONE - 1)
                              : lcg_range(PIEZO_Q24_ONE + 1, 4 * PIEZO_Q24_ONE);
        }
        const struct piezo_play_coef c = {r, a, w, n_r, n_a};
        struct piezo_play p, q;
        assert_int_equal(piezo_play_init(&p, &c, f_buf, PIEZO_PLAY_MAX_OPS, off_buf, OFF_LEN),
                         PIEZO_OK);
        assert_int_equal(piezo_play_init(&q, &c, f_c, PIEZO_PLAY_MAX_OPS, off_c, OFF_LEN),
                         PIEZO_OK);
        struct walk wk = {0, 1, 0, 1};
        size_t falls = 0u;
        for (size_t k = 0; k < 20000u; k++) {
            const int32_t u = walk_next(&wk, span);
            const size_t at = s * 100000u + k;
            falls += u < p.u_prev_q15;
            assert_golden_i32("upi step: sum", at, piezo_play_process_upi(&p, u), piezo_play_process_upi_c(&q, u));
            assert_golden_i32("upi step: acc", at, p.acc_q39, q.acc_q39);
            assert_golden_i32("upi step: u_prev", at, p.u_prev_q15, q.u_prev_q15);
            for (size_t i = 0; i < n_ops; i++) {
                assert_golden_i32("upi step: output", at * 1000u + i, f_buf[i], f_c[i]);
            }
        }
        /* the walk fell often enough to test the falling step (2,785 to 6,724) */
        assert_true(falls >= 2000u);
    }
}

/* An unparallel bank without thresholds: nothing to update, and its work
 * array may be empty (here one past a real one, so that ASan sees a write). */
static void test_empty_upi_bank(void **state)
{
    (void)state;
    int32_t a[2] = {PIEZO_Q24_ONE / 2, 2 * PIEZO_Q24_ONE};
    int32_t r[1] = {0}, w[1] = {0}, f[1] = {0};
    int64_t wk[1] = {0};
    const struct piezo_play_coef c = {r, a, w, 0, 2};
    struct piezo_play p;
    assert_int_equal(piezo_play_init(&p, &c, f, 0, wk + 1, 0), PIEZO_OK);
    const int32_t u[6] = {0, 100, 200, -300, -400, 500};
    for (size_t k = 0; k < 6; k++) {
        assert_true(piezo_play_process(&p, u[k]) == 0);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_cpi_matches_golden),
        cmocka_unit_test(test_upi_matches_golden),
        cmocka_unit_test(test_wide_matches_golden),
        cmocka_unit_test(test_split_run_carries_state),
        cmocka_unit_test(test_reset_zeroes_state),
        cmocka_unit_test(test_init_refuses_bad_coefficients),
        cmocka_unit_test(test_branches_by_hand),
        cmocka_unit_test(test_runs_equal_eager_formula),
        cmocka_unit_test(test_classical_runs_equal_scan),
        cmocka_unit_test(test_cpi_step_matches_c_step),
        cmocka_unit_test(test_upi_step_matches_c_step),
        cmocka_unit_test(test_empty_upi_bank),
    };
    return cmocka_run_group_tests_name("play", tests, NULL, NULL);
}
