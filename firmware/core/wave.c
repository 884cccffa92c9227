#include "wave.h"

#include <stddef.h>

#include "fixed_q.h"
#include "piezo_err.h"
#include "piezo_interface.h"

typedef char piezo_sine_lut_size_check_t[(PIEZO_SINE_LUT_N == 1025) ? 1 : -1];

int16_t piezo_sine_q15(uint32_t phase)
{
    /* top 10 bits pick the segment, the next 16 interpolate inside it. In
     * int32: adjacent entries of the table differ by at most 201 (test_wave
     * checks < 2^8), so |(y1 - y0) * frac| < 2^8 * 2^16 = 2^24; the rounded
     * interpolation lies between y0 and y1, a q15 value: no saturation. */
    uint32_t i = phase >> 22;
    int32_t frac = (int32_t)((phase >> 6) & 0xFFFFu);
    int32_t y0 = piezo_sine_lut_q15[i];
    int32_t y1 = piezo_sine_lut_q15[i + 1u];
    return (int16_t)(y0 + (((y1 - y0) * frac + 32768) >> 16));
}

/* offset + rshift_rnd(amplitude * shape, 15), saturated, in int32:
 * |amplitude * shape| <= 2^15 * 2^15 = 2^30 and the rounding half 2^14 keep
 * the product inside int32; the sum is below 2^16 in magnitude. */
static int16_t scale_q15(int32_t offset_q15, int32_t amplitude_q15, int32_t shape_q15)
{
    int32_t y = offset_q15 + ((amplitude_q15 * shape_q15 + (1 << 14)) >> 15);
    return piezo_sat_q15(y); /* (an int32: one SSAT on Cortex-M4) */
}

static int16_t triangle_q15(uint32_t phase)
{
    uint32_t q = phase + 0x40000000u; /* quarter period ahead: start at 0 rising */
    if (q < 0x80000000u) {
        return (int16_t)((int32_t)(q >> 15) - 32768);
    }
    return (int16_t)(32767 - (int32_t)((q - 0x80000000u) >> 15));
}

int piezo_wave_init(piezo_wave_t *w, const piezo_wave_cfg_t *cfg)
{
    if (w == NULL || cfg == NULL) {
        return PIEZO_EINVAL;
    }
    switch (cfg->kind) {
    case PIEZO_WAVE_OFF:
    case PIEZO_WAVE_SINE:
    case PIEZO_WAVE_TRIANGLE:
        break;
    case PIEZO_WAVE_CHIRP:
        if (cfg->chirp_end_word < cfg->freq_word) {
            return PIEZO_EORDER;
        }
        break;
    case PIEZO_WAVE_MULTISINE:
        if (cfg->n_tones == 0u || cfg->tones == NULL) {
            return PIEZO_EINVAL;
        }
        if (cfg->n_tones > PIEZO_WAVE_MAX_TONES) {
            return PIEZO_ERANGE;
        }
        break;
    case PIEZO_WAVE_STEPS:
        if (cfg->n_levels == 0u || cfg->levels_q15 == NULL || cfg->durations == NULL) {
            return PIEZO_EINVAL;
        }
        for (uint16_t i = 0; i < cfg->n_levels; i++) {
            if (cfg->durations[i] == 0u) {
                return PIEZO_EINVAL;
            }
        }
        break;
    case PIEZO_WAVE_ARBITRARY:
        if (cfg->n_levels == 0u || cfg->levels_q15 == NULL || cfg->hold_ticks == 0u) {
            return PIEZO_EINVAL;
        }
        break;
    default:
        return PIEZO_EINVAL;
    }
    w->cfg = cfg;
    piezo_wave_reset(w);
    return PIEZO_OK;
}

void piezo_wave_reset(piezo_wave_t *w)
{
    const piezo_wave_cfg_t *c = w->cfg;
    w->phase = 0u;
    w->freq = c->freq_word;
    w->level = 0u;
    w->held = 0u;
    w->done_cycles = 0u;
    w->running = (uint8_t)(c->kind != PIEZO_WAVE_OFF);
    for (uint16_t i = 0; i < PIEZO_WAVE_MAX_TONES; i++) {
        w->tone_phase[i] = (c->kind == PIEZO_WAVE_MULTISINE && i < c->n_tones) ? c->tones[i].phase_word : 0u;
    }
}

int piezo_wave_running(const piezo_wave_t *w)
{
    return w->running != 0u;
}

/* Counts a finished period or pass and stops a finite wave. */
static void end_of_cycle(piezo_wave_t *w)
{
    w->done_cycles++;
    if (w->cfg->cycles != 0u && w->done_cycles >= w->cfg->cycles) {
        w->running = 0u;
    }
}

/* Advances a level list: steps use per-level durations, arbitrary one hold. */
static int32_t next_level(piezo_wave_t *w, uint32_t hold)
{
    const piezo_wave_cfg_t *c = w->cfg;
    int32_t shape = c->levels_q15[w->level];
    if (++w->held >= hold) {
        w->held = 0u;
        if (++w->level >= c->n_levels) {
            w->level = 0u;
            end_of_cycle(w);
        }
    }
    return shape;
}

int16_t piezo_wave_process(piezo_wave_t *w)
{
    const piezo_wave_cfg_t *c = w->cfg;
    int32_t shape;
    if (!w->running) {
        return c->offset_q15;
    }
    /* the sine, the calibrations' and the scans' wave, tested first: one
     * compare instead of the switch's range test and table branch, then the
     * sine-or-triangle test (the same arithmetic as the triangle's case) */
    if (c->kind == PIEZO_WAVE_SINE) {
        uint32_t next = w->phase + w->freq;
        shape = piezo_sine_q15(w->phase);
        if (next < w->phase) {
            end_of_cycle(w); /* the accumulator wrapped: one period done */
        }
        w->phase = next;
        return scale_q15(c->offset_q15, c->amplitude_q15, shape);
    }
    switch (c->kind) {
    case PIEZO_WAVE_SINE: /* (above) */
    case PIEZO_WAVE_TRIANGLE: {
        shape = (c->kind == PIEZO_WAVE_SINE) ? piezo_sine_q15(w->phase) : triangle_q15(w->phase);
        uint32_t next = w->phase + w->freq;
        if (next < w->phase) {
            end_of_cycle(w); /* the accumulator wrapped: one period done */
        }
        w->phase = next;
        break;
    }
    case PIEZO_WAVE_CHIRP:
        shape = piezo_sine_q15(w->phase);
        w->phase += w->freq;
        if (c->chirp_end_word - w->freq <= c->chirp_rate_word) {
            w->running = 0u; /* reached the last frequency */
        } else {
            w->freq += c->chirp_rate_word;
        }
        break;
    case PIEZO_WAVE_MULTISINE: {
        int32_t sum = 0;
        for (uint16_t i = 0; i < c->n_tones; i++) {
            sum += (int32_t)piezo_rshift_rnd64(
                (int64_t)c->tones[i].amplitude_q15 * piezo_sine_q15(w->tone_phase[i]), 15u);
            w->tone_phase[i] += c->tones[i].freq_word;
        }
        return piezo_sat_q15((int64_t)c->offset_q15 + sum);
    }
    case PIEZO_WAVE_STEPS:
        shape = next_level(w, c->durations[w->level]);
        break;
    case PIEZO_WAVE_ARBITRARY:
        shape = next_level(w, c->hold_ticks);
        break;
    default:
        return c->offset_q15;
    }
    return scale_q15(c->offset_q15, c->amplitude_q15, shape);
}
