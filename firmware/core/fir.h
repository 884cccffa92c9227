/*
 * fir.h - the dynamics-inverse FIR of the feedforward path: a filter on the
 * early reference (controller.h, tick step 4c) whose taps the host designs
 * so that the stage's dynamics times this filter is a pure delay of the
 * preview over the band the calibration identified
 * (host/piezoctl/calibrate/dyninv.py, docs/calibrate.md "The dynamics inverse").
 *
 * Per call, with the new sample x(t) (q15) and taps h_k (q13), k = 0..n-1,
 * spaced d ticks apart:
 *   y(t) = sat_q15(rshift_rnd(sum_k h_k x(t - k d), 13))
 * one rounding (piezo_rshift_rnd64: round half toward +infinity) and one
 * saturation, nothing else. host/piezoctl/golden/fir.py is the bit-exact twin
 * (golden vectors: tests/firmware/test_fir.c).
 *
 * Formats: x, y q15 (Q0.15); h q13 (int16, Q2.13: [-4, 4 - 2^-13], LSB
 * 1.2e-4). A gain of 1 is 8192; the taps of a unity-DC-gain inverse sum to
 * 8192. The spacing d (1..PIEZO_FIR_MAX_SPACING; 0 reads as 1) lets 32 taps
 * span 32 d ticks: a low first mode (140 Hz) needs a longer span than the
 * 3.2 ms of d = 1, at the price of a response that repeats every tick rate / d.
 *
 * Scaling and overflow: |h_k x| <= 2^15 * 2^15 = 2^30 per tap, at most
 * 2^5 taps: |acc| <= 2^35, far inside int64; no intermediate can overflow for
 * any taps and any input. The result is saturated to q15 (a filter with gain
 * above 1 on a reference near full scale): sat_q15 is the only clamp.
 *
 * History: a ring of PIEZO_FIR_HIST = 256 samples indexed by a uint8_t
 * position, so the wrap is the integer's own (no compare); it holds the last
 * (n - 1) d + 1 <= 31 * 8 + 1 = 249 samples. reset fills it with a constant
 * (a reference that has been x0 forever: no step out of the filter).
 * No division, no floating point.
 */
#ifndef PIEZO_FIR_H
#define PIEZO_FIR_H

#include <stdint.h>

#include "piezo_interface.h"

#define PIEZO_FIR_MAX_TAPS PIEZO_HOLDING_DYNINV_Q13_COUNT /* 32: interface.toml dyninv_q13 */
#define PIEZO_FIR_MAX_SPACING 8u
#define PIEZO_FIR_HIST 256u
#define PIEZO_FIR_Q13_FRAC 13u

typedef char piezo_fir_hist_check_t[((PIEZO_FIR_MAX_TAPS - 1u) * PIEZO_FIR_MAX_SPACING + 1u <= PIEZO_FIR_HIST &&
                                     PIEZO_FIR_HIST == 256u) ? 1 : -1];

typedef struct {
    uint8_t n_taps;                      /* 0 = off (the tick skips the filter), 1..PIEZO_FIR_MAX_TAPS */
    uint8_t spacing;                     /* ticks between taps, 1..PIEZO_FIR_MAX_SPACING (0 reads as 1) */
    int16_t h_q13[PIEZO_FIR_MAX_TAPS];   /* taps, q13; h_q13[0] weighs the newest sample */
} piezo_fir_coef_t;

typedef struct {
    int16_t hist_q15[PIEZO_FIR_HIST];
    uint8_t pos;                         /* where the next sample goes */
} piezo_fir_t;

/** PIEZO_OK, or PIEZO_EINVAL for n_taps > PIEZO_FIR_MAX_TAPS or spacing > PIEZO_FIR_MAX_SPACING. */
int piezo_fir_check(const piezo_fir_coef_t *k);

/** History = x0 everywhere (a constant input: the output is the DC gain times x0 at once). */
void piezo_fir_reset(piezo_fir_t *f, int16_t x0_q15);

/** One sample in, one out (see the formula above). Call only with n_taps >= 1. */
int16_t piezo_fir_q13_process(piezo_fir_t *f, const piezo_fir_coef_t *k, int16_t x_q15);

#endif /* PIEZO_FIR_H */
