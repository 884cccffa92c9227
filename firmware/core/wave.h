/*
 * wave.h - wave generator: sine, triangle, multisine, chirp, steps, arbitrary table.
 *
 * One sample per tick. Periodic shapes run on a 32-bit phase accumulator:
 * phase advances by freq_word = round(f / f_tick * 2^32) each tick (the host
 * computes the words; f resolution at 10 kHz is 2.3 uHz). Output:
 *     y_q15 = sat_q15(offset_q15 + rshift_rnd(amplitude_q15 * shape_q15, 15))
 * with shape in [-1, 1) as q15; multisine sums its tones' own amplitudes.
 *
 * Shapes (q15):
 *   sine      piezo_sine_lut_q15 (1024 segments), linear interpolation on the
 *             top 10 phase bits, 16 fraction bits, rounding rule; starts at 0 rising.
 *   triangle  exact from the phase: starts at 0 rising, peak at 1/4 period.
 *   chirp     sine whose freq_word grows by chirp_rate_word each tick up to
 *             chirp_end_word; the wave finishes there.
 *   multisine sum of up to PIEZO_WAVE_MAX_TONES sines, each with amplitude and
 *             start phase; the sum saturates to q15.
 *   steps     levels_q15[i] held for durations[i] ticks each (dwells of any length).
 *   arbitrary levels_q15[i] held hold_ticks each (1 = one sample per tick).
 *
 * cycles > 0 ends the wave after that many periods (periodic shapes) or passes
 * through the level list (steps, arbitrary); a finished wave outputs offset_q15
 * and piezo_wave_running() turns 0. cycles = 0 runs until reset.
 *
 * Scaling and overflow: products are int32 (|amplitude * shape| <= 2^30, plus
 * the rounding half 2^14); the sine's interpolation is int32 (the table's
 * adjacent entries differ by less than 2^8, times a 16-bit fraction: < 2^24)
 * and lies between two table entries, so it needs no saturation; the
 * multisine sum is int32 (< 8 * 2^15); every output is saturated to q15
 * (test_wave checks the int32 forms against the int64 formulas).
 */
#ifndef PIEZO_WAVE_H
#define PIEZO_WAVE_H

#include <stdint.h>

#define PIEZO_WAVE_MAX_TONES 8u

enum piezo_wave_kind {
    PIEZO_WAVE_OFF = 0,
    PIEZO_WAVE_SINE = 1,
    PIEZO_WAVE_TRIANGLE = 2,
    PIEZO_WAVE_MULTISINE = 3,
    PIEZO_WAVE_CHIRP = 4,
    PIEZO_WAVE_STEPS = 5,
    PIEZO_WAVE_ARBITRARY = 6
};

typedef struct {
    int16_t amplitude_q15; /* peak of this tone */
    uint32_t freq_word;    /* f / f_tick * 2^32 */
    uint32_t phase_word;   /* start phase / (2 pi) * 2^32 */
} piezo_wave_tone_t;

typedef struct {
    uint8_t kind;                   /* enum piezo_wave_kind */
    int16_t offset_q15;
    int16_t amplitude_q15;          /* sine, triangle, chirp, steps, arbitrary */
    uint32_t freq_word;             /* sine, triangle; chirp start */
    uint32_t chirp_rate_word;       /* chirp: freq_word increment per tick */
    uint32_t chirp_end_word;        /* chirp: last frequency */
    uint32_t cycles;                /* 0 = endless */
    uint16_t n_tones;               /* multisine */
    const piezo_wave_tone_t *tones; /* multisine, n_tones entries */
    uint16_t n_levels;              /* steps, arbitrary */
    const int16_t *levels_q15;      /* steps, arbitrary: shape values */
    const uint32_t *durations;      /* steps: ticks per level (each >= 1) */
    uint32_t hold_ticks;            /* arbitrary: ticks per level (>= 1) */
} piezo_wave_cfg_t;

typedef struct {
    const piezo_wave_cfg_t *cfg;
    uint32_t phase;
    uint32_t freq;
    uint32_t tone_phase[PIEZO_WAVE_MAX_TONES];
    uint32_t level;      /* index into levels_q15 */
    uint32_t held;       /* ticks spent on the current level */
    uint32_t done_cycles;
    uint8_t running;
} piezo_wave_t;

/** Check cfg and start the wave from its beginning. Returns a piezo_err code. */
int piezo_wave_init(piezo_wave_t *w, const piezo_wave_cfg_t *cfg);
/** Restart the configured wave from its beginning. */
void piezo_wave_reset(piezo_wave_t *w);
/** Next sample of the wave (q15). */
int16_t piezo_wave_process(piezo_wave_t *w);
/** 1 while the wave runs, 0 once a finite wave has finished (or kind OFF). */
int piezo_wave_running(const piezo_wave_t *w);
/** sin(2 pi phase / 2^32) in q15 from the shared LUT (used by other modules). */
int16_t piezo_sine_q15(uint32_t phase);

#endif /* PIEZO_WAVE_H */
