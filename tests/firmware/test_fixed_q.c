/* The shared fixed-point primitives against the host's fixed.py, bit for bit. */
#include "piezo_test.h"
#include "fixed_q.h"
#include "fixed_q_vectors.h"

static void test_mul_q15_q24_matches_golden(void **state)
{
    (void)state;
    for (size_t k = 0; k < GOLDEN_MUL_N; k++) {
        assert_golden_i32("mul_q15_q24", k,
                          piezo_mul_q15_q24(golden_mul_a_q15[k], golden_mul_b_q24[k]),
                          golden_mul_out_q15[k]);
    }
}

static void test_rshift_rnd_matches_golden(void **state)
{
    (void)state;
    for (size_t k = 0; k < GOLDEN_RSHIFT_N; k++) {
        assert_golden_i32("rshift_rnd64", k,
                          piezo_rshift_rnd64(golden_rshift_x[k], golden_rshift_s[k]),
                          golden_rshift_out[k]);
    }
}

static void test_rounding_ties_go_up(void **state)
{
    (void)state;
    assert_true(piezo_rshift_rnd64(-3, 1) == -1); /* -1.5 -> -1 */
    assert_true(piezo_rshift_rnd64(3, 1) == 2);   /*  1.5 ->  2 */
    assert_true(piezo_rshift_rnd32(-1, 1) == 0);  /* -0.5 ->  0 */
    assert_true(piezo_sat_q15(40000) == 32767);
    assert_true(piezo_sat_q15(-40000) == -32768);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mul_q15_q24_matches_golden),
        cmocka_unit_test(test_rshift_rnd_matches_golden),
        cmocka_unit_test(test_rounding_ties_go_up),
    };
    return cmocka_run_group_tests_name("fixed_q", tests, NULL, NULL);
}
