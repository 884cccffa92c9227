/*
 * xcouple.h - cross-axis coupling predictor: the fixed-point form of the
 * distributed Hammerstein model the host identifies (kind `hammerstein`,
 * docs/cross-coupling.md), for the compensation term of a two-axis stage.
 *
 * Model, per tick, for the other axis' drive u and a position x (q15 inputs):
 *   u_n  = clamp(rshift_rnd((u - u_c) g_u, 16), +-32767)   normalized drive, q15
 *   x_n  = clamp(rshift_rnd((x - x_c) g_x, 16), +-32767)   normalized position, q15
 *   p_k  = u_n^k, k = 0..K (p_0 = 32768, p_k = rshift_rnd(p_{k-1} u_n, 15))
 *   s_b  = x_n^b, b = 0..D (the same recursion)
 *   mu_c = rshift_rnd(sum_{k,b} eta_{c,k,b} rshift_rnd(p_k s_b, 15), 15)     q24
 *   rho_{c,i} = rshift_rnd(sum_b xi_{c,i,b} s_b, 15)                         q24
 *   y    = sat_q15(rshift_rnd(sum_{c,i} rho_{c,i} zeta_{c,i}, 33))           q15
 *   zeta_c <- rshift_rnd(A zeta_c + B mu_c, 24)  (each row one rounding)     q24
 * i.e. y(t) = sum_c sum_i rho_{c,i}(x(t)) L_i[N_c(u, x)](t): m Laguerre
 * filters (state matrix A, input B; strictly proper, so y(t) depends on u up
 * to t - 1) per channel c = 1..Nc on a polynomial N_c in u_n whose
 * coefficients are polynomials in x_n, with output weights polynomial in x_n.
 * The host folds the conversion to this axis' drive units (1 / static gain)
 * into xi: y is the drive that cancels the predicted coupling, negated.
 *
 * The first call after init/reset starts the filters at the equilibrium of
 * that call's input, zeta_c = rshift_rnd(E mu_c, 24) with E = (I - A)^-1 B
 * from the table (the host model's steady start).
 *
 * Scaling and overflow (init refuses coefficients outside these bounds):
 *   |p_k|, |s_b|, |p_k s_b| terms <= 2^15 (|u_n|, |x_n| <= 32767);
 *   sum_{k,b} |eta_{c,k,b}| <= 2^24 per channel, so |mu_c| <= 2^24 (1.0) and
 *     the mu accumulator <= 2^39;
 *   A lower triangular, 0 <= A_ii < 2^24, |A_ij|, |B_i| < 2^25 (E is any
 *     int32: the Laguerre filters' DC gains are 4.5, 11.7, 31, 81 at the
 *     paper's q = 0.1, T = 2);
 *   state bound: with Z_i = 2^(24 + s_i), s_i <= 10, chosen by init as the
 *     smallest with (2^24 - A_ii) Z_i >= |B_i| 2^24 + sum_{j<i} |A_ij| Z_j + 2^24
 *     and |E_i| < Z_i, every |zeta_i| <= Z_i <= 2^34 for all time (induction
 *     on the rows; the 2^24 covers the rounding); the row accumulator is
 *     <= 2^25 (m 2^34 + 2^24) < 2^62;
 *   per output term: (sum_b |xi_{c,i,b}| + 1) <= 2^(35 - s_i), so
 *     |rho_{c,i} zeta_{c,i}| <= 2^59 and the output accumulator (at most 8
 *     terms) < 2^62. (Laguerre combinations that differentiate have large
 *     alternating xi: the bound is per filter, against its own state bound.)
 * No division, no floating point; one rounding rule (piezo_rshift_rnd64).
 */
#ifndef PIEZO_XCOUPLE_H
#define PIEZO_XCOUPLE_H

#include <stdint.h>

#define PIEZO_XC_MAX_M 4u    /* Laguerre filters per channel */
#define PIEZO_XC_MAX_CH 2u   /* channels Nc */
#define PIEZO_XC_MAX_POW 8u  /* K + 1: powers u_n^0 .. u_n^7 */
#define PIEZO_XC_MAX_DEG 4u  /* D + 1: position polynomials up to x_n^3 */
#define PIEZO_XC_MAX_SHIFT 10u

struct piezo_xc_coef {
    uint8_t m;               /* filters, 1..PIEZO_XC_MAX_M */
    uint8_t n_ch;            /* channels, 1..PIEZO_XC_MAX_CH */
    uint8_t n_pow;           /* K + 1, 1..PIEZO_XC_MAX_POW */
    uint8_t n_deg;           /* D + 1, 1..PIEZO_XC_MAX_DEG */
    int32_t u_center_q15;    /* u_c, within +-32768 */
    int32_t u_gain_q16;      /* g_u > 0 */
    int32_t x_center_q15;    /* x_c, within +-32768 */
    int32_t x_gain_q16;      /* g_x > 0 */
    const int32_t *a_q24;    /* A, m x m row-major */
    const int32_t *b_q24;    /* B, m */
    const int32_t *e_q24;    /* E = (I - A)^-1 B, m */
    const int32_t *eta_q24;  /* eta[c][k][b], n_ch x n_pow x n_deg */
    const int32_t *xi_q24;   /* xi[c][i][b], n_ch x m x n_deg */
};

struct piezo_xc {
    const struct piezo_xc_coef *k;
    int64_t zeta_q24[PIEZO_XC_MAX_CH * PIEZO_XC_MAX_M];
    uint8_t started;         /* 0 until the first process call after reset */
};

/** Check the coefficients (bounds above) and reset. Returns a piezo_err code:
 *  PIEZO_EINVAL (NULL, sizes), PIEZO_ERANGE (a bound fails). */
int piezo_xc_init(struct piezo_xc *s, const struct piezo_xc_coef *k);

/** Forget the filter states: the next call starts at its input's equilibrium. */
void piezo_xc_reset(struct piezo_xc *s);

/** One tick: the predicted coupling (q15, in the units the table chose) for
 *  the other axis' drive u and the position x. */
int16_t piezo_xc_process(struct piezo_xc *s, int16_t u_q15, int16_t x_q15);

#endif /* PIEZO_XCOUPLE_H */
