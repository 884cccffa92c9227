/* The RKP kind through piezo_ff_process (coefset.c): the feedforward's tick
 * for an rkp table equals the RKP kernel called directly (its output checked
 * against the golden vectors of host/piezoctl/golden/rkp.py) feeding its
 * density to a DCC instance of its own, bit for bit, every tick. No other
 * test ran this branch: making it unreachable passed every test (round 14). */
#include <string.h>

#include "piezo_test.h"
#include "coefset.h"
#include "piezo_interface.h"
#include "rkp_vectors.h"

static piezo_coefset_t cs;   /* large: not on the stack */
static piezo_ff_state_t ff;

/* The reference: the kernels as the RKP kind's tick is documented
 * (coefset.h): the density of this tick, then the DCC law with it. */
static struct piezo_rkp ref_rkp;
static struct piezo_dcc ref_dcc;
static struct piezo_dcc_coeffs ref_dcc_c;
static int16_t ref_psi[PIEZO_CS_MAX_RKP_OPS];
static int32_t ref_w[PIEZO_CS_MAX_RKP_OPS];
static int32_t ref_cpsi[PIEZO_CS_MAX_RKP_OPS], ref_zo[PIEZO_CS_MAX_RKP_OPS];

#define G_Q24 (3 << 23)         /* 1.5: not 1, so a lost gain shows */
#define Y_GAIN_Q24 (7 << 21)    /* 0.875 */
#define Y_OFFSET_Q15 (-1200)
#define OL_GAIN_Q24 (1 << 24)   /* the open-loop line, what an unknown kind plays */

static void setup_rkp_set(void)
{
    static const struct piezo_kp_grid grid = {.n1_q15 = rkp_std_n1, .n2_q15 = rkp_std_n2, .n_ops = rkp_std_NOPS,
                                              .nmin_q15 = rkp_std_NMIN, .rmax_q15 = rkp_std_RMAX,
                                              .slope_q16 = rkp_std_SLOPE, .xsat_q15 = rkp_std_XSAT};
    memset(&cs, 0, sizeof cs);
    assert_true(rkp_std_NOPS <= PIEZO_CS_MAX_RKP_OPS && rkp_std_NRBF <= PIEZO_CS_MAX_RBF);
    cs.kind = PIEZO_TABLE_KIND_RKP;
    cs.open_loop_gain_q24 = OL_GAIN_Q24;
    cs.open_loop_offset_q15 = 0;
    cs.y_to_u_gain_q24 = Y_GAIN_Q24;
    cs.y_offset_q15 = Y_OFFSET_Q15;
    cs.rkp.grid = grid;
    cs.rkp.theta_q24 = rkp_std_theta;
    cs.rkp.center_q24 = rkp_std_center;
    cs.rkp.inv_width_q16 = rkp_std_inv_width;
    cs.rkp.n_rbf = rkp_std_NRBF;
    cs.rkp.alpha_q16 = rkp_std_ALPHA;
    cs.dcc.grid = grid;
    cs.dcc.g_q24 = G_Q24;
    cs.dcc.c_q24 = cs.c_q24; /* replaced by the state's density in piezo_ff_bind */
    assert_int_equal(piezo_ff_bind(&ff, &cs), PIEZO_OK);

    ref_dcc_c = cs.dcc;
    ref_dcc_c.c_q24 = ref_w;
    assert_int_equal(piezo_rkp_init(&ref_rkp, &cs.rkp, ref_psi, ref_w, PIEZO_CS_MAX_RKP_OPS), PIEZO_OK);
    assert_int_equal(piezo_dcc_init(&ref_dcc, &ref_dcc_c, ref_cpsi, ref_zo, PIEZO_CS_MAX_RKP_OPS), PIEZO_OK);
}

/* Every golden input of the standard set as the applied drive, a shifted
 * copy as the reference r: the output, the density and the operators agree
 * with the kernels called directly every tick, and the output is neither the
 * open-loop line nor the DCC with the density left at zero. */
static void test_rkp_kind_matches_kernels(void **state)
{
    (void)state;
#define RKP_STD_CASE(name, set) {rkp_case_##name##_u, rkp_case_##name##_y, sizeof rkp_case_##name##_u / sizeof(int16_t), #set},
    static const struct {
        const int16_t *u, *y;
        size_t n;
        const char *set;
    } cases[] = {RKP_GOLDEN_CASES(RKP_STD_CASE)};
    size_t ticks = 0, off_line = 0, moved_w = 0;
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        if (strcmp(cases[i].set, "rkp_std") != 0) {
            continue;
        }
        setup_rkp_set();
        for (size_t k = 0; k < cases[i].n; k++) {
            const int16_t u = cases[i].u[k];
            const int16_t r = cases[i].u[(k + 7u) % cases[i].n];
            const int16_t got = piezo_ff_process(&ff, &cs, r, u);
            /* the reference */
            assert_golden_i32("rkp direct", k, piezo_rkp_process(&ref_rkp, u), cases[i].y[k]);
            ref_dcc.u_last_q15 = u;
            const int16_t want = piezo_dcc_process(&ref_dcc, piezo_line_q15(r, Y_GAIN_Q24, Y_OFFSET_Q15));
            assert_golden_i32("piezo_ff_process rkp", k, got, want);
            for (uint16_t j = 0; j < rkp_std_NOPS; j++) {
                assert_golden_i32("density w", j, ff.w_q24[j], ref_w[j]);
                assert_golden_i32("rkp psi", j, ff.psi_q15[j], ref_psi[j]);
                assert_golden_i32("dcc psi", j, ff.dcc.psi_q15[j], ref_dcc.psi_q15[j]);
                moved_w += ref_w[j] != 0;
            }
            off_line += got != piezo_line_q15(r, OL_GAIN_Q24, 0);
            ticks++;
        }
    }
    printf("rkp kind: %zu ticks, %zu off the open-loop line, %zu nonzero weights seen\n", ticks, off_line, moved_w);
    assert_true(ticks >= 1000u);
    assert_true(off_line > ticks / 2u); /* not the open-loop line */
    assert_true(moved_w > ticks);       /* the density is not zero */
}

/* The DCC kind through piezo_ff_process (Thumb-2 on the Cortex-M4 since
 * round 17): the output and the operators equal the DCC kernel called
 * directly with the same line and the same applied drive, every tick. The
 * applied drive is not the law's last output (a golden input sequence), so
 * a lost u_last store shows: the law's own store makes them equal otherwise. */
static void test_dcc_kind_matches_kernel(void **state)
{
    (void)state;
    size_t ticks = 0, applied_differs = 0;
    setup_rkp_set(); /* the grid, the line */
    cs.kind = PIEZO_TABLE_KIND_KP_DCC;
    for (uint16_t j = 0; j < rkp_std_NOPS; j++) {
        cs.c_q24[j] = (int32_t)((j * 7919u) % 40000u) + 2000; /* positive, distinct */
    }
    cs.dcc.c_q24 = cs.c_q24;
    assert_int_equal(piezo_ff_bind(&ff, &cs), PIEZO_OK);
    ref_dcc_c = cs.dcc;
    assert_int_equal(piezo_dcc_init(&ref_dcc, &ref_dcc_c, ref_cpsi, ref_zo, PIEZO_CS_MAX_RKP_OPS), PIEZO_OK);
    piezo_dcc_const_weights(&ref_dcc);
    int16_t last = 0;
    for (size_t k = 0; k < sizeof rkp_case_random_u / sizeof rkp_case_random_u[0]; k++) {
        const size_t n = sizeof rkp_case_random_u / sizeof rkp_case_random_u[0];
        const int16_t u = rkp_case_random_u[k];
        const int16_t r = rkp_case_random_u[(k + 7u) % n];
        const int16_t got = piezo_ff_process(&ff, &cs, r, u);
        ref_dcc.u_last_q15 = u;
        const int16_t want = piezo_dcc_process(&ref_dcc, piezo_line_q15(r, Y_GAIN_Q24, Y_OFFSET_Q15));
        assert_golden_i32("piezo_ff_process dcc", k, got, want);
        for (uint16_t j = 0; j < rkp_std_NOPS; j++) {
            assert_golden_i32("dcc psi", j, ff.dcc.psi_q15[j], ref_dcc.psi_q15[j]);
        }
        applied_differs += u != last;
        last = got;
        ticks++;
    }
    printf("dcc kind: %zu ticks, applied drive not the last output on %zu\n", ticks, applied_differs);
    assert_true(ticks >= 100u);
    assert_true(applied_differs > ticks / 2u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_rkp_kind_matches_kernels),
        cmocka_unit_test(test_dcc_kind_matches_kernel),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
