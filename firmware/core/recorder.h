/*
 * recorder.h - data recorder: a ring buffer of chosen q15 signals, triggered,
 * read out later (over the protocol, between ticks).
 *
 * Each tick the control loop hands the recorder an array of all its signals
 * (indexed by signal id); the recorder keeps n_channels of them every
 * `decimation` ticks as one frame. States: IDLE -> (arm) ARMED -> (trigger)
 * TRIGGERED -> DONE. While ARMED it records continuously, so up to
 * `pretrigger` frames before the trigger are kept; after the trigger it
 * records until the buffer holds capacity frames in all (or fewer if fewer
 * pretrigger frames had been seen), then stops. Frames are read back in
 * time order, frame 0 the oldest.
 *
 * Ring mode (cfg.ring = 1, for captures longer than the buffer): after the
 * trigger the recorder never stops; it keeps overwriting its oldest frame
 * until reset, and `written` counts the frames stored since the trigger.
 * The trigger restarts the ring at slot 0 and the decimation count, so frame
 * n (taken n * decimation ticks after the trigger's tick: 0 = the first tick
 * processed after it) sits in slot n mod capacity until frame n + capacity
 * replaces it; a reader between ticks streams the capture with
 * piezo_rec_read_slot() and knows from `written` which slots still hold
 * the frames it wants (written - n < capacity). Ring mode keeps no
 * pretrigger frames (pretrigger must be 0). `written` wraps at 2^32
 * (about 5 days at 10 kHz).
 *
 * Triggers: IMMEDIATE (on arm), SOFTWARE (piezo_rec_trigger(), e.g. the wave
 * generator's start), RISING / FALLING (the trigger signal crosses
 * trigger_level_q15 upward / downward between two decimated samples).
 *
 * No arithmetic on the samples: they are stored as given (no rounding).
 * Indices wrap by comparison, not by modulo (no division in the tick).
 */
#ifndef PIEZO_RECORDER_H
#define PIEZO_RECORDER_H

#include <stdint.h>

#define PIEZO_REC_MAX_CHANNELS 8u

enum piezo_rec_state { PIEZO_REC_IDLE = 0, PIEZO_REC_ARMED = 1, PIEZO_REC_TRIGGERED = 2, PIEZO_REC_DONE = 3 };
enum piezo_rec_trigger { PIEZO_REC_IMMEDIATE = 0, PIEZO_REC_SOFTWARE = 1, PIEZO_REC_RISING = 2, PIEZO_REC_FALLING = 3 };

typedef struct {
    uint8_t n_channels;                        /* 1..PIEZO_REC_MAX_CHANNELS */
    uint8_t signal[PIEZO_REC_MAX_CHANNELS];    /* signal id of each channel */
    uint16_t decimation;                       /* keep every n-th tick, >= 1 */
    uint32_t pretrigger;                       /* frames kept before the trigger, < capacity */
    uint8_t trigger;                           /* enum piezo_rec_trigger */
    uint8_t trigger_signal;                    /* signal id for RISING / FALLING */
    int16_t trigger_level_q15;
    uint8_t ring;                              /* 1: keep recording after the trigger (ring mode) */
} piezo_rec_cfg_t;

typedef struct {
    piezo_rec_cfg_t cfg;
    int16_t *buf_q15;          /* caller-owned, capacity * n_channels samples */
    uint32_t buf_len;          /* samples in buf_q15 */
    uint32_t capacity;         /* frames: buf_len / n_channels */
    uint8_t n_signals;         /* length of the signal array given each tick */
    uint8_t state;             /* enum piezo_rec_state */
    uint32_t write;            /* next frame slot */
    uint32_t filled;           /* frames held, <= capacity */
    uint32_t post_left;        /* frames still to record after the trigger */
    uint32_t written;          /* frames stored since the trigger (wraps at 2^32) */
    uint16_t decim_count;      /* ticks still to skip before the next frame (counts down) */
    int16_t last_trigger_q15;
    uint8_t have_last;
} piezo_rec_t;

/** Bind a caller-owned buffer of buf_len samples; n_signals is the size of the
 *  per-tick signal array. Returns a piezo_err code. */
int piezo_rec_init(piezo_rec_t *r, int16_t *buf_q15, uint32_t buf_len, uint8_t n_signals);
/** Configure (only while not armed). Returns a piezo_err code. */
int piezo_rec_configure(piezo_rec_t *r, const piezo_rec_cfg_t *cfg);
/** Drop any recording and go IDLE. */
void piezo_rec_reset(piezo_rec_t *r);
/** Start recording; an IMMEDIATE trigger fires at once. */
void piezo_rec_arm(piezo_rec_t *r);
/** Fire the trigger (ARMED only). */
void piezo_rec_trigger(piezo_rec_t *r);
/** One tick: signals_q15 holds n_signals values indexed by signal id. */
void piezo_rec_process(piezo_rec_t *r, const int16_t *signals_q15);
/** Frames available for readout (DONE: all; otherwise those recorded so far). */
uint32_t piezo_rec_frames(const piezo_rec_t *r);
/** Copy frame k (0 = oldest) to out (n_channels values). Returns a piezo_err code. */
int piezo_rec_read(const piezo_rec_t *r, uint32_t k, int16_t *out_q15);
/** Frames stored since the trigger (ring mode: the streaming position). */
uint32_t piezo_rec_written(const piezo_rec_t *r);
/** Copy buffer slot `slot` (ring mode: frame n is in slot n mod capacity) to
 *  out (n_channels values). PIEZO_ERANGE for a slot not yet written. */
int piezo_rec_read_slot(const piezo_rec_t *r, uint32_t slot, int16_t *out_q15);

#endif /* PIEZO_RECORDER_H */
