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

/* The Cortex-M forms (SSAT, QADD, SMLAL/SMULL in fixed_q.h) against the plain
 * int64 definitions they replace, on edge values and a pseudo-random sweep;
 * under QEMU this runs the instructions, on the host the C forms. */
static int16_t ref_sat_q15(int64_t x)
{
    return (int16_t)(x > INT16_MAX ? INT16_MAX : (x < INT16_MIN ? INT16_MIN : x));
}

static int32_t ref_sat_i32(int64_t x)
{
    return (int32_t)(x > INT32_MAX ? INT32_MAX : (x < INT32_MIN ? INT32_MIN : x));
}

static uint64_t lcg_next(uint64_t *s)
{
    *s = *s * 6364136223846793005ull + 1442695040888963407ull;
    return *s;
}

static void test_saturation_forms_match_int64(void **state)
{
    static const int64_t edge[] = {
        0, 1, -1, 32767, 32768, -32768, -32769, 65535, -65536,
        INT32_MAX, (int64_t)INT32_MAX + 1, INT32_MIN, (int64_t)INT32_MIN - 1,
        (int64_t)1 << 32, -((int64_t)1 << 32), ((int64_t)1 << 32) + 5, -((int64_t)1 << 32) + 5,
        ((int64_t)1 << 32) - 32768, INT64_MAX, INT64_MIN, INT64_MAX - 1, INT64_MIN + 1,
    };
    uint64_t seed = 12345u;
    (void)state;
    for (size_t k = 0; k < sizeof edge / sizeof edge[0]; k++) {
        assert_true(piezo_sat_q15(edge[k]) == ref_sat_q15(edge[k]));
        assert_true(piezo_sat_i32(edge[k]) == ref_sat_i32(edge[k]));
    }
    for (int k = 0; k < 20000; k++) {
        /* every magnitude: a random word shifted right by 0..63 bits */
        uint64_t w = lcg_next(&seed);
        int64_t x = (int64_t)w >> (lcg_next(&seed) >> 58);
        int32_t a = (int32_t)(uint32_t)(lcg_next(&seed) >> 32), b = (int32_t)(uint32_t)(lcg_next(&seed) >> 32);
        a >>= (lcg_next(&seed) >> 59);
        b >>= (lcg_next(&seed) >> 59);
        assert_true(piezo_sat_q15(x) == ref_sat_q15(x));
        assert_true(piezo_sat_i32(x) == ref_sat_i32(x));
        assert_true(piezo_add_sat_i32(a, b) == ref_sat_i32((int64_t)a + b));
        assert_true(piezo_mul32(a, b) == (int64_t)a * b);
        /* acc small enough that acc + a b cannot overflow */
        assert_true(piezo_mlal(x >> 2, a, b) == (x >> 2) + (int64_t)a * b);
        assert_true(piezo_mul_rshift_rnd(a, b, 15u) == piezo_rshift_rnd64((int64_t)a * b, 15u));
        assert_true(piezo_mul_rshift_rnd(a, b, 24u) == piezo_rshift_rnd64((int64_t)a * b, 24u));
        assert_true(piezo_mul_hi_rnd(a, b) == (int32_t)(((int64_t)a * b + ((int64_t)1 << 31)) >> 32));
        /* the two uses (round 17): a q15 u times a q16 gain, shift 16; a q15
         * r times a q24 gain, shift 24 */
        const int32_t q = (int16_t)(lcg_next(&seed) >> 48);
        assert_true(piezo_mul_hi_rnd(q * 65536, b) == (int32_t)piezo_rshift_rnd64((int64_t)q * b, 16u));
        assert_true(piezo_mul_hi_rnd(q * 256, b) == (int32_t)piezo_rshift_rnd64((int64_t)q * b, 24u));
    }
    /* the edges: the extremes, and ties of both signs */
    static const int32_t ea[] = {INT32_MIN, INT32_MIN, INT32_MAX, -32768 * 65536, 3 * 65536, -3 * 65536, 1, -1};
    static const int32_t eb[] = {INT32_MIN, INT32_MAX, INT32_MAX, INT32_MIN, 1 << 15, 1 << 15, INT32_MIN, INT32_MIN};
    for (size_t k = 0; k < sizeof ea / sizeof ea[0]; k++) {
        assert_true(piezo_mul_hi_rnd(ea[k], eb[k]) == (int32_t)(((int64_t)ea[k] * eb[k] + ((int64_t)1 << 31)) >> 32));
    }
    assert_true(piezo_add_sat_i32(INT32_MAX, 1) == INT32_MAX);
    assert_true(piezo_add_sat_i32(INT32_MIN, -1) == INT32_MIN);
}

/* piezo_sat_q15_rnd24 (SSAT of the high word, then of the shifted word)
 * against the clamp of the rounded int64 shift: every magnitude, the q15
 * limits and the high word's clamp edges (H = 255, 256, -256, -257), ties of
 * both signs. |x| < 2^62: the callers' sums, and x + 2^23 cannot overflow. */
static int16_t ref_sat_q15_rnd24(int64_t x)
{
    return ref_sat_q15((x + ((int64_t)1 << 23)) >> 24);
}

static void test_sat_q15_rnd24_matches_int64(void **state)
{
    uint64_t seed = 777u;
    (void)state;
    static const int64_t q[] = {0, 1, -1, 32767, 32768, -32768, -32769, 65279, 65280, 65535, 65536,
                                -65280, -65281, -65536, -65537, 1 << 20, -(1 << 20),
                                (int64_t)1 << 37, -((int64_t)1 << 37)};
    for (size_t k = 0; k < sizeof q / sizeof q[0]; k++) {
        for (int64_t d = -((int64_t)1 << 23) - 1; d <= ((int64_t)1 << 23) + 1; d += ((int64_t)1 << 23) / 2) {
            const int64_t x = q[k] * ((int64_t)1 << 24) + d;
            assert_true(piezo_sat_q15_rnd24(x) == ref_sat_q15_rnd24(x));
        }
    }
    for (int64_t hword = -300; hword <= 300; hword++) {
        for (uint32_t lo = 0u; lo < 16u; lo++) {
            const int64_t x = (int64_t)((uint64_t)hword << 32) + (int64_t)(lo * 0x11111111u);
            assert_true(piezo_sat_q15_rnd24(x) == ref_sat_q15_rnd24(x));
        }
    }
    for (int k = 0; k < 20000; k++) {
        const int64_t x = (int64_t)lcg_next(&seed) >> (2u + (lcg_next(&seed) >> 58) % 62u);
        assert_true(piezo_sat_q15_rnd24(x) == ref_sat_q15_rnd24(x));
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_mul_q15_q24_matches_golden),
        cmocka_unit_test(test_rshift_rnd_matches_golden),
        cmocka_unit_test(test_rounding_ties_go_up),
        cmocka_unit_test(test_saturation_forms_match_int64),
        cmocka_unit_test(test_sat_q15_rnd24_matches_int64),
    };
    return cmocka_run_group_tests_name("fixed_q", tests, NULL, NULL);
}
