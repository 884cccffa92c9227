/*
 * rkp.h - rate-dependent KP model (RKP): KP operators with a density that
 * depends on the input rate through Gaussian radial basis functions.
 *
 * Per tick (docs/kernels-kp.md; float reference host/piezoctl/models/kp.py
 * rkp_model, bit-exact golden model host/piezoctl/golden/rkp.py):
 *
 *   1. rate:     d = u[k] - u[k-1];  q[k] = q[k-1] + a (d - q[k-1])
 *                (first-order low-pass of the per-sample difference; the
 *                rate in FS/s is q / dt, the kernel works per sample)
 *   2. features: F_m = g(|q - c_m| / sigma_m), g(z) = exp(-z^2/2) from the
 *                generated LUT piezo_gauss_lut_q15 with linear interpolation,
 *                g(z) = 0 for z >= zmax (= 4); m = 0..n_rbf-1
 *   3. density:  w_j = sum_m Theta_jm F_m
 *   4. model:    the KP operators of kp.h advance with u; y = sum_j psi_j w_j
 *
 * Formats:
 *   u_q15, psi_q15, y_q15   q15 (int16).
 *   rate_q24      filtered rate q in FS per sample, q24 (int32); |q| <= 2 FS
 *                 per sample (= 65535 q15 LSB), so |rate_q24| <= 2^25.
 *   alpha_q16     filter coefficient a in q16, 1..65536 (65536: no filtering).
 *   center_q24    Gaussian centers c_m, FS per sample, |c_m| <= 4 (2^26).
 *   inv_width_q16 1 / sigma_m, samples per FS, q16, >= 1 (host computes it:
 *                 no division on the target).
 *   theta_q24     Theta, q24, stored Gaussian by Gaussian:
 *                 theta_q24[m * n_ops + j] = Theta_jm; for every operator j,
 *                 sum_m |Theta_jm| <= INT32_MAX (checked by init), so that
 *                 w_j always fits q24 without saturation.
 *   w_q24         density of the current tick (caller's state array).
 *   feature z     z_q16 = rshift_rnd(|rate_q24 - c_q24| * inv_width_q16, 24);
 *                 LUT index i = z_q16 >> 10 (step zmax / 256 = 2^-6), fraction
 *                 f = z_q16 & 1023, F = L[i] + rshift_rnd((L[i+1] - L[i]) f, 10).
 *
 * Rounding: the one rule (piezo_rshift_rnd, round half up) in the filter, z,
 * the interpolation, the density (q39 -> q24) and the output (q39 -> q15).
 * Saturation: only y is clamped to q15. F is in [0, 32767] by construction.
 *
 * State on reset: psi = 0, u_prev = nmin (as kp.h), rate_q24 = 0, w = 0. The
 * rate estimator sees the same u_prev, so the first sample is a step from nmin.
 *
 * Scaling and overflow: filter: |d_q24 - rate_q24| <= 2^26, times alpha <= 2^16:
 * below 2^42 in int64; the rounded update keeps |rate_q24| <= 65535 * 2^9.
 * z: |rate - c| < 2^27, times inv_width < 2^31: below 2^58 in int64.
 * Density: |Theta_jm F_m| < 2^46, summed over n_rbf <= 32 features below 2^51;
 * with sum_m |Theta_jm| <= INT32_MAX and F <= 32767 < 2^15 the rounded w_j fits
 * int32. Output: as kp.h, below 2^58. No accumulator can overflow.
 */
#ifndef PIEZO_RKP_H
#define PIEZO_RKP_H

#include <stddef.h>
#include <stdint.h>

#include "kp.h"
#include "piezo_err.h"

/* Most Gaussians per density (the paper uses 13). */
#define PIEZO_RKP_MAX_RBF 32u
/* Largest |center_q24|: 4 FS per sample. */
#define PIEZO_RKP_MAX_CENTER_Q24 (1L << 26)

struct piezo_rkp_coeffs {
    struct piezo_kp_grid grid;
    const int32_t *theta_q24;      /* n_rbf * n_ops, theta_q24[m * n_ops + j] */
    const int32_t *center_q24;     /* n_rbf rate centers [FS per sample] */
    const int32_t *inv_width_q16;  /* n_rbf inverse widths [samples per FS] */
    uint16_t n_rbf;                /* 1..PIEZO_RKP_MAX_RBF */
    int32_t alpha_q16;             /* rate filter coefficient, 1..65536 */
};

/* Caller-owned instance; the coefficients may be shared, the state may not. */
struct piezo_rkp {
    const struct piezo_rkp_coeffs *coeffs;
    int16_t *psi_q15;   /* caller's state, n_ops entries */
    int32_t *w_q24;     /* caller's state, n_ops entries: density of the last tick */
    int32_t rate_q24;   /* filtered rate, FS per sample */
    int16_t u_prev_q15; /* previous input */
};

/** g(z) = exp(-z^2/2) for z_q16 >= 0 from the LUT, 0 for z >= zmax. */
int16_t piezo_rkp_gauss_q15(int32_t z_q16);

/**
 * Bind an instance to coefficients and state arrays of n_state entries each
 * (n_state >= n_ops, else PIEZO_ERANGE), check the coefficients and reset.
 * Errors: PIEZO_EINVAL (NULL pointer, alpha, center, width or theta out of
 * range), PIEZO_ERANGE (n_rbf not in 1..PIEZO_RKP_MAX_RBF, state too small),
 * and the grid's errors (piezo_kp_grid_check).
 */
enum piezo_err piezo_rkp_init(struct piezo_rkp *rkp, const struct piezo_rkp_coeffs *coeffs,
                              int16_t *psi_q15, int32_t *w_q24, size_t n_state);

/** Reset state: psi = 0, w = 0, rate = 0, u_prev = nmin. */
void piezo_rkp_reset(struct piezo_rkp *rkp);

/** One sample: rate, features, density, operators; returns y (q15, saturated). */
int16_t piezo_rkp_process(struct piezo_rkp *rkp, int16_t u_q15);

#endif /* PIEZO_RKP_H */
