/* A bank of CPI/UPI play operators and their weighted sum (see play.h). */
#include "play.h"

#include <stddef.h>
#include <string.h>

#include "fixed_q.h"

/*
 * The upper branch hi_ij(u) = A_j(u) + c_ij with A_j(u) = rshift_rnd(a_j u, 24)
 * (one rounding per slope and sample) and c_ij = rshift_rnd(a_j r_i, 24)
 * (init). The constants are q15 integers, |c| < 2^27 (a < 2^31, r <= 2^20),
 * stored in the caller's int64 work array (by memcpy; the Thumb-2 steps
 * read them as int32), column by column, each beside its operator's weight
 * (round 17, second part): word k = j * n_r + i holds c_ij in its first four
 * bytes and a copy of w_ij (coef->w_q24[i n_a + j]) in its last four, so
 * that the falling step reads a pair of operators' constants and weights
 * by one LDM (no strided weight pointer).
 */
static inline int32_t c_get(const int64_t *c2, size_t k)
{
    int32_t v; /* through memcpy: the words are int64 objects (one LDR on the M4) */
    memcpy(&v, (const unsigned char *)c2 + k * 2u * sizeof v, sizeof v);
    return v;
}

static inline void c_set(int64_t *c2, size_t k, int32_t v)
{
    memcpy((unsigned char *)c2 + k * 2u * sizeof v, &v, sizeof v);
}

static inline void cw_set(int64_t *c2, size_t k, int32_t w)
{
    memcpy((unsigned char *)c2 + (k * 2u + 1u) * sizeof w, &w, sizeof w);
}

/* A_j(u) = rshift_rnd(a_j u, 24): |a u| < 2^31 * 2^20, so |A| < 2^27. */
static inline int32_t upper_a(int32_t a_q24, int32_t u_q15)
{
    return (int32_t)piezo_rshift_rnd64((int64_t)a_q24 * u_q15, 24u);
}

int piezo_play_init(struct piezo_play *p, const struct piezo_play_coef *coef,
                    int32_t *f_q15, size_t f_len, int64_t *work, size_t work_len)
{
    if (p == NULL || coef == NULL || f_q15 == NULL) {
        return PIEZO_EINVAL;
    }
    const size_t n_ops = PIEZO_PLAY_N_OPS(coef->n_r, coef->n_a);
    if (n_ops > PIEZO_PLAY_MAX_OPS || f_len < n_ops) {
        return PIEZO_ERANGE;
    }
    if (n_ops > 0u && (coef->r_q15 == NULL || coef->w_q24 == NULL)) {
        return PIEZO_EINVAL;
    }
    if (coef->n_a > 0u) {
        if (coef->a_q24 == NULL || work == NULL) {
            return PIEZO_EINVAL;
        }
        if (work_len < PIEZO_PLAY_WORK_LEN(coef->n_r, coef->n_a)) {
            return PIEZO_ERANGE;
        }
        for (size_t j = 0; j < coef->n_a; j++) {
            if (coef->a_q24[j] <= 0) {
                return PIEZO_EINVAL;
            }
        }
    }
    for (size_t i = 0; i < coef->n_r; i++) {
        const int32_t r = coef->r_q15[i];
        if (r < 0 || r > PIEZO_PLAY_WIDE_MAX_Q15) {
            return PIEZO_EINVAL;
        }
        if (i > 0u && r < coef->r_q15[i - 1u]) {
            return PIEZO_EORDER;
        }
    }
    p->coef = coef;
    p->f_q15 = f_q15;
    p->c2_q15 = coef->n_a > 0u ? work : NULL;
    p->n_ops = n_ops;
    /* Constants of the upper branch, c_ij = rshift_rnd(a_j r_i, 24) (q15),
     * column by column: constant j * n_r + i (c_get), each with its weight */
    for (size_t i = 0; i < coef->n_r && coef->n_a > 0u; i++) {
        for (size_t j = 0; j < coef->n_a; j++) {
            c_set(work, j * coef->n_r + i,
                  (int32_t)piezo_rshift_rnd64((int64_t)coef->a_q24[j] * coef->r_q15[i], 24u));
            cw_set(work, j * coef->n_r + i, coef->w_q24[i * coef->n_a + j]);
        }
    }
    piezo_play_reset(p);
    return PIEZO_OK;
}

void piezo_play_reset(struct piezo_play *p)
{
    for (size_t k = 0; k < p->n_ops; k++) {
        p->f_q15[k] = 0;
    }
    p->acc_q39 = 0;
    p->u_prev_q15 = 0;
    p->primed = 0u;
    p->run_dir = 0;
    p->run_n = 0u;
    p->run_w_q24 = 0;
}

/* The formula on every operator, the sum from scratch (first sample). */
static int64_t play_full(struct piezo_play *p, int32_t u_q15)
{
    const struct piezo_play_coef *c = p->coef;
    const int32_t *r = c->r_q15;
    const int32_t *w = c->w_q24;
    int32_t *f = p->f_q15;
    const size_t n_a = c->n_a, n_r = c->n_r;
    int64_t acc = 0;
    if (n_a == 0u) {
        for (size_t i = 0; i < n_r; i++) {
            const int32_t lo = u_q15 - r[i];
            const int32_t hi = u_q15 + r[i];
            int32_t y = f[i];
            y = y < hi ? y : hi;
            y = y > lo ? y : lo;
            f[i] = y;
            acc += (int64_t)w[i] * y;
        }
        return acc;
    }
    for (size_t j = 0; j < n_a; j++) {
        const int32_t au = upper_a(c->a_q24[j], u_q15);
        int32_t *fc = f + j * n_r; /* column j, outputs column by column */
        for (size_t i = 0, k = j; i < n_r; i++, k += n_a) {
            const int32_t hi = au + c_get(p->c2_q15, j * n_r + i);
            const int32_t lo = u_q15 - r[i];
            int32_t y = fc[i];
            y = y < hi ? y : hi;
            y = y > lo ? y : lo;
            fc[i] = y;
            acc += (int64_t)w[k] * y;
        }
    }
    return acc;
}

/*
 * The unparallel bank falling: for each slope (column) a_j, from the
 * column's first threshold, F moves iff F >= hi = A_j(u) + c_ij (A_j once
 * per column), to max(u - r, hi), or to hi where the lower branch cannot win
 * (a <= 1 and u <= 0, or a >= 1 and u >= 0: each rounding is above its
 * value less 1/2, so u - r - hi < u (1 - a) - r (1 + a) + 1, an integer
 * below 1); the scan stops at the first F < hi. Returns acc plus the sum of
 * w (F_new - F_old). F == hi goes through the update too: F >= u - r while
 * falling, so then max(hi, u - r) == F and nothing changes.
 */
#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/* Cortex-M4: the column loop in Thumb-2 (upi_fall_m4 below), the same
 * integers as the C loop that other targets compile; test_play (random
 * banks of odd and even sizes against the formula on every operator) and
 * the golden vectors of test_eupi and test_eupi_inv check it under QEMU.
 * gcc's C spends 14 instructions per moving operator on the upper branch
 * (it splits the constant's ldrd and counts separately) and 19 with the
 * lower one, and spills the column loop's pointers; here 11 (two operators
 * per pass; the break tested on the sign of the step it stores) and 17
 * with the lower branch, but only over the column's lower-branch prefix:
 * g_i = (u - r_i) - hi_i is non-increasing in i (r_{i+1} - r_i = D >= 0
 * raises hi by c_{i+1} - c_i >= 0, so g falls by at least D), so once
 * the upper branch wins (u - r < hi) it wins for the rest of the column,
 * which the upper-branch loop finishes at 11 (round 13), 10.5 since round
 * 14 (a pass's two weights are read at wp and wp + stride and wp steps
 * once by two strides; wp is reloaded per column), 8 since round 17 (hi =
 * A_j + c: one add instead of the carry add; the pair's two constants, its
 * two outputs and, when both move, its two stores by one LDRD or STRD; an
 * odd count takes one operator first).
 * The column state lives in the caller's struct (the constants'
 * column found from the outputs' by one add). A loop alone
 * in assembly inside the C function costs more in spills than it saves. */
struct upi_fall_args {   /* the column loop's state, on upi_fall_m4's stack */
    uintptr_t c_f;       /* 0: c - 2 f (addresses): a column's pairs start at c_f + 2 fp */
    int32_t *f;          /* 4: the column's outputs (column by column); updated per column */
    uint32_t f_step;     /* 8: n_r * 4, bytes of a column of outputs */
    int32_t u_8;         /* 12: u 2^8, SMMULR's operand */
    int32_t k;           /* 16: the lower branch's test constant K */
    const int32_t *r;    /* 20: thresholds */
    const int32_t *a_end;/* 24: one past the last slope (round 18: after r, */
                         /* so that r, loaded by the coefficients' LDM into */
                         /* r8, is stored below it by the set-up's STM) */
    uint32_t pad;        /* 28: p sits at 32 */
};
/* the first five words in one LDM per column, the set-up's seven in one STM
 * (round 16: 15 -> 10 per column, 24 -> 20 to enter; round 17: the slope's
 * pointer kept in r10, u 2^8 and K loaded with the rest; the weights with
 * the constants, no weight pointer per column) */
typedef char piezo_upi_fall_args_layout_check_t[(offsetof(struct upi_fall_args, u_8) == 12u &&
                                                 offsetof(struct upi_fall_args, r) == 20u &&
                                                 offsetof(struct upi_fall_args, a_end) == 24u &&
                                                 sizeof(struct upi_fall_args) == 32u) ? 1 : -1];
/* upi_fall_m4 reads n_r and n_a as one word and takes a_end = a + 4 n_a
 * from it by one shift (lsr #14): exact while n_r < 2^14 (n_r <= n_ops) */
typedef char piezo_upi_fall_n_r_bits_check_t[(PIEZO_PLAY_MAX_OPS < (1u << 14)) ? 1 : -1];
/* upi_fall_m4 and rise_m4 read the instance and its coefficients directly */
typedef char piezo_play_layout_check_t[(offsetof(struct piezo_play, coef) == 0u &&
                                        offsetof(struct piezo_play, f_q15) == 4u &&
                                        offsetof(struct piezo_play, c2_q15) == 8u &&
                                        offsetof(struct piezo_play, n_ops) == 12u &&
                                        offsetof(struct piezo_play, acc_q39) == 16u &&
                                        offsetof(struct piezo_play, u_prev_q15) == 24u &&
                                        offsetof(struct piezo_play_coef, r_q15) == 0u &&
                                        offsetof(struct piezo_play_coef, a_q24) == 4u &&
                                        offsetof(struct piezo_play_coef, w_q24) == 8u &&
                                        offsetof(struct piezo_play_coef, n_r) == 12u &&
                                        offsetof(struct piezo_play_coef, n_a) == 14u) ? 1 : -1];

static __attribute__((naked, noinline, used)) int64_t upi_fall_m4(struct piezo_play *p)
{
    (void)p;
    /* r1 cp (the pairs (c_ij, w_ij), int32 each), r2 fp, r3 the column's
     * end of fp, r6 A_j = rshift_rnd(a_j u, 24), r8:r9 acc, r10 &a_j (then
     * the next slope's), r4 r5 r7 r11 r12 scratch, lr u, r0 the thresholds
     * in the lower-branch loop; the column state at [sp] */
    __asm__ volatile(
        "    push   {r0, r4-r11, lr}\n"       /* p at [sp, #32] once the state is below it */
        "    sub    sp, #32\n"                /* the column state at [sp] (upi_fall_args) */
        "    mov    r3, #-1\n"
        "    strb   r3, [r0, #29]\n"          /* run_dir = -1: the rising runs end */
        "    ldm    r0, {r1, r2, r3}\n"       /* coef, f, the pairs (round 18: one LDM) */
        "    ldr    lr, [r0, #24]\n"          /* u (process stored it) */
        "    ldm    r1, {r8, r10, r11, r12}\n" /* r, a, w (not used), n_r | n_a << 16 */
                                               /* (round 18: one LDM for four loads) */
        "    sub    r1, r3, r2, lsl #1\n"     /* c - 2 f: a column's pairs are at it + 2 fp */
        "    add    r11, r10, r12, lsr #14\n" /* a_end = a + 4 n_a (n_r < 2^14: its bits */
                                               /* shift out) */
        "    lsl    r6, lr, #8\n"             /* u 2^8 (fits: |u| <= 2^20) */
        "    mov    r7, #0x1000000\n"         /* K: the lower branch can win iff */
        "    sub    r7, r7, lr, asr #31\n"    /* ((a_j - K) ^ (u >> 31)) < 0: u >= 0 and */
                                               /* a < 1 (K = 2^24), u < 0 and a > 1 */
                                               /* (K = 2^24 + 1: ~(a - K) = 2^24 - a); at */
                                               /* u = 0 the lower-branch loop for a < 1 (it */
                                               /* cannot win there: -r <= hi; round 18: */
                                               /* 2 instructions for K instead of 6) */
        "    lsl    r3, r12, #16\n"
        "    lsrs   r3, r3, #14\n"            /* n_r * 4 */
        "    stm    sp, {r1, r2, r3, r6, r7, r8, r11}\n"
        "    ldrd   r8, r9, [r0, #16]\n"      /* acc */
        "    beq    7f\n"                     /* n_r == 0 (the lsrs) */
        "1:  ldm    sp, {r1, r2, r3, r6, r7}\n" /* column (r10 = &a_j) */
        "    add    r1, r1, r2, lsl #1\n"     /* its pairs */
        "    ldr    r11, [r10], #4\n"          /* a_j */
        "    smmulr r6, r11, r6\n"            /* the rounded high word (a_j u 2^8 + 2^31) >> 32 */
        "    subs   r7, r11, r7\n"            /* is A_j = rshift_rnd(a_j u, 24) */
        "    eors   r7, r7, lr, asr #31\n"
        "    bmi    5f\n"
        "    lsls   r12, r3, #30\n"           /* upper branch only, two per pass: C = */
        "    add    r3, r3, r2\n"             /* n_r odd (r3 = n_r * 4 until this add, */
        "    bcc    31f\n"                    /* its outputs' end after; round 18) */
        "33: ldrd   r11, r4, [r1], #8\n"      /* odd: one first (its c and w) */
        "    ldr    r12, [r2]\n"
        "    add    r11, r11, r6\n"           /* hi = A_j + c */
        "    subs   r7, r11, r12\n"           /* d = hi - F: F < hi ends the scan */
        "    bgt    6f\n"
        "    str    r11, [r2], #4\n"
        "    smlal  r8, r9, r4, r7\n"
        "    cmp    r2, r3\n"
        "    beq    6f\n"
        "31: ldm    r1!, {r4, r5, r7, r11}\n" /* the pair's c, w, c, w */
        "    ldrd   r12, r0, [r2]\n"          /* its outputs */
        "    add    r4, r4, r6\n"             /* hi = A_j + c */
        "    subs   r12, r4, r12\n"           /* d = hi - F: F < hi ends the scan */
        "    bgt    6f\n"
        "    add    r7, r7, r6\n"
        "    subs   r0, r7, r0\n"
        "    bgt    32f\n"                    /* the second ends it: the first alone moves */
        "    strd   r4, r7, [r2], #8\n"
        "    smlal  r8, r9, r5, r12\n"
        "    smlal  r8, r9, r11, r0\n"
        "    cmp    r2, r3\n"
        "    bne    31b\n"
        "    b      6f\n"
        "32: str    r4, [r2], #4\n"
        "    smlal  r8, r9, r5, r12\n"
        "    str    r3, [sp, #4]\n"           /* the column's end (6 below), in line */
        "    ldr    r11, [sp, #24]\n"         /* (round 18: no branch to it) */
        "    cmp    r10, r11\n"
        "    bne    1b\n"
        "    add    sp, #32\n"               /* the exit (7 below), in line: on a */
        "    ldr    r2, [sp], #4\n"          /* fall the last column often ends here */
        "    strd   r8, r9, [r2, #16]\n"     /* (round 18: no branch to it) */
        "    mov    r0, r8\n"
        "    mov    r1, r9\n"
        "    pop    {r4-r11, pc}\n"
        "5:  add    r3, r3, r2\n"             /* its outputs' end */
        "    ldr    r0, [sp, #20]\n"           /* with the lower branch: its prefix, one per pass */
        "51: ldrd   r11, r4, [r1], #8\n"       /* c, w */
        "    add    r11, r11, r6\n"            /* hi = A_j + c */
        "    ldr    r7, [r0], #4\n"
        "    sub    r7, lr, r7\n"              /* lo = u - r */
        "    cmp    r7, r11\n"
        "    blt    53f\n"                     /* lo < hi: from here on the upper branch wins */
        "    ldr    r12, [r2]\n"
        "    cmp    r12, r11\n"
        "    blt    6f\n"                      /* F < hi ends the scan */
        "    str    r7, [r2], #4\n"
        "    sub    r7, r7, r12\n"
        "    smlal  r8, r9, r4, r7\n"
        "    cmp    r2, r3\n"
        "    bne    51b\n"
        "    b      6f\n"
        "53: ldr    r12, [r2]\n"               /* this operator on the upper branch, */
        "    subs   r7, r11, r12\n"
        "    bgt    6f\n"
        "    str    r11, [r2], #4\n"
        "    smlal  r8, r9, r4, r7\n"
        "    cmp    r2, r3\n"
        "    bne    3f\n"                      /* the rest by the upper-branch loop */
        "6:  str    r3, [sp, #4]\n"            /* next column: fp's starts where this one ends */
        "    ldr    r11, [sp, #24]\n"
        "    cmp    r10, r11\n"
        "    bne    1b\n"
        "7:  add    sp, #32\n"
        "    ldr    r2, [sp], #4\n"           /* p */
        "    strd   r8, r9, [r2, #16]\n"      /* p->acc_q39 */
        "    mov    r0, r8\n"
        "    mov    r1, r9\n"
        "    pop    {r4-r11, pc}\n"
        "3:  sub    r12, r3, r2\n"             /* after a lower-branch prefix: the rest's */
        "    tst    r12, #4\n"                 /* parity */
        "    beq    31b\n"
        "    b      33b\n");
}

#endif

/* The C falling step: what other targets run, and on the Cortex-M4 the
 * reference of upi_fall_m4 (piezo_play_process_upi_c, test_play). */
static int64_t upi_fall(const struct piezo_play_coef *c, const int64_t *c2, int32_t *f, int32_t u_q15,
                        int64_t acc)
{
    const int32_t *r = c->r_q15;
    const int32_t *w = c->w_q24;
    const size_t n_r = c->n_r, n_a = c->n_a;
    for (size_t j = 0; j < n_a; j++) {
        const int32_t au = upper_a(c->a_q24[j], u_q15);
        size_t k = j * n_r; /* the column's first constant */
        int32_t *fp = f + j * n_r;
        const int32_t *rp = r;
        const int32_t *wp = w + j;
        const int32_t a_j = c->a_q24[j];
        if (a_j <= PIEZO_Q24_ONE ? u_q15 <= 0 : u_q15 >= 0) {
            for (size_t i = n_r; i != 0u; i--) {
                const int32_t hi = au + c_get(c2, k++);
                const int32_t y = *fp;
                if (y < hi) {
                    break;
                }
                *fp++ = hi;
                acc += (int64_t)*wp * (hi - y);
                wp += n_a;
            }
            continue;
        }
        for (size_t i = n_r; i != 0u; i--) {
            const int32_t hi = au + c_get(c2, k++);
            const int32_t y = *fp;
            if (y < hi) {
                break;
            }
            const int32_t lo = u_q15 - *rp++;
            const int32_t v = hi > lo ? hi : lo;
            *fp++ = v;
            acc += (int64_t)*wp * (v - y);
            wp += n_a;
        }
    }
    return acc;
}

/*
 * Rising, F = max(u - r_i, F) (the upper branch cannot bind while rising):
 * for each of n_col columns of n_r outputs (column by column from f), from
 * the column's first threshold to the first u - r_i <= F; the column's
 * weights start at w + column and step by w_step entries (n_a, the
 * unparallel bank's row-major weights). Returns acc plus the sum of
 * w (F_new - F_old).
 */
#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/* Cortex-M4: in Thumb-2, 10 instructions per moving operator (two per
 * pass; the break tested on the sign of the step it accumulates) against
 * gcc's 13; test_play and the EUPI golden vectors under QEMU. 9.5 since
 * round 14: a pass's two weights at wp and wp + stride, wp stepped once per
 * pass (with n_r odd every column enters at a pair's second, so the first
 * column's weight pointer starts one stride back). Round 17: the rising
 * runs (upi_rise below): each column's run stored two per pass (LDRD/STRD,
 * 3 per operator), its part of the sum one UMLAL + MLA for the bank; the
 * scan from the run's end at 11.5 per operator (run_w += w), each column's
 * state (its rest count) read and written once. Round 17, second part: the
 * scan reads the weights' copy beside the constants (8 bytes apart, one
 * post-indexed load each; the pointer set once when a column's scan starts,
 * none per column otherwise): 11 per operator. */

static __attribute__((naked, noinline, used)) int64_t rise_m4(struct piezo_play *p, int32_t u_q15, int32_t u_prev_q15)
{
    (void)p;
    (void)u_q15;
    (void)u_prev_q15;
    /* r0 wp, r1 rp, r2 fp, r3 the column's end of fp, r4 the column's rest
     * count in bytes (4 (n_r - m_j), uint16), r6 r7 r12 scratch, r8:r9 acc, r10:r11
     * run_w, lr u, r5 the counts' end; at [sp]: W = c2 + 4 - 2 f (the
     * weights' copy beside the constants: the weight of the output at fp is
     * at W + 2 fp; round 17, second part), the thresholds, n_r * 4 (one LDM
     * per column); p at [sp, #16] */
    __asm__ volatile(
        "    push   {r0, r4-r11, lr}\n"
        "    sub    sp, #16\n"
        "    ldrd   r8, r9, [r0, #16]\n"      /* acc */
        "    mov    lr, r1\n"                 /* u */
        "    sub    r1, r1, r2\n"             /* d = u - u_prev > 0 (the entry's r2) */
        "    ldrsb  r6, [r0, #29]\n"          /* run_dir */
        "    movs   r7, #1\n"
        "    strb   r7, [r0, #29]\n"          /* run_dir = 1 */
        "    ldrd   r10, r11, [r0, #32]\n"    /* run_w */
        "    ldm    r0, {r0, r2, r4, r7}\n"   /* coef, f, the constants (n_ops pairs of */
                                               /* them: the rest counts follow), n_ops */
                                               /* (round 18: one LDM for four LDRs) */
        "    ldrh   r12, [r0, #12]\n"         /* n_r */
        "    ldrh   r5, [r0, #14]\n"          /* n_a */
        "    ldr    r3, [r0, #0]\n"           /* r */
        "    add    r0, r4, #4\n"
        "    sub    r0, r0, r2, lsl #1\n"     /* W */
        "    add    r4, r4, r7, lsl #3\n"
        "    add    r5, r4, r5, lsl #1\n"     /* the counts' end */
        "    lsls   r12, r12, #2\n"          /* n_r * 4 (round 18: its flags test */
        "    beq    7f\n"                    /* n_r == 0, no CMP) */
        "    cmp    r6, #1\n"
        "    bne    8f\n"
        "    umlal  r8, r9, r10, r1\n"        /* the runs go on: acc += run_w d (d > 0) */
        "    mla    r9, r11, r1, r9\n"
        "9:  stm    sp, {r0, r3, r12}\n"
        "1:  ldrh   r7, [r4]\n"               /* column: its rest, in bytes */
        "    ldm    sp, {r0, r1, r12}\n"      /* W, rp = r, n_r * 4 */
        "    add    r3, r2, r12\n"            /* the column's end */
        "    sub    r6, r3, r7\n"             /* the run's end */
        "    sub    r6, r6, #4\n"             /* its stores two per pass while fp < r6 */
        "    cmp    r2, r6\n"
        "    bhs    22f\n"
        "21: ldrd   r7, r12, [r1], #8\n"
        "    sub    r7, lr, r7\n"
        "    sub    r12, lr, r12\n"
        "    strd   r7, r12, [r2], #8\n"
        "    cmp    r2, r6\n"
        "    blo    21b\n"
        "22: bne    30f\n"                    /* fp == r6: one left */
        "    ldr    r7, [r1], #4\n"
        "    sub    r7, lr, r7\n"
        "    str    r7, [r2], #4\n"
        "30: subs   r6, r3, r2\n"             /* the scan from the run's end */
        "    beq    4f\n"
        "    ldr    r12, [r1], #4\n"          /* its first operator alone (round 18: */
        "    ldr    r7, [r2]\n"               /* on a steady rise it is the one that */
        "    sub    r12, lr, r12\n"           /* ends the scan; 7 instructions then, */
        "    subs   r7, r12, r7\n"            /* 10 through the pair loop) */
        "    ble    4f\n"
        "    str    r12, [r2], #4\n"
        "    add    r0, r0, r2, lsl #1\n"     /* wp = W + 2 fp: the next one's weight, */
        "    ldr    r12, [r0, #-8]\n"         /* this one's 8 bytes before it */
        "    smlal  r8, r9, r12, r7\n"
        "    adds   r10, r10, r12\n"          /* run_w += w */
        "    adc    r11, r11, r12, asr #31\n"
        "    cmp    r2, r3\n"
        "    beq    4f\n"
        "    tst    r6, #4\n"                 /* an even count left: the pair's first */
        "    beq    3f\n"                    /* odd: enter at the pair's second */
        "2:  ldr    r6, [r1], #4\n"
        "    ldr    r7, [r2]\n"
        "    sub    r6, lr, r6\n"
        "    subs   r7, r6, r7\n"            /* d = (u - r) - F: <= 0 ends the scan */
        "    ble    4f\n"
        "    str    r6, [r2], #4\n"
        "    ldr    r6, [r0], #8\n"           /* the pair's weights, 8 bytes apart */
        "    smlal  r8, r9, r6, r7\n"
        "    adds   r10, r10, r6\n"           /* run_w += w */
        "    adc    r11, r11, r6, asr #31\n"
        "3:  ldr    r6, [r1], #4\n"
        "    ldr    r7, [r2]\n"
        "    sub    r6, lr, r6\n"
        "    subs   r7, r6, r7\n"            /* d = (u - r) - F: <= 0 ends the scan */
        "    ble    4f\n"
        "    str    r6, [r2], #4\n"
        "    ldr    r6, [r0], #8\n"
        "    smlal  r8, r9, r6, r7\n"
        "    adds   r10, r10, r6\n"
        "    adc    r11, r11, r6, asr #31\n"
        "    cmp    r2, r3\n"
        "    bne    2b\n"
        "4:  sub    r6, r3, r2\n"             /* the column's new rest, in bytes */
        "    strh   r6, [r4], #2\n"
        "    mov    r2, r3\n"                  /* the next column starts where this one ends */
        "    cmp    r4, r5\n"
        "    bne    1b\n"
        "    ldr    r0, [sp, #16]\n"          /* p */
        "    strd   r10, r11, [r0, #32]\n"    /* run_w */
        "    strd   r8, r9, [r0, #16]\n"      /* p->acc_q39 (round 18: p loaded once) */
        "    add    sp, #20\n"                /* the state and the pushed p */
        "    mov    r0, r8\n"
        "    mov    r1, r9\n"
        "    pop    {r4-r11, pc}\n"
        "7:  add    sp, #16\n"                /* no operators */
        "    ldr    r2, [sp], #4\n"           /* p */
        "    strd   r8, r9, [r2, #16]\n"      /* p->acc_q39 */
        "    mov    r0, r8\n"
        "    mov    r1, r9\n"
        "    pop    {r4-r11, pc}\n"
        "8:  movs   r10, #0\n"                /* new runs: run_w = 0, every rest n_r */
        "    movs   r11, #0\n"                /* (in bytes, n_r * 4); out of line: the */
        "    mov    r6, r4\n"                 /* runs that go on reach 9 without a branch */
        "81: strh   r12, [r6], #2\n"
        "    cmp    r6, r5\n"
        "    bne    81b\n"
        "    b      9b\n");
}

#endif
/* The classical run's stores: f[k] = u + r[k] falling (rsb == 0), u - r[k]
 * rising (rsb == 1). On Thumb-2 two per pass (ldrd/strd: three
 * instructions per operator; gcc's C pairs neither and spends five). */
static inline void store_run(int32_t *f, const int32_t *r, size_t n, int32_t u, int rsb)
{
#if defined(__thumb2__)
    if (n >= 2u) {
        int32_t *const last2 = f + n - 1u; /* a pair fits while f < last2 */
        int32_t t0, t1;
        if (rsb) {
            __asm__ volatile("1:\n\t"
                             "ldrd  %[t0], %[t1], [%[r]], #8\n\t"
                             "sub   %[t0], %[u], %[t0]\n\t"
                             "sub   %[t1], %[u], %[t1]\n\t"
                             "strd  %[t0], %[t1], [%[f]], #8\n\t"
                             "cmp   %[f], %[l]\n\t"
                             "blo   1b"
                             : [f] "+r"(f), [r] "+r"(r), [t0] "=&r"(t0), [t1] "=&r"(t1)
                             : [u] "r"(u), [l] "r"(last2)
                             : "cc", "memory");
        } else {
            __asm__ volatile("1:\n\t"
                             "ldrd  %[t0], %[t1], [%[r]], #8\n\t"
                             "add   %[t0], %[u], %[t0]\n\t"
                             "add   %[t1], %[u], %[t1]\n\t"
                             "strd  %[t0], %[t1], [%[f]], #8\n\t"
                             "cmp   %[f], %[l]\n\t"
                             "blo   1b"
                             : [f] "+r"(f), [r] "+r"(r), [t0] "=&r"(t0), [t1] "=&r"(t1)
                             : [u] "r"(u), [l] "r"(last2)
                             : "cc", "memory");
        }
        if (f <= last2) { /* n odd: one left */
            *f = rsb ? u - *r : u + *r;
        }
        return;
    }
#endif
    for (size_t k = 0; k < n; k++) {
        f[k] = rsb ? u - r[k] : u + r[k];
    }
}

/*
 * The unparallel bank's rising runs (round 17): after a rising sample the
 * operators 0..m_j-1 of column j (the ones that moved) hold u_prev - r_i;
 * a sample that rises again moves each of them by exactly d = u - u_prev
 * (F = max(u - r_i, F), u - r_i > u_prev - r_i), in every column: their part
 * of the sum is d * run_w, run_w = the sum of their weights over the whole
 * bank (p->run_w_q24, int64: |run_w| < 2^8 * 2^31, |d| <= 2^21, as the
 * classical run), and they are only stored; each column's scan goes on from
 * m_j. Each column keeps 4 (n_r - m_j) (uint16, the bytes after its run),
 * after the constants and weights in the work array (bytes 8 n_ops + 2 j:
 * PIEZO_PLAY_WORK_LEN).
 * p->run_dir is +1 while they hold; a falling sample sets it to -1 and
 * reset to 0: the next rise starts every column's run anew.
 */
static inline unsigned char *upi_runs(const struct piezo_play *p)
{
    return (unsigned char *)p->c2_q15 + p->n_ops * sizeof(int64_t);
}

/* The rest counts are kept in bytes, 4 (n_r - m_j) (round 18: rise_m4
 * subtracts it from the column's end and stores it without shifts; n_r <=
 * PIEZO_PLAY_MAX_OPS, so 4 n_r fits uint16). */
static inline size_t m_get(const unsigned char *m, size_t j)
{
    uint16_t v;
    memcpy(&v, m + j * sizeof v, sizeof v);
    return v / 4u;
}

static inline void m_set(unsigned char *m, size_t j, size_t v)
{
    const uint16_t x = (uint16_t)(v * 4u);
    memcpy(m + j * sizeof x, &x, sizeof x);
}

/* The C rising step (the reference of rise_m4, as upi_fall above). */
static int64_t upi_rise(struct piezo_play *p, int32_t u_q15, int32_t u_prev, int64_t acc)
{
    const struct piezo_play_coef *c = p->coef;
    const int32_t *r = c->r_q15;
    const size_t n_r = c->n_r, n_a = c->n_a;
    if (n_r == 0u) {
        return acc; /* no operators, and the work array may be empty (rise_m4 too) */
    }
    unsigned char *m = upi_runs(p);
    const int keep = p->run_dir > 0;
    int64_t run_w = 0;
    if (keep) {
        run_w = p->run_w_q24;
        acc += run_w * (u_q15 - u_prev);
    }
    for (size_t j = 0; j < n_a; j++) {
        int32_t *fc = p->f_q15 + j * n_r;
        size_t i = keep ? n_r - m_get(m, j) : 0u;
        const int32_t *wk = c->w_q24 + j + i * n_a;
        store_run(fc, r, i, u_q15, 1);
        for (; i < n_r; i++, wk += n_a) {
            const int32_t lo = u_q15 - r[i];
            const int32_t y = fc[i];
            if (lo <= y) {
                break;
            }
            fc[i] = lo;
            acc += (int64_t)*wk * (lo - y);
            run_w += *wk;
        }
        m_set(m, j, n_r - i);
    }
    p->run_dir = 1;
    p->run_w_q24 = run_w;
    return acc;
}

/* The first sample after init or reset: every operator by the formula. */
/* used: the Cortex-M4 entries below branch to it from assembly */
static __attribute__((noinline, used)) int64_t play_first(struct piezo_play *p, int32_t u_q15)
{
    p->primed = 1u;
    p->u_prev_q15 = u_q15;
    p->acc_q39 = play_full(p, u_q15);
    return p->acc_q39;
}

/* The classical bank's step for a primed bank and a new input (the caller
 * tested both): the C that other targets compile, and the reference of the
 * Cortex-M4's cpi_m4 (piezo_play_process_cpi_c, test_play). */
static inline __attribute__((always_inline)) int64_t cpi_step(struct piezo_play *p, int32_t u_q15)
{
    const int32_t u_prev = p->u_prev_q15;
    p->u_prev_q15 = u_q15;

    const struct piezo_play_coef *c = p->coef;
    const int32_t *r = c->r_q15;
    const int32_t *w = c->w_q24;
    int32_t *f = p->f_q15;
    const size_t n_r = c->n_r;
    int64_t acc = p->acc_q39;
    /* Classical: rising F = max(u - r, F), falling F = min(u + r, F);
     * the operators that move are a prefix in both directions. The
     * last sample's run (play.h) moves by d = u - u_prev as one when
     * the direction holds: d * run_w, then only its stores; the scan
     * goes on after it. */
    /* the step d = new - old decides the break by its sign (one subs
     * instead of a compare and a subtraction); |u|, r <= 2^20 and
     * |F| <= 2^21 (play.h), so d cannot overflow */
    const int8_t dir = u_q15 > u_prev ? 1 : -1;
    size_t i = 0;
    int64_t run_w = 0;
    if (dir == p->run_dir) {
        i = p->run_n;
        run_w = p->run_w_q24;
        acc += run_w * (u_q15 - u_prev);
    }
    p->run_dir = dir;
    if (dir > 0) {
        store_run(f, r, i, u_q15, 1);
        for (; i < n_r; i++) {
            const int32_t lo = u_q15 - r[i];
            const int32_t d = lo - f[i];
            if (d <= 0) {
                break;
            }
            f[i] = lo;
            acc += (int64_t)w[i] * d;
            run_w += w[i];
        }
    } else {
        store_run(f, r, i, u_q15, 0);
        for (; i < n_r; i++) {
            const int32_t hi = u_q15 + r[i];
            const int32_t d = hi - f[i];
            if (d >= 0) {
                break;
            }
            f[i] = hi;
            acc += (int64_t)w[i] * d;
            run_w += w[i];
        }
    }
    p->run_n = (uint16_t)i;
    p->run_w_q24 = run_w;
    p->acc_q39 = acc;
    return acc;
}

#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/* Cortex-M4: cpi_step in Thumb-2, the same integers. gcc's C (91 at the
 * reference's worst tick 127: a falling run of 9 and one operator tested)
 * spends 11 on the run's d * run_w (a 64 x 64 product), re-derives the scan's
 * three pointers from the index (8) and saves and reloads two of them on the
 * stack; here the run's product is UMLAL plus MLA on the high word (d > 0
 * rising; falling d < 0, read unsigned as d + 2^32, so the low word of run_w
 * comes off the high word once more), the store loop leaves the pointers
 * where the scan starts, and the tick's state stays in registers.
 * r0 p, r1 u, r2 d then scratch, r3:r8 run_w (low, high), r4:r5 acc, r6 r,
 * r7 w, r9 i, r10 the stores' bound then scratch, r11 scratch,
 * ip f, lr n_r. No call inside: nine registers pushed. */
static __attribute__((naked, noinline, used)) int64_t cpi_m4(struct piezo_play *p, int32_t u_q15, int32_t u_prev_q15)
{
    (void)p;
    (void)u_q15;
    (void)u_prev_q15;
    __asm__ volatile(
        "    push   {r4-r11, lr}\n"
        "    ldm    r0, {r3, ip}\n"           /* coef, f (round 18: one LDM) */
        "    str    r1, [r0, #24]\n"          /* u_prev = u */
        "    ldrd   r4, r5, [r0, #16]\n"      /* acc */
        "    ldr    r6, [r3, #0]\n"           /* r */
        "    ldr    r7, [r3, #8]\n"           /* w */
        "    ldrh   lr, [r3, #12]\n"          /* n_r */
        "    ldrsb  r8, [r0, #29]\n"          /* run_dir */
        "    subs   r2, r1, r2\n"             /* d = u - u_prev, never 0 here */
        "    ble    20f\n"
        /* rising: F = max(u - r, F) */
        "    cmp    r8, #1\n"
        "    beq    11f\n"
        "    movs   r8, #1\n"
        "    strb   r8, [r0, #29]\n"          /* run_dir = 1 */
        "    movs   r8, #0\n"
        "    movs   r9, #0\n"                 /* a new run: i = 0, run_w = 0 (round 16: */
        "    movs   r3, #0\n"                 /* here, not on every tick) */
        "    b      15f\n"
        "11: ldrh   r9, [r0, #30]\n"          /* i = run_n */
        "    ldrd   r3, r8, [r0, #32]\n"      /* run_w */
        "    umlal  r4, r5, r3, r2\n"         /* acc += run_w d (d > 0) */
        "    mla    r5, r8, r2, r5\n"
        "    add    r10, ip, r9, lsl #2\n"   /* f + i */
        "    sub    r10, r10, #12\n"          /* four fit while ip < r10 */
        "    cmp    ip, r10\n"
        "    bhs    13f\n"
        "12: ldmia  r6!, {r2, r3, r8, r11}\n" /* the run's stores, four a pass */
        "    sub    r2, r1, r2\n"
        "    sub    r3, r1, r3\n"
        "    sub    r8, r1, r8\n"
        "    sub    r11, r1, r11\n"
        "    stmia  ip!, {r2, r3, r8, r11}\n"
        "    cmp    ip, r10\n"
        "    blo    12b\n"
        "13: add    r10, r10, #12\n"
        "    sub    r2, r10, ip\n"           /* bytes left: 0, 4, 8 or 12 */
        "    cmp    r2, #8\n"
        "    blo    14f\n"
        "    ldrd   r3, r8, [r6], #8\n"
        "    sub    r3, r1, r3\n"
        "    sub    r8, r1, r8\n"
        "    strd   r3, r8, [ip], #8\n"
        "    subs   r2, r2, #8\n"
        "14: cbz    r2, 18f\n"
        "    ldr    r3, [r6], #4\n"
        "    sub    r3, r1, r3\n"
        "    str    r3, [ip], #4\n"
        "18: ldrd   r3, r8, [r0, #32]\n"      /* run_w again */
        "    add    r7, r7, r9, lsl #2\n"     /* w + i */
        "15: cmp    r9, lr\n"                 /* the scan from i */
        "    bhs    30f\n"
        "    ldr    r2, [r6], #4\n"
        "    ldr    r10, [ip]\n"
        "    sub    r2, r1, r2\n"             /* lo = u - r_i */
        "    subs   r10, r2, r10\n"           /* d_i = lo - F_i */
        "    ble    30f\n"
        "    str    r2, [ip], #4\n"
        "    ldr    r11, [r7], #4\n"
        "    smlal  r4, r5, r11, r10\n"       /* acc += w_i d_i */
        "    adds   r3, r3, r11\n"            /* run_w += w_i */
        "    adc    r8, r8, r11, asr #31\n"
        "    adds   r9, #1\n"
        "    b      15b\n"
        /* falling: F = min(u + r, F) */
        "20: cmp    r8, #-1\n"
        "    beq    21f\n"
        "    mov    r8, #-1\n"
        "    strb   r8, [r0, #29]\n"          /* run_dir = -1 */
        "    movs   r8, #0\n"
        "    movs   r9, #0\n"                 /* a new run: i = 0, run_w = 0 (round 16: */
        "    movs   r3, #0\n"                 /* here, not on every tick) */
        "    b      25f\n"
        "21: ldrh   r9, [r0, #30]\n"
        "    ldrd   r3, r8, [r0, #32]\n"
        "    umlal  r4, r5, r3, r2\n"         /* d < 0 read as d + 2^32: */
        "    mla    r5, r8, r2, r5\n"
        "    sub    r5, r5, r3\n"             /* less run_w's low word times 2^32 */
        "    add    r10, ip, r9, lsl #2\n"   /* f + i */
        "    sub    r10, r10, #12\n"          /* four fit while ip < r10 */
        "    cmp    ip, r10\n"
        "    bhs    23f\n"
        "22: ldmia  r6!, {r2, r3, r8, r11}\n" /* the run's stores, four a pass */
        "    add    r2, r1, r2\n"
        "    add    r3, r1, r3\n"
        "    add    r8, r1, r8\n"
        "    add    r11, r1, r11\n"
        "    stmia  ip!, {r2, r3, r8, r11}\n"
        "    cmp    ip, r10\n"
        "    blo    22b\n"
        "23: add    r10, r10, #12\n"
        "    sub    r2, r10, ip\n"           /* bytes left: 0, 4, 8 or 12 */
        "    cmp    r2, #8\n"
        "    blo    24f\n"
        "    ldrd   r3, r8, [r6], #8\n"
        "    add    r3, r1, r3\n"
        "    add    r8, r1, r8\n"
        "    strd   r3, r8, [ip], #8\n"
        "    subs   r2, r2, #8\n"
        "24: cbz    r2, 28f\n"
        "    ldr    r3, [r6], #4\n"
        "    add    r3, r1, r3\n"
        "    str    r3, [ip], #4\n"
        "28: ldrd   r3, r8, [r0, #32]\n"      /* run_w again */
        "    add    r7, r7, r9, lsl #2\n"     /* w + i */
        "25: cmp    r9, lr\n"
        "    bhs    30f\n"
        "    ldr    r2, [r6], #4\n"
        "    ldr    r10, [ip]\n"
        "    add    r2, r1, r2\n"             /* hi = u + r_i */
        "    subs   r10, r2, r10\n"           /* d_i = hi - F_i */
        "    bge    30f\n"
        "    str    r2, [ip], #4\n"
        "    ldr    r11, [r7], #4\n"
        "    smlal  r4, r5, r11, r10\n"
        "    adds   r3, r3, r11\n"
        "    adc    r8, r8, r11, asr #31\n"
        "    adds   r9, #1\n"
        "    b      25b\n"
        "30: strh   r9, [r0, #30]\n"          /* run_n, run_w, acc */
        "    strd   r3, r8, [r0, #32]\n"
        "    strd   r4, r5, [r0, #16]\n"
        "    mov    r0, r4\n"
        "    mov    r1, r5\n"
        "    pop    {r4-r11, pc}\n");
}
/* cpi_m4 reads the instance's run fields directly */
typedef char piezo_play_run_layout_check_t[(offsetof(struct piezo_play, primed) == 28u &&
                                            offsetof(struct piezo_play, run_dir) == 29u &&
                                            offsetof(struct piezo_play, run_n) == 30u &&
                                            offsetof(struct piezo_play, run_w_q24) == 32u) ? 1 : -1];
#endif

#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/* Cortex-M4: the two entries' tests in Thumb-2, branching to their steps
 * (gcc's C saved and restored r4 around them: 8 and 11 instructions at the
 * reference's worst tick, here 5 and 8). The same tests as the C below. */
__attribute__((naked)) int64_t piezo_play_process_cpi(struct piezo_play *p, int32_t u_q15)
{
    (void)p;
    (void)u_q15;
    __asm__ volatile(
        "    ldrb   r3, [r0, #28]\n"          /* primed */
        "    ldr    r2, [r0, #24]\n"          /* u_prev, cpi_m4's third argument */
        "    cbz    r3, 1f\n"
        "    cmp    r2, r1\n"
        "    bne.w  cpi_m4\n"
        "    ldrd   r0, r1, [r0, #16]\n"      /* the update is idempotent: acc */
        "    bx     lr\n"
        "1:  b.w    play_first\n");
}
#else
int64_t piezo_play_process_cpi(struct piezo_play *p, int32_t u_q15)
{
    if (!p->primed) {
        return play_first(p, u_q15);
    }
    if (u_q15 == p->u_prev_q15) {
        return p->acc_q39; /* the update is idempotent */
    }
    return cpi_step(p, u_q15);
}
#endif

int64_t piezo_play_process_cpi_c(struct piezo_play *p, int32_t u_q15)
{
    if (!p->primed) {
        return play_first(p, u_q15);
    }
    if (u_q15 == p->u_prev_q15) {
        return p->acc_q39;
    }
    return cpi_step(p, u_q15);
}

#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__)
/* rise_m4 and upi_fall_m4 read p, its coefficients and acc_q39 and store
 * acc_q39; the entry stores u_prev. Unparallel, column by column (slope a_j,
 * thresholds ascending); the outputs are stored column by column too (slot
 * j * n_r + i); rising, F = max(u - r_i, F): the upper branch cannot bind. */
__attribute__((naked)) int64_t piezo_play_process_upi(struct piezo_play *p, int32_t u_q15)
{
    (void)p;
    (void)u_q15;
    __asm__ volatile(
        "    ldrb   r3, [r0, #28]\n"          /* primed */
        "    ldr    r2, [r0, #24]\n"          /* u_prev */
        "    cbz    r3, 1f\n"
        "    cmp    r1, r2\n"
        "    beq    2f\n"
        "    str    r1, [r0, #24]\n"          /* u_prev = u */
        "    bgt.w  rise_m4\n"
        "    b.w    upi_fall_m4\n"
        "2:  ldrd   r0, r1, [r0, #16]\n"      /* the update is idempotent: acc */
        "    bx     lr\n"
        "1:  b.w    play_first\n");
}
#else
int64_t piezo_play_process_upi(struct piezo_play *p, int32_t u_q15)
{
    return piezo_play_process_upi_c(p, u_q15);
}
#endif

int64_t piezo_play_process_upi_c(struct piezo_play *p, int32_t u_q15)
{
    if (!p->primed) {
        return play_first(p, u_q15);
    }
    const int32_t u_prev = p->u_prev_q15;
    if (u_q15 == u_prev) {
        return p->acc_q39; /* the update is idempotent */
    }
    p->u_prev_q15 = u_q15;

    /* Unparallel, column by column (slope a_j, thresholds ascending); the
     * outputs are stored column by column too (slot j * n_r + i), so that a
     * column's outputs, thresholds and branch constants are walked in step;
     * only the weights (row-major, as given) are read with a stride. */
    /* rising, F = max(u - r_i, F): the upper branch cannot bind */
    const struct piezo_play_coef *c = p->coef;
    int64_t acc = p->acc_q39;
    if (u_q15 > u_prev) {
        acc = upi_rise(p, u_q15, u_prev, acc);
    } else {
        p->run_dir = -1; /* the rising runs end */
        acc = upi_fall(c, p->c2_q15, p->f_q15, u_q15, acc);
    }
    p->acc_q39 = acc;
    return acc;
}

int64_t piezo_play_process(struct piezo_play *p, int32_t u_q15)
{
    return p->coef->n_a == 0u ? piezo_play_process_cpi(p, u_q15) : piezo_play_process_upi(p, u_q15);
}
