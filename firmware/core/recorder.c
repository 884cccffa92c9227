#include "recorder.h"

#include <stddef.h>

#include "piezo_err.h"

int piezo_rec_init(piezo_rec_t *r, int16_t *buf_q15, uint32_t buf_len, uint8_t n_signals)
{
    if (r == NULL || buf_q15 == NULL || buf_len == 0u || n_signals == 0u) {
        return PIEZO_EINVAL;
    }
    r->buf_q15 = buf_q15;
    r->n_signals = n_signals;
    r->cfg.n_channels = 1u;
    r->cfg.signal[0] = 0u;
    r->cfg.decimation = 1u;
    r->cfg.pretrigger = 0u;
    r->cfg.trigger = PIEZO_REC_IMMEDIATE;
    r->cfg.trigger_signal = 0u;
    r->cfg.trigger_level_q15 = 0;
    r->cfg.ring = 0u;
    r->buf_len = buf_len;
    r->capacity = buf_len;
    piezo_rec_reset(r);
    return PIEZO_OK;
}

int piezo_rec_configure(piezo_rec_t *r, const piezo_rec_cfg_t *cfg)
{
    uint32_t cap;
    if (cfg == NULL || cfg->n_channels == 0u || cfg->n_channels > PIEZO_REC_MAX_CHANNELS ||
        cfg->decimation == 0u || cfg->trigger > PIEZO_REC_FALLING || cfg->ring > 1u ||
        (cfg->ring != 0u && cfg->pretrigger != 0u) ||
        cfg->trigger_signal >= r->n_signals) {
        return PIEZO_EINVAL;
    }
    if (r->state == PIEZO_REC_ARMED || r->state == PIEZO_REC_TRIGGERED) {
        return PIEZO_EORDER;
    }
    for (uint8_t i = 0; i < cfg->n_channels; i++) {
        if (cfg->signal[i] >= r->n_signals) {
            return PIEZO_EINVAL;
        }
    }
    /* frames that fit: buffer samples / channels, by subtraction (the core
     * links no division, even outside the tick) */
    cap = 0u;
    for (uint32_t left = r->buf_len; left >= cfg->n_channels; left -= cfg->n_channels) {
        cap++;
    }
    if (cfg->pretrigger >= cap) {
        return PIEZO_ERANGE;
    }
    r->cfg = *cfg;
    r->capacity = cap;
    piezo_rec_reset(r);
    return PIEZO_OK;
}

void piezo_rec_reset(piezo_rec_t *r)
{
    r->state = PIEZO_REC_IDLE;
    r->write = 0u;
    r->filled = 0u;
    r->post_left = 0u;
    r->written = 0u;
    r->decim_count = 0u;
    r->have_last = 0u;
}

void piezo_rec_arm(piezo_rec_t *r)
{
    piezo_rec_reset(r);
    r->state = PIEZO_REC_ARMED;
    if (r->cfg.trigger == PIEZO_REC_IMMEDIATE) {
        piezo_rec_trigger(r);
    }
}

void piezo_rec_trigger(piezo_rec_t *r)
{
    if (r->state != PIEZO_REC_ARMED) {
        return;
    }
    /* keep at most `pretrigger` frames from before; fill the rest after */
    if (r->filled > r->cfg.pretrigger) {
        r->filled = r->cfg.pretrigger;
    }
    r->post_left = r->capacity - r->filled;
    if (r->cfg.ring != 0u) {
        /* the ring starts over at slot 0 with the next tick: frame n lands in
         * slot n mod capacity and was taken n * decimation ticks after the trigger */
        r->write = 0u;
        r->filled = 0u;
        r->decim_count = 0u;
    }
    r->written = 0u;
    r->state = PIEZO_REC_TRIGGERED;
}

/* store()'s switch copies up to 8 channels */
typedef char piezo_rec_max_channels_check_t[(PIEZO_REC_MAX_CHANNELS == 8u) ? 1 : -1];

static void store(piezo_rec_t *r, const int16_t *signals_q15)
{
    const uint8_t *sig = r->cfg.signal;
    const uint32_t w = r->write, cap = r->capacity;
    int16_t *frame = r->buf_q15 + (size_t)w * r->cfg.n_channels;
    /* one copy per channel, without a loop (n_channels is 1..8, configure) */
    switch (r->cfg.n_channels) {
    case 8: frame[7] = signals_q15[sig[7]]; /* fall through */
    case 7: frame[6] = signals_q15[sig[6]]; /* fall through */
    case 6: frame[5] = signals_q15[sig[5]]; /* fall through */
    case 5: frame[4] = signals_q15[sig[4]]; /* fall through */
    case 4: frame[3] = signals_q15[sig[3]]; /* fall through */
    case 3: frame[2] = signals_q15[sig[2]]; /* fall through */
    case 2: frame[1] = signals_q15[sig[1]]; /* fall through */
    default: frame[0] = signals_q15[sig[0]]; break;
    }
    /* write and filled from registers: the frame's stores cannot change them
     * (gcc would otherwise reload them after the int16 stores) */
    r->write = (w + 1u == cap) ? 0u : w + 1u;
    if (r->filled < cap) {
        r->filled++;
    }
}

void piezo_rec_process(piezo_rec_t *r, const int16_t *signals_q15)
{
    uint8_t state = r->state;
    /* ARMED (1) or TRIGGERED (2) as one unsigned compare */
    if ((uint8_t)(state - PIEZO_REC_ARMED) > (uint8_t)(PIEZO_REC_TRIGGERED - PIEZO_REC_ARMED)) {
        return;
    }
    /* decimation: decim_count ticks still to skip before the next frame, a
     * countdown from decimation - 1 (0 with decimation 1: every tick); the
     * frames are those of the count-up it replaced, ticks 0, d, 2d, ... after
     * an arm or a ring's trigger, which both set it to 0 */
    if (r->decim_count != 0u) {
        r->decim_count--;
        return;
    }
    r->decim_count = (uint16_t)(r->cfg.decimation - 1u);
    if (state == PIEZO_REC_ARMED) {
        if (r->cfg.trigger == PIEZO_REC_RISING || r->cfg.trigger == PIEZO_REC_FALLING) {
            int16_t v = signals_q15[r->cfg.trigger_signal];
            int16_t lvl = r->cfg.trigger_level_q15;
            if (r->have_last &&
                ((r->cfg.trigger == PIEZO_REC_RISING && r->last_trigger_q15 < lvl && v >= lvl) ||
                 (r->cfg.trigger == PIEZO_REC_FALLING && r->last_trigger_q15 > lvl && v <= lvl))) {
                piezo_rec_trigger(r); /* from ARMED: always to TRIGGERED */
                state = PIEZO_REC_TRIGGERED;
            }
            r->last_trigger_q15 = v;
            r->have_last = 1u;
        }
    }
    store(r, signals_q15);
    if (state != PIEZO_REC_TRIGGERED) {
        return; /* still armed: a pretrigger frame */
    }
    r->written++; /* after the store: a reader never sees a counted frame half written */
    if (r->cfg.ring == 0u && --r->post_left == 0u) {
        r->state = PIEZO_REC_DONE;
    }
}


uint32_t piezo_rec_frames(const piezo_rec_t *r)
{
    return r->filled;
}

int piezo_rec_read(const piezo_rec_t *r, uint32_t k, int16_t *out_q15)
{
    uint32_t slot;
    if (out_q15 == NULL || k >= r->filled) {
        return PIEZO_ERANGE;
    }
    /* oldest frame sits `filled` slots behind the write position */
    slot = (r->write >= r->filled) ? r->write - r->filled : r->write + r->capacity - r->filled;
    slot += k;
    if (slot >= r->capacity) {
        slot -= r->capacity;
    }
    for (uint8_t i = 0; i < r->cfg.n_channels; i++) {
        out_q15[i] = r->buf_q15[(size_t)slot * r->cfg.n_channels + i];
    }
    return PIEZO_OK;
}

uint32_t piezo_rec_written(const piezo_rec_t *r)
{
    return r->written;
}

int piezo_rec_read_slot(const piezo_rec_t *r, uint32_t slot, int16_t *out_q15)
{
    if (out_q15 == NULL || slot >= r->filled) {
        return PIEZO_ERANGE; /* the ring fills slots 0, 1, ... in order */
    }
    for (uint8_t i = 0; i < r->cfg.n_channels; i++) {
        out_q15[i] = r->buf_q15[(size_t)slot * r->cfg.n_channels + i];
    }
    return PIEZO_OK;
}
