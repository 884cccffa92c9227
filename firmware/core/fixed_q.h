/*
 * fixed_q.h - the fixed-point primitives every core kernel uses.
 *
 * Formats (see docs/fixed-point.md; the names match common/interface.toml):
 *   q15  int16_t,  Q0.15: signals normalized to full scale, [-1, 1 - 2^-15].
 *   q24  int32_t,  Q7.24: gains, weights, densities, polynomial coefficients,
 *                  [-128, 128 - 2^-24].
 *   q16  int32_t, Q15.16: slopes and scales, [-32768, 32768 - 2^-16].
 *   accumulators   int64_t, sized per kernel so that they cannot overflow.
 *
 * The one rounding rule: a right shift by s > 0 bits adds 2^(s-1) first and
 * then shifts arithmetically (floor), i.e. round half toward +infinity.
 * host/piezoctl/fixed.py implements the identical rule ((x + (1 << (s-1))) >> s
 * on Python integers) and the golden-vector tests prove the two bit for bit.
 *
 * Saturation: a value stored as a signal is clamped to the q15 range by
 * piezo_sat_q15(); nothing else saturates silently.
 */
#ifndef PIEZO_FIXED_Q_H
#define PIEZO_FIXED_Q_H

#include <stdint.h>

#define PIEZO_Q15_MAX INT16_MAX
#define PIEZO_Q15_MIN INT16_MIN
#define PIEZO_Q15_ONE 32768L      /* 1.0 in q15 (not representable in int16_t) */
#define PIEZO_Q24_ONE 16777216L   /* 1.0 in q24 */
#define PIEZO_Q16_ONE 65536L      /* 1.0 in q16 */

/* The rounding rule relies on >> of a negative signed value being an
 * arithmetic (floor) shift. C99 leaves it implementation-defined; every
 * compiler we build with (gcc, clang, arm-none-eabi-gcc) shifts arithmetically,
 * and this refuses to compile anywhere that does not. */
typedef char piezo_arith_shift_check_t[((-3L >> 1) == -2L) ? 1 : -1];

/** Round-half-up right shift of a 64-bit value by s bits (1 <= s <= 62). */
static inline int64_t piezo_rshift_rnd64(int64_t x, unsigned s)
{
    return (x + ((int64_t)1 << (s - 1u))) >> s;
}

/** Round-half-up right shift of a 32-bit value by s bits (1 <= s <= 30). */
static inline int32_t piezo_rshift_rnd32(int32_t x, unsigned s)
{
    return (int32_t)(((int64_t)x + ((int64_t)1 << (s - 1u))) >> s);
}

/** Clamp a wide value to the q15 range.
 *
 * On a core with the saturating instructions (Cortex-M4: __ARM_FEATURE_SAT) the
 * same function in fewer instructions: x lies in the int32 range iff its high
 * word is the sign of its low word, and then SSAT #16 clamps the low word
 * exactly as the comparisons below do; outside the int32 range the sign of the
 * high word picks the limit. The result is the same for every x (the
 * golden-vector tests run on both builds). */
static inline int16_t piezo_sat_q15(int64_t x)
{
#if defined(__ARM_FEATURE_SAT)
    const int32_t lo = (int32_t)x, hi = (int32_t)(x >> 32);
    if (__builtin_expect(hi == (lo >> 31), 1)) {
        return (int16_t)(int32_t)__builtin_arm_ssat(lo, 16u); /* SSAT #16 */
    }
    return hi < 0 ? PIEZO_Q15_MIN : PIEZO_Q15_MAX;
#else
    if (x > PIEZO_Q15_MAX) {
        return PIEZO_Q15_MAX;
    }
    if (x < PIEZO_Q15_MIN) {
        return PIEZO_Q15_MIN;
    }
    return (int16_t)x;
#endif
}

/** piezo_sat_q15(piezo_rshift_rnd64(x, 24)): a Q39 (or q24 x q15) sum
 * rounded to q15 and clamped, for every int64 x.
 *
 * With SSAT (round 17, 2 instructions fewer than the general form's range
 * test and branch): y = x + 2^23 = H 2^32 + L, and y >> 24 = H 2^8 + (L >> 24)
 * with L >> 24 in [0, 255]. H clamped to [-256, 255] (SSAT #9) leaves the
 * value exact when H is in that range (|y >> 24| < 2^16 then, no int32
 * overflow), and otherwise leaves it beyond the q15 range on the same side
 * (>= 255 2^8 > 32767, or <= -2^16 + 255 < -32768), so SSAT #16 of it gives
 * the same limit as the clamp of the true value. */
static inline int16_t piezo_sat_q15_rnd24(int64_t x)
{
#if defined(__ARM_FEATURE_SAT)
    const int64_t y = x + ((int64_t)1 << 23);
    const int32_t hs = (int32_t)__builtin_arm_ssat((int32_t)(y >> 32), 9u);
    const uint32_t v = ((uint32_t)hs << 8) | ((uint32_t)y >> 24);
    return (int16_t)(int32_t)__builtin_arm_ssat((int32_t)v, 16u);
#else
    return piezo_sat_q15(piezo_rshift_rnd64(x, 24u));
#endif
}

/** acc + a * b in int64 (|a * b| <= 2^62; the caller keeps the sum in
 * range, as for the C expression), one SMLAL on Thumb-2.
 *
 * gcc -O2 forms a 64 x 64 multiply (mul, mla, umull, add) for (int64_t)a * b
 * when it already holds the sign extension of a or b from an earlier product
 * in the same function; the instruction here keeps it one 32 x 32 -> 64
 * multiply. Same value as the C expression on every build (the C expression
 * where there is no Thumb-2; the golden-vector tests run on both). */
static inline int64_t piezo_mlal(int64_t acc, int32_t a, int32_t b)
{
#if defined(__thumb2__) && defined(__GNUC__)
    __asm__("smlal %Q0, %R0, %1, %2" : "+r"(acc) : "r"(a), "r"(b));
    return acc;
#else
    return acc + (int64_t)a * b;
#endif
}

/** a * b in int64 with one SMULL on Thumb-2 (see piezo_mlal). */
static inline int64_t piezo_mul32(int32_t a, int32_t b)
{
#if defined(__thumb2__) && defined(__GNUC__)
    int64_t p;
    __asm__("smull %Q0, %R0, %1, %2" : "=r"(p) : "r"(a), "r"(b));
    return p;
#else
    return (int64_t)a * b;
#endif
}

/** piezo_rshift_rnd64((int64_t)a * b, s) with the product by piezo_mul32
 * (one SMULL on Thumb-2; an SMLAL onto the rounding constant needs the
 * constant copied into the accumulator's registers first). */
static inline int64_t piezo_mul_rshift_rnd(int32_t a, int32_t b, unsigned s)
{
    return piezo_rshift_rnd64(piezo_mul32(a, b), s);
}

/** piezo_rshift_rnd64((int64_t)a * b, 32): the rounded high word of a 32 x
 * 32 product, one SMMULR on the Cortex-M4 (round 17). With a = x 2^(32 - s)
 * for an x that fits so shifted (a q15 x and s >= 16, or s = 24 and
 * |x| <= 2^23) it is piezo_rshift_rnd64(x b, s) exactly, in 2 instructions
 * where the 64-bit form sets up the rounding constant, an SMLAL and a
 * shift of the word pair (5). */
static inline int32_t piezo_mul_hi_rnd(int32_t a, int32_t b)
{
#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__) && defined(__GNUC__)
    int32_t hi;
    __asm__("smmulr %0, %1, %2" : "=r"(hi) : "r"(a), "r"(b));
    return hi;
#else
    return (int32_t)piezo_rshift_rnd64((int64_t)a * b, 32u);
#endif
}

/** c + piezo_mul_hi_rnd(a, b), one SMMLAR on the Cortex-M4 (round 18: the
 * Horner step's add folded into the multiply; the core forms c 2^32 + a b
 * + 2^31 in 64 bits, so the sum is exact; the caller keeps it in int32). */
static inline int32_t piezo_mul_hi_rnd_add(int32_t a, int32_t b, int32_t c)
{
#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__) && defined(__GNUC__)
    int32_t r;
    __asm__("smmlar %0, %1, %2, %3" : "=r"(r) : "r"(a), "r"(b), "r"(c));
    return r;
#else
    return c + (int32_t)piezo_rshift_rnd64((int64_t)a * b, 32u);
#endif
}

/** Clamp a wide value to the int32 range (q24, q16 intermediates). */
static inline int32_t piezo_sat_i32(int64_t x)
{
    /* x lies in the int32 range iff its high word is the sign of its low
     * word (one compare instead of two 64-bit ones); else the high word's
     * sign picks the limit. (int32_t) keeps the low word (gcc, clang). */
    const int32_t lo = (int32_t)x, hi = (int32_t)(x >> 32);
    if (hi == (lo >> 31)) {
        return lo;
    }
    return hi < 0 ? INT32_MIN : INT32_MAX;
}

/** a + b clamped to the int32 range: piezo_sat_i32((int64_t)a + b), one QADD
 * on a core with the DSP instructions (Cortex-M4: __ARM_FEATURE_DSP; it sets
 * the sticky Q flag, which nothing here reads). */
static inline int32_t piezo_add_sat_i32(int32_t a, int32_t b)
{
#if defined(__ARM_FEATURE_DSP) && defined(__GNUC__)
    return (int32_t)__builtin_arm_qadd(a, b);
#else
    return piezo_sat_i32((int64_t)a + b);
#endif
}

/** q15 * q24 -> q15 with the rounding rule and saturation. */
static inline int16_t piezo_mul_q15_q24(int32_t a_q15, int32_t b_q24)
{
    return piezo_sat_q15(piezo_rshift_rnd64((int64_t)a_q15 * b_q24, 24u));
}

static inline int32_t piezo_max_i32(int32_t a, int32_t b) { return a > b ? a : b; }
static inline int32_t piezo_min_i32(int32_t a, int32_t b) { return a < b ? a : b; }

#endif /* PIEZO_FIXED_Q_H */
