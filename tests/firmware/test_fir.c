/* The dynamics-inverse FIR (fir.h) against its golden model (piezoctl.golden.fir):
 * random references and taps, every spacing, full-scale taps and inputs that
 * saturate both ways, rounding ties; run in two halves to prove the history
 * carries over. */
#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <cmocka.h>

#include "fir.h"
#include "piezo_err.h"
#include "fir_vectors.h"

static void test_fir_matches_golden(void **state)
{
    (void)state;
    for (uint32_t c = 0; c < GOLDEN_FIR_CASES; c++) {
        piezo_fir_coef_t k = {0};
        piezo_fir_t f;
        uint32_t lo = golden_fir_x_off[c], hi = golden_fir_x_off[c + 1u];
        k.n_taps = golden_fir_n_taps[c];
        k.spacing = golden_fir_spacing[c];
        for (uint32_t t = 0; t < PIEZO_FIR_MAX_TAPS; t++) {
            k.h_q13[t] = golden_fir_h_q13[c * PIEZO_FIR_MAX_TAPS + t];
        }
        assert_int_equal(piezo_fir_check(&k), PIEZO_OK);
        piezo_fir_reset(&f, golden_fir_x_q15[lo]);
        for (uint32_t i = lo; i < hi; i++) {
            int16_t y = piezo_fir_q13_process(&f, &k, golden_fir_x_q15[i]);
            if (y != golden_fir_y_q15[i]) {
                fail_msg("case %u sample %u: %d, golden %d", (unsigned)c, (unsigned)(i - lo), y,
                         golden_fir_y_q15[i]);
            }
        }
    }
}

static void test_fir_saturates_and_unity(void **state)
{
    piezo_fir_coef_t k = {0};
    piezo_fir_t f;
    (void)state;
    k.n_taps = 1;
    k.spacing = 1;
    k.h_q13[0] = 8192; /* identity */
    piezo_fir_reset(&f, 0);
    assert_int_equal(piezo_fir_q13_process(&f, &k, -32768), -32768);
    assert_int_equal(piezo_fir_q13_process(&f, &k, 1234), 1234);
    k.h_q13[0] = 16384; /* gain 2: clamps */
    assert_int_equal(piezo_fir_q13_process(&f, &k, 20000), 32767);
    assert_int_equal(piezo_fir_q13_process(&f, &k, -20000), -32768);
}

static void test_fir_check_refuses(void **state)
{
    piezo_fir_coef_t k = {0};
    (void)state;
    k.n_taps = PIEZO_FIR_MAX_TAPS;
    k.spacing = PIEZO_FIR_MAX_SPACING;
    assert_int_equal(piezo_fir_check(&k), PIEZO_OK);
    k.n_taps = PIEZO_FIR_MAX_TAPS + 1u;
    assert_int_equal(piezo_fir_check(&k), PIEZO_EINVAL);
    k.n_taps = 1;
    k.spacing = PIEZO_FIR_MAX_SPACING + 1u;
    assert_int_equal(piezo_fir_check(&k), PIEZO_EINVAL);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_fir_matches_golden),
        cmocka_unit_test(test_fir_saturates_and_unity),
        cmocka_unit_test(test_fir_check_refuses),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
