/* Helpers shared by the cmocka tests of the core. */
#ifndef PIEZO_TEST_H
#define PIEZO_TEST_H

#include <stdarg.h>
#include <stddef.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <cmocka.h>

/* cmocka 1.1.5's assert_in_range takes unsigned values and misreads negative
 * q15 numbers: compare signed values with this. */
#define assert_signed_in_range(v, lo, hi)                                          \
    do {                                                                           \
        long long v_ = (long long)(v), lo_ = (long long)(lo), hi_ = (long long)(hi); \
        if (v_ < lo_ || v_ > hi_) {                                                \
            fail_msg("%lld not in [%lld, %lld]", v_, lo_, hi_);                    \
        }                                                                          \
    } while (0)

/* Bit-exact comparison of a kernel's output against golden samples: fails on
 * the first differing sample and names it. */
#define assert_golden_i32(name, k, got, want)                                      \
    do {                                                                           \
        long long g_ = (long long)(got), w_ = (long long)(want);                   \
        if (g_ != w_) {                                                            \
            fail_msg("%s: sample %lu: C %lld, golden %lld", (name),                \
                     (unsigned long)(k), g_, w_);                                  \
        }                                                                          \
    } while (0)

/* The tests' random numbers: one step of the 32-bit linear congruential
 * generator (Numerical Recipes' constants) on *x, returning the new state.
 * Tests seed their own state, so every test's sequence is its own. */
static inline uint32_t piezo_test_lcg(uint32_t *x)
{
    *x = *x * 1664525u + 1013904223u;
    return *x;
}

#endif /* PIEZO_TEST_H */
