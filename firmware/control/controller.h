/*
 * controller.h - one axis of the piezo controller: the 10 kHz tick and the
 * commands the protocol layer issues between ticks.
 *
 * The tick, in this fixed order (controller.c):
 *   1. swap in a committed coefficient set (only here: a tick boundary);
 *      a servo off/on request (piezo_ctl_servo) switches mode and
 *      reference here too, so no tick sees half of it
 *   2. read the ADC code and check it (plausibility: inside the sensor's
 *      valid code range, and no jump larger than max_jump per tick; bad_limit
 *      consecutive bad samples raise the sensor fault)
 *   3. scale the sensor: y = sat_q15(rshift_rnd((adc - adc_zero) * sensor_gain_q16, 16))
 *   4. reference: the wave generator, or the host's setpoint. With a preview
 *      of D ticks the feedforward sees the reference D ticks early and
 *      everything else (error, feedback, recorder) sees it on time, so the
 *      stage's own lag (transport delay, amplifier, the tick) is cancelled for
 *      any reference the controller generates itself. An input shaper
 *      (three taps at 0, m and 2m ticks, e.g. zero-vibration-derivative for
 *      the first mode) smooths the early reference before the feedforward,
 *      so the compensated drive does not excite the resonance; its delay of
 *      m ticks is part of what the preview cancels. Then the dynamics
 *      inverse (fir.h, off with dyninv.n_taps = 0): an FIR the host designs
 *      so that the stage's linear dynamics times the filter is a delay of
 *      preview_ticks over the identified band (calibrate/dyninv.py); with
 *      that preview the stage then follows the reference on time, whatever
 *      the reference (a streamed setpoint, a random scan), not only a
 *      periodic one. It runs after the shaper; the calibration configures
 *      it instead of the shaper (shaper_ticks = 0), since its taps already
 *      hold the first mode's inverse (docs/calibrate.md)
 *   5. feedforward (modes FEEDFORWARD and FF_FEEDBACK): the active table's
 *      EUPI inverse or DCC law, chosen by the table's kind; in OPEN_LOOP the
 *      table's straight line u_ff = r g + o (coefset.h); no table, or
 *      DIRECT: u_ff = r (the reference read as a drive)
 *   6. feedback (FF_FEEDBACK, FEEDBACK): e = r - y, u_fb = notch(PID(e))
 *   7. u = sat_q15(u_ff + u_fb); disarmed or IDLE: u = u_safe
 *      cross-coupling compensation (a cross_coupling table loaded): the
 *      xcouple kernel predicts, from the other axis' drive (sig[PIEZO_SIG_U2]) and a
 *      position (this axis' y or the other's y2, as the table says), the
 *      drive that the coupling from the other axis is worth on this axis;
 *      in FEEDFORWARD, FF_FEEDBACK and FEEDBACK (not DIRECT, OPEN_LOOP or
 *      with xcouple_bypass) u = sat_q15(u - u_xc). The kernel runs every
 *      tick while a table is loaded, so its filters follow u2 in any mode
 *   8. clamp and slew-limit, then the DAC code:
 *      code = clamp(dac_zero + rshift_rnd(u * dac_gain_q16, 16), dac_min, dac_max)
 *   9. recorder, status counters
 * A fault (sensor, repeated overruns) disarms: the drive ramps to u_safe at
 * the slew limit and stays there until the host clears the faults and re-arms.
 * The DCC operators follow the drive actually applied (after feedback, clamp
 * and slew limit); they start from their reset state (the input rested at
 * the bottom of the plane), which matches a stage resting at u_safe when
 * u_safe is the bottom of the drive range.
 *
 * Commands (piezo_ctl_*) run in the main context, never inside the tick. The
 * only data they share with the tick are single-word flags and indices.
 */
#ifndef PIEZO_CONTROLLER_H
#define PIEZO_CONTROLLER_H

#include <stdint.h>

#include "coefset.h"
#include "fir.h"
#include "piezo_interface.h"
#include "pid.h"
#include "recorder.h"
#include "store.h"
#include "wave.h"

/* The mode (enum piezo_enum_mode: PIEZO_MODE_*), the reference source (enum
 * piezo_enum_ref_source: PIEZO_REF_*) and the recorder's signal ids (enum
 * piezo_enum_rec_signals: PIEZO_SIG_*, all q15) are the interface's enumerations
 * (common/interface.toml [enums], generated into piezo_interface.h). */

/* Sizes a target may override (-D): the host's defaults fill a 10 kHz run of
 * 6.5 s on one channel; a 128 KiB microcontroller takes fewer. */
#ifndef PIEZO_CTL_REC_SAMPLES
#define PIEZO_CTL_REC_SAMPLES 65536u /* recorder buffer, samples of all channels */
#endif
#define PIEZO_CTL_WAVE_MAX_LEVELS 256u
#ifndef PIEZO_CTL_WAVE_FF_MAX /* learned feedforward entries (a small target may take fewer, -D) */
#define PIEZO_CTL_WAVE_FF_MAX PIEZO_HOLDING_WAVE_FF_LEVELS_COUNT
#endif
typedef char piezo_ctl_wave_ff_max_check_t[(PIEZO_CTL_WAVE_FF_MAX >= 2u &&
                                            PIEZO_CTL_WAVE_FF_MAX <= PIEZO_HOLDING_WAVE_FF_LEVELS_COUNT) ? 1 : -1];
#define PIEZO_CTL_WAVE_FF_OFF 2 /* wave_ff_pending: switch the learned feedforward off */

/* The learned feedforward of a periodic wave (iterative learning control,
 * host/piezoctl/calibrate/ilc.py): a position correction c (q15 of the
 * position half-range, like the reference) tabulated at n_q15 entries spread
 * evenly over one period of freq_word. While the wave runs it is added to the
 * loop's reference, in sync with it: the feedforward sees r_ahead + c at the
 * same phase, the feedback the error (r + c) - y at the phase preview_ticks
 * earlier, so the correction goes through the whole closed loop (whose gain
 * is close to 1 where the learning acts). The recorder's ref and err stay the
 * true reference r and r - y, the errors the learning minimizes. */
typedef struct {
    int16_t c_q15[PIEZO_CTL_WAVE_FF_MAX];
    uint16_t n;          /* entries over one period, 1..PIEZO_CTL_WAVE_FF_MAX */
    uint32_t freq_word;  /* periods per tick * 2^32 */
} piezo_ctl_wave_ff_t;

typedef struct {
    int32_t adc_zero;          /* ADC code of zero displacement */
    int32_t sensor_gain_q16;   /* q15 LSB per ADC code */
    int32_t adc_min_ok;        /* plausible ADC codes: [adc_min_ok, adc_max_ok] */
    int32_t adc_max_ok;
    int16_t max_jump_q15;      /* largest plausible change of y per tick; 0 = off */
    uint16_t bad_limit;        /* consecutive implausible samples before the fault, >= 1 */
    uint16_t overrun_limit;    /* consecutive overruns before the fault; 0 = never */
    int16_t u_safe_q15;        /* drive while disarmed or idle (e.g. the code of 0 V) */
    int32_t dac_zero;          /* DAC code of u = 0 */
    int32_t dac_gain_q16;      /* DAC codes per q15 LSB of u */
    int32_t dac_min;           /* DAC code range */
    int32_t dac_max;
    piezo_limit_coef_t limit;  /* output clamp and slew limit (q15) */
    piezo_pid_coef_t pid;
    piezo_biquad_coef_t notch;
    uint8_t notch_on;
    uint8_t preview_ticks;     /* feedforward look-ahead, 0..PIEZO_CTL_MAX_PREVIEW */
    uint8_t shaper_ticks;      /* tap spacing m, 0 = no shaper, 1..PIEZO_CTL_MAX_SHAPER */
    int16_t shaper_q15[3];     /* taps at 0, m, 2m; they should sum to 32768 (unity DC gain) */
    uint8_t xcouple_bypass;    /* 1: a loaded coupling table is not applied */
    piezo_fir_coef_t dyninv;   /* dynamics-inverse FIR on the early reference; n_taps 0 = off */
} piezo_ctl_cfg_t;

#define PIEZO_CTL_MAX_PREVIEW 96u
#define PIEZO_CTL_MAX_SHAPER 64u

typedef struct {
    uint8_t armed;
    uint32_t faults;           /* PIEZO_FAULT_* bits (latched until cleared) */
    uint32_t ticks;
    uint32_t overruns;         /* ticks the target reported as late */
    uint32_t clamps;           /* ticks whose drive was clamped or slew-limited */
    uint32_t bad_unlocks;      /* wrong unlock keys */
    uint16_t table_result;     /* reason code of the last table command */
} piezo_ctl_status_t;

/* Sessions: who holds an unlock and owns the staged upload. A transport
 * numbers its sessions 0..PIEZO_CTL_SESSIONS-2 (TCP: one per connection
 * slot; RTU: the line); the last one is the target's own code
 * (piezo_ctl_load_image). */
#define PIEZO_CTL_SESSIONS 8u
#define PIEZO_CTL_SESSION_LOCAL 7u

/* The stage a controller drives, as its identity registers say; an image
 * built for another one is refused (wrong_stage, wrong_axis). known = 0: the
 * target does not say, and nothing is compared. */
typedef struct {
    uint8_t known;
    uint16_t axis;
    int32_t drive_min_mv, drive_max_mv;
    int32_t position_min_nm, position_max_nm;
} piezo_ctl_stage_t;

typedef struct {
    piezo_ctl_cfg_t cfg;
    piezo_ctl_status_t st;
    uint8_t mode;
    uint8_t ref_source;
    int16_t setpoint_q15;
    /* 1: a request for the tick boundary is published (pending, xc_pending,
     * wave_ff_pending or servo_req); step 1 of the tick looks at those only
     * then. Set after the request itself (both volatile: in that order), cleared
     * by the tick. */
    volatile uint8_t boundary_req;
    /* &ff[active] and &set[active], NULL with no table: written with active
     * (set_active, controller.c: at init, at boot's load and by the tick's
     * swap), read by the tick's step 5 instead of indexing both arrays */
    piezo_ff_state_t *ff_act;
    const piezo_coefset_t *set_act;

    /* The tick's own state, here near the start: the tick addresses it from
     * the instance pointer without a base register per 4 KiB (issue 15,
     * round 14); the large arrays follow. */
    piezo_pid_t pid;
    piezo_biquad_t notch;
    piezo_limit_t limit;
    piezo_rec_t rec;
    /* The signals of the last tick (q15), the recorder's and the register
     * map's copy. sig[PIEZO_SIG_U2], the other axis' drive, is an input as
     * well and lives only here (no copy per tick, round 16): the input of the
     * cross-coupling compensation, recorded as signal u2. A multi-axis target
     * sets it before each tick from the other axis' controller (sil_loop.c:
     * that controller's drive of the previous tick, the same for both axes);
     * elsewhere the host may write it (register u2_q15); the tick never
     * writes it. */
    int16_t sig[PIEZO_SIG_N];
    int16_t y_prev_q15;
    uint16_t bad_run;
    uint16_t overrun_run;      /* overruns with no tick completed between them */
    uint8_t have_y;
    /* the sensor's jump test, its bound: 2 max_jump, or UINT32_MAX with the
     * test off or before the first good sample (controller.c, read_sensor);
     * written only by init and the tick (step 1 derives it again after any
     * request, a configuration change too: piezo_ctl_config_changed) */
    uint32_t jump_span;
    volatile int8_t xc_active; /* the coupling slot in use (xset, xc below), -1 = none */
    int16_t xc_q15;            /* last compensation term u_xc (drive, q15) */
    piezo_wave_t wave;
    /* the learned feedforward's slots (wave_ff, below): the one played and
     * the one the tick takes over */
    volatile int8_t wave_ff_active;  /* slot played, -1 = none */
    volatile int8_t wave_ff_pending; /* committed slot for the tick, PIEZO_CTL_WAVE_FF_OFF, or -1 */
    uint32_t wave_ff_phase;          /* phase of r_ahead; restarts with the wave */
    int16_t wave_ff_q15;             /* last correction added to the feedforward reference */
    volatile uint8_t wave_on_trigger; /* 1: start the wave when the recorder triggers */
    /* 1: a stage between the reference and the feedforward may act (the
     * preview, the learned feedforward's slot, the shaper, the dynamics
     * inverse: piezo_ctl_ref_stages_of); 0: the tick skips them with one test
     * (issue 15, round 16). Written only by init and the tick's step 1: every
     * path that changes one of those fields (the configuration: rebind in
     * regmap.c through piezo_ctl_config_changed; the slot: the tick's swap)
     * has the tick's next step 1 compute it again. */
    uint8_t ref_stages;

    /* feedforward tables: the active set, the previous one (rollback) and a
     * free one that a commit fills; the tick swaps a committed set in */
    piezo_coefset_t set[3];
    piezo_ff_state_t ff[3];
    volatile int8_t active;    /* index into set[], -1 = no table */
    volatile int8_t pending;   /* committed set waiting for the tick, -1 = none */
    int8_t previous;           /* rollback target, -1 = none */
    volatile uint8_t servo_req; /* 0 none, 1 servo off, 2 servo on: done by the tick (step 1) */

    /* cross-coupling table: slots of its own, committed, swapped at the tick
     * boundary and rolled back like the feedforward sets; RAM only (the flash
     * store keeps the feedforward table) */
    piezo_xcset_t xset[3];
    struct piezo_xc xc[3];
    volatile int8_t xc_pending;
    int8_t xc_previous;
    uint8_t last_commit_xc;    /* 1: the last good commit was a coupling table (rollback acts on it) */

    /* staged bank: the image being uploaded */
    uint8_t staged[PIEZO_TABLE_MAX_BYTES];
    uint32_t staged_len;
    uint32_t staged_crc;       /* CRC field of the last complete staged image */
    int8_t staged_owner;       /* session that staged it, -1 = none */
    uint8_t unlocked;          /* bit s: session s is unlocked */
    uint32_t key;              /* provisioned unlock key, 0 = none (every unlock refused) */
    uint32_t unlock_bad_run;   /* wrong keys in a row (any session) */
    uint32_t bad_at_ms;        /* when the last one came */
    piezo_ctl_stage_t stage;
    piezo_store_t store;
    uint8_t have_store;
    uint32_t overrun_tick;     /* st.ticks at the last overrun (piezo_ctl_overrun) */

    piezo_wave_cfg_t wave_cfg;
    piezo_wave_tone_t tones[PIEZO_WAVE_MAX_TONES];
    int16_t levels_q15[PIEZO_CTL_WAVE_MAX_LEVELS];
    uint32_t durations[PIEZO_CTL_WAVE_MAX_LEVELS];
    /* learned feedforward: entries staged by the host, two slots (one played,
     * one a commit fills), swapped at the tick boundary like the tables */
    int16_t wave_ff_staged_q15[PIEZO_CTL_WAVE_FF_MAX];
    piezo_ctl_wave_ff_t wave_ff[2];
    /* (the slots' indices and phase are with the tick's state, above) */

    int16_t rec_buf[PIEZO_CTL_REC_SAMPLES];

    int16_t ref_fifo[PIEZO_CTL_MAX_PREVIEW]; /* the reference, preview_ticks behind */
    uint8_t fifo_pos;
    int16_t shaper_hist[2u * PIEZO_CTL_MAX_SHAPER + 1u]; /* early reference history */
    uint8_t shaper_pos;
    piezo_fir_t dyninv;        /* the dynamics inverse's history (the shaped early reference) */
} piezo_ctl_t;

/** Initialize with a configuration; no table, disarmed, IDLE. Returns a piezo_err code. */
int piezo_ctl_init(piezo_ctl_t *c, const piezo_ctl_cfg_t *cfg);

/** Attach persistent storage and boot the stored active table, if any.
 *  Returns the reason code of loading it (OK also when there is none). */
uint16_t piezo_ctl_attach_store(piezo_ctl_t *c, const piezo_storage_t *io);

/** The configuration (cfg) changed between two ticks: the next tick's step 1
 *  derives what it caches from it again (ref_stages, jump_span). Whoever writes cfg
 *  after init calls it, after the write (regmap.c's rebind). */
void piezo_ctl_config_changed(piezo_ctl_t *c);

/** What ref_stages should be for the present configuration and slot: 1 when
 *  the preview, the learned feedforward's slot, the shaper or the dynamics
 *  inverse is on. */
uint8_t piezo_ctl_ref_stages_of(const piezo_ctl_t *c);

/** The 10 kHz tick: adc[0] this axis' sensor code, adc[1] the other axis'
 *  (or 0); returns this axis' DAC code (the target's tick passes it on in a
 *  register: no store and load through a pointer, round 16). */
int32_t piezo_ctl_step(piezo_ctl_t *c, const int32_t adc[2]);

/** The tick with the DAC code written to *dac. */
static inline void piezo_ctl_tick(piezo_ctl_t *c, const int32_t adc[2], int32_t *dac)
{
    *dac = piezo_ctl_step(c, adc);
}

/** The target reports that a tick started late or ran past its period. */
void piezo_ctl_overrun(piezo_ctl_t *c);

/* Commands (main context). Each returns 0 or a piezo_err code. */
int piezo_ctl_set_mode(piezo_ctl_t *c, uint8_t mode);
int piezo_ctl_arm(piezo_ctl_t *c, uint8_t on);
void piezo_ctl_clear_faults(piezo_ctl_t *c);
/** Servo off (on = 0): open loop holding the drive applied now. The setpoint
 *  becomes that drive, the reference source the setpoint, the mode DIRECT,
 *  the wave stops, the preview line and shaper history are filled with it:
 *  the next ticks apply the same drive (no jump). Only while armed
 *  (PIEZO_EORDER otherwise: disarmed, the drive is u_safe already).
 *  Servo on (on = 1): closed loop at the present position. The setpoint
 *  becomes the position y, the reference source the setpoint, the mode
 *  FEEDBACK; the PID integrator is preloaded with the drive applied now
 *  (clamped to the PID's output range) and the notch's history with its
 *  steady state, so the first feedback output equals that drive (no jump).
 *  A disarmed unit is armed (PIEZO_EORDER with faults). */
int piezo_ctl_servo(piezo_ctl_t *c, uint8_t on);
int piezo_ctl_start_wave(piezo_ctl_t *c);  /* from wave_cfg; triggers a SOFTWARE recorder */
/** Start the wave at the tick the armed recorder triggers, e.g. on the other
 *  axis' drive u2 crossing a level: the wave's first sample is the next
 *  tick's, in step with the other axis' wave. Now: the wave is checked (its
 *  error returned, nothing changed), loaded at its start, and the reference
 *  holds its offset (source setpoint) until the trigger; then the tick only
 *  switches the source to the wave and restarts the learned feedforward. */
int piezo_ctl_start_wave_on_trigger(piezo_ctl_t *c);
/** Commit the learned feedforward: copy staged[0 .. n) and freq_word into the
 *  slot not being played; the tick plays it from its next start (step 1).
 *  PIEZO_EINVAL: n outside 1..PIEZO_CTL_WAVE_FF_MAX or freq_word 0, staged
 *  NULL; PIEZO_EBUSY: the previous commit not yet taken by a tick. A refused
 *  commit changes nothing: the slot being played is never written. */
int piezo_ctl_wave_ff_commit(piezo_ctl_t *c, const int16_t *staged_q15, uint16_t n, uint32_t freq_word);
/** Stop playing the learned feedforward (from the next tick). PIEZO_EBUSY as above. */
int piezo_ctl_wave_ff_off(piezo_ctl_t *c);
/** The learned feedforward the tick plays, or takes at its next start (a
 *  commit pending); NULL = none. */
const piezo_ctl_wave_ff_t *piezo_ctl_wave_ff_played(const piezo_ctl_t *c);

/** Entries of the learned feedforward played (0 = none; a pending commit counts). */
uint16_t piezo_ctl_wave_ff_n(const piezo_ctl_t *c);
void piezo_ctl_stop_wave(piezo_ctl_t *c);

/* Provisioning: the unlock key (>= 32 bits; 0 = none, every unlock refused)
 * and the stage this controller drives. */
void piezo_ctl_set_key(piezo_ctl_t *c, uint32_t key);
void piezo_ctl_set_stage(piezo_ctl_t *c, const piezo_ctl_stage_t *stage);

/* Unlock, per session. A wrong key returns PIEZO_EKEY; from
 * PIEZO_UNLOCK_BACKOFF_AFTER wrong keys in a row (any session) every unlock
 * is refused with PIEZO_EBUSY for a backoff that doubles with each further
 * wrong key, and from PIEZO_UNLOCK_LOCKOUT_AFTER for PIEZO_UNLOCK_LOCKOUT_MS.
 * now_ms: the caller's clock (wraps at 2^32). */
int piezo_ctl_unlock(piezo_ctl_t *c, uint8_t session, uint32_t key, uint32_t now_ms);
/** Milliseconds until an unlock is considered again (0: now). */
uint32_t piezo_ctl_unlock_wait_ms(const piezo_ctl_t *c, uint32_t now_ms);
int piezo_ctl_is_unlocked(const piezo_ctl_t *c, uint8_t session);
void piezo_ctl_lock(piezo_ctl_t *c, uint8_t session);
/** The session ended (connection closed): its unlock and its upload go. */
void piezo_ctl_end_session(piezo_ctl_t *c, uint8_t session);

/* Tables. The staged bank belongs to the session that wrote its first byte;
 * another session's write, clear or commit is refused (not_owner). */
int piezo_ctl_stage_write(piezo_ctl_t *c, uint8_t session, uint32_t offset, const uint8_t *data, uint32_t len);
int piezo_ctl_clear_staged(piezo_ctl_t *c, uint8_t session);
/** Check and commit the staged image (len 0: all staged bytes). */
uint16_t piezo_ctl_commit(piezo_ctl_t *c, uint8_t session, uint32_t len);
/** Stage a whole image and commit it in the target's own session: for a
 *  target that loads a table compiled into it (or a test). Every check of a
 *  commit but the sweep runs (the sweep checks tables that arrive over a
 *  session and tables booted from the store). Returns the reason. */
uint16_t piezo_ctl_load_image(piezo_ctl_t *c, const uint8_t *img, uint32_t len);
uint16_t piezo_ctl_rollback(piezo_ctl_t *c, uint8_t session);
/** CRC of the active cross-coupling table (0 when none). */
uint32_t piezo_ctl_coupling_crc(const piezo_ctl_t *c);
/** CRC and version of the active table (0, 0 when none). */
uint32_t piezo_ctl_active_crc(const piezo_ctl_t *c);
uint32_t piezo_ctl_active_version(const piezo_ctl_t *c);

#endif /* PIEZO_CONTROLLER_H */
