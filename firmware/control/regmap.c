#include "regmap.h"

#include <stddef.h>
#include <string.h>

#include "piezo_err.h"
#include "piezo_interface.h"
#include "table_image.h"

#define FW_VERSION ((0u << 16) | (1u << 8) | 0u)

/* The interface's enumerations are the wire values; the core kernels keep
 * their own enums (they do not depend on the interface): they must agree.
 * (C99: a negative array size fails the build; int casts: the enums differ.) */
typedef char piezo_wave_kinds_agree[((int)PIEZO_WAVE_KIND_SINE == (int)PIEZO_WAVE_SINE &&
                                     (int)PIEZO_WAVE_KIND_TRIANGLE == (int)PIEZO_WAVE_TRIANGLE &&
                                     (int)PIEZO_WAVE_KIND_MULTISINE == (int)PIEZO_WAVE_MULTISINE &&
                                     (int)PIEZO_WAVE_KIND_CHIRP == (int)PIEZO_WAVE_CHIRP &&
                                     (int)PIEZO_WAVE_KIND_STEPS == (int)PIEZO_WAVE_STEPS &&
                                     (int)PIEZO_WAVE_KIND_ARBITRARY == (int)PIEZO_WAVE_ARBITRARY &&
                                     (int)PIEZO_WAVE_KIND_N == (int)PIEZO_WAVE_ARBITRARY + 1)
                                        ? 1
                                        : -1];
typedef char piezo_rec_triggers_agree[((int)PIEZO_REC_TRIGGER_IMMEDIATE == (int)PIEZO_REC_IMMEDIATE &&
                                       (int)PIEZO_REC_TRIGGER_SOFTWARE == (int)PIEZO_REC_SOFTWARE &&
                                       (int)PIEZO_REC_TRIGGER_RISING == (int)PIEZO_REC_RISING &&
                                       (int)PIEZO_REC_TRIGGER_FALLING == (int)PIEZO_REC_FALLING &&
                                       (int)PIEZO_REC_TRIGGER_N == (int)PIEZO_REC_FALLING + 1 &&
                                       (int)PIEZO_REC_STATE_DONE == (int)PIEZO_REC_DONE &&
                                       (int)PIEZO_REC_STATE_TRIGGERED == (int)PIEZO_REC_TRIGGERED &&
                                       (int)PIEZO_REC_STATE_ARMED == (int)PIEZO_REC_ARMED)
                                          ? 1
                                          : -1];

void piezo_regmap_init(piezo_regmap_t *m, piezo_ctl_t *ctl)
{
    memset(m, 0, sizeof *m);
    m->ctl = ctl;
    m->n_axes = 1u;
    m->tick_hz = 10000u;
    m->fw_version = FW_VERSION;
    m->rec_cfg = ctl->rec.cfg;
    m->params_defaults = ctl->cfg;
    m->params_source = PIEZO_PARAMS_SRC_DEFAULTS;
    m->params_result = PIEZO_PARAMS_REASON_NONE_STORED;
    m->params_ignored = PIEZO_PARAMS_REASON_OK;
    m->params_wave = PIEZO_PARAMS_WAVE_NONE;
}

void piezo_regmap_provision(piezo_regmap_t *m, uint32_t key)
{
    piezo_ctl_stage_t st = {1u, m->axis, m->drive_min_mv, m->drive_max_mv, m->position_min_nm, m->position_max_nm};
    piezo_ctl_set_stage(m->ctl, &st);
    piezo_ctl_set_key(m->ctl, key);
}

/* The controller's clock in ms, from its tick count (between ticks: a
 * division is fine here). */
static uint32_t now_ms(const piezo_regmap_t *m)
{
    uint32_t hz = m->tick_hz != 0u ? m->tick_hz : 10000u;
    return (uint32_t)((uint64_t)m->ctl->st.ticks * 1000u / hz);
}

/* The descriptor holding address a, and the word within it, or NULL. */
static const piezo_reg_desc_t *find(const piezo_reg_desc_t *tab, unsigned n, uint16_t a, uint32_t *word)
{
    for (unsigned i = 0; i < n; i++) {
        uint32_t span = (uint32_t)tab[i].words * tab[i].count;
        if (a >= tab[i].addr && a < tab[i].addr + span) {
            *word = a - tab[i].addr;
            return &tab[i];
        }
    }
    return NULL;
}

static uint16_t word_of(uint32_t v, const piezo_reg_desc_t *d, uint32_t word)
{
    if (d->words == 1u) {
        return (uint16_t)v;
    }
    return (word & 1u) == 0u ? (uint16_t)(v >> 16) : (uint16_t)v; /* high word first */
}

static uint32_t u32_of_i(int32_t v)
{
    return (uint32_t)v;
}

static uint32_t input_value(const piezo_regmap_t *m, const piezo_reg_desc_t *d, uint32_t elem)
{
    const piezo_ctl_t *c = m->ctl;
    (void)elem; /* no input register is an array */
    switch (d->id) {
    case PIEZO_IREG_DEVICE_ID: return 0x505Au;
    case PIEZO_IREG_FW_VERSION: return m->fw_version;
    case PIEZO_IREG_LAYOUT_VERSION: return PIEZO_LAYOUT_VERSION;
    case PIEZO_IREG_INTERFACE_CRC: return PIEZO_INTERFACE_CRC32;
    case PIEZO_IREG_N_AXES: return m->n_axes;
    case PIEZO_IREG_AXIS: return m->axis;
    case PIEZO_IREG_TICK_HZ: return m->tick_hz;
    case PIEZO_IREG_DRIVE_MIN_MV: return u32_of_i(m->drive_min_mv);
    case PIEZO_IREG_DRIVE_MAX_MV: return u32_of_i(m->drive_max_mv);
    case PIEZO_IREG_POSITION_MIN_NM: return u32_of_i(m->position_min_nm);
    case PIEZO_IREG_POSITION_MAX_NM: return u32_of_i(m->position_max_nm);
    case PIEZO_IREG_REC_CAPACITY: return PIEZO_CTL_REC_SAMPLES;
    case PIEZO_IREG_ARMED: return c->st.armed;
    case PIEZO_IREG_FAULTS: return c->st.faults;
    case PIEZO_IREG_TICK_COUNT: return c->st.ticks;
    case PIEZO_IREG_OVERRUNS: return c->st.overruns;
    case PIEZO_IREG_ACTIVE_TABLE_CRC: return piezo_ctl_active_crc(c);
    case PIEZO_IREG_ACTIVE_TABLE_VERSION: return piezo_ctl_active_version(c);
    case PIEZO_IREG_STAGED_TABLE_CRC: return c->staged_crc;
    case PIEZO_IREG_BAD_UNLOCKS: return c->st.bad_unlocks;
    case PIEZO_IREG_TABLE_RESULT: return c->st.table_result;
    case PIEZO_IREG_MODE: return c->mode;
    case PIEZO_IREG_POSITION_Q15: return (uint16_t)c->sig[PIEZO_SIG_Y];
    case PIEZO_IREG_DRIVE_Q15: return (uint16_t)c->sig[PIEZO_SIG_U];
    case PIEZO_IREG_REFERENCE_Q15: return (uint16_t)c->sig[PIEZO_SIG_REF];
    case PIEZO_IREG_ERROR_Q15: return (uint16_t)c->sig[PIEZO_SIG_ERR];
    case PIEZO_IREG_CLAMPS: return c->st.clamps;
    case PIEZO_IREG_TICK_TIME_NS: return m->tick_time_ns;
    case PIEZO_IREG_TICK_TIME_MAX_NS: return m->tick_time_max_ns;
    case PIEZO_IREG_PREVIOUS_TABLE_CRC: return c->previous >= 0 ? c->set[c->previous].crc : 0u;
    case PIEZO_IREG_WAVE_RUNNING: return (uint32_t)piezo_wave_running(&c->wave);
    case PIEZO_IREG_WAVE_FF_N_LIVE: return piezo_ctl_wave_ff_n(c);
    case PIEZO_IREG_WAVE_FF_CAPACITY: return PIEZO_CTL_WAVE_FF_MAX;
    case PIEZO_IREG_REC_STATE: return c->rec.state;
    case PIEZO_IREG_REC_FRAMES: return piezo_rec_frames(&c->rec);
    case PIEZO_IREG_ACTIVE_TABLE_KIND: {
        int8_t a = c->pending >= 0 ? c->pending : c->active;
        return a >= 0 ? c->set[a].kind : 0u;
    }
    case PIEZO_IREG_STAGED_BYTES: return c->staged_len;
    case PIEZO_IREG_COUPLING_TABLE_CRC: return piezo_ctl_coupling_crc(c);
    case PIEZO_IREG_PREVIOUS_TABLE_VERSION: return c->previous >= 0 ? c->set[c->previous].version : 0u;
    case PIEZO_IREG_PREVIOUS_TABLE_KIND: return c->previous >= 0 ? c->set[c->previous].kind : 0u;
    case PIEZO_IREG_PARAMS_RESULT: return m->params_result;
    case PIEZO_IREG_PARAMS_SOURCE: return m->params_source;
    case PIEZO_IREG_PARAMS_SEQ: return m->have_pstore ? piezo_pstore_seq(&m->pstore) : 0u;
    case PIEZO_IREG_PARAMS_IGNORED: return m->params_ignored;
    case PIEZO_IREG_PARAMS_WAVE: return m->params_wave;
    case PIEZO_IREG_REC_WRITTEN: return piezo_rec_written(&c->rec);
    default: return 0u;
    }
}

typedef uint32_t (*value_fn)(const piezo_regmap_t *m, const piezo_reg_desc_t *d, uint32_t elem);

/* Reads `count` registers of one space: each word of each element (32-bit
 * values high word first); an unmapped address refuses the whole read. */
static uint8_t read_space(const piezo_regmap_t *m, const piezo_reg_desc_t *tab, unsigned n, value_fn value,
                          uint16_t addr, uint16_t count, uint16_t *out)
{
    for (uint16_t i = 0; i < count; i++) {
        uint32_t w;
        const piezo_reg_desc_t *d = find(tab, n, (uint16_t)(addr + i), &w);
        if (d == NULL) {
            return PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS;
        }
        out[i] = word_of(value(m, d, d->words == 2u ? w >> 1 : w), d, w);
    }
    return 0u;
}

static uint8_t read_input(void *ctx, uint16_t addr, uint16_t count, uint16_t *out)
{
    return read_space(ctx, piezo_input_regs, PIEZO_IREG_N, input_value, addr, count, out);
}

/* One recorded sample by flattened index (frame * channels + channel). */
static int16_t rec_sample(const piezo_ctl_t *c, uint32_t index)
{
    int16_t frame[PIEZO_REC_MAX_CHANNELS];
    uint32_t nch = c->rec.cfg.n_channels, k;
    if (index >= PIEZO_CTL_REC_SAMPLES) {
        return 0; /* past any recording (as piezo_rec_read would say) */
    }
    /* readout runs between ticks, never in them: a division here is fine
     * (hardware UDIV on the Cortex-M4); the per-register walk it replaces
     * made a full readout quadratic */
    k = index / nch;
    /* ring mode addresses buffer slots (streaming), else frames oldest first */
    if ((c->rec.cfg.ring != 0u ? piezo_rec_read_slot(&c->rec, k, frame) : piezo_rec_read(&c->rec, k, frame)) !=
        PIEZO_OK) {
        return 0;
    }
    return frame[index - k * nch];
}

/* Current value of holding element `elem` (32-bit values whole). */
static uint32_t holding_value(const piezo_regmap_t *m, const piezo_reg_desc_t *d, uint32_t elem)
{
    const piezo_ctl_t *c = m->ctl;
    const piezo_ctl_cfg_t *g = &c->cfg;
    const piezo_wave_cfg_t *w = &c->wave_cfg;
    switch (d->id) {
    case PIEZO_HREG_UNLOCK: return (uint32_t)piezo_ctl_is_unlocked(c, m->session);
    case PIEZO_HREG_UNLOCK_KEY: return 0u;
    case PIEZO_HREG_MODE: return c->mode;
    case PIEZO_HREG_ARM: return c->st.armed;
    case PIEZO_HREG_SETPOINT_Q15: return (uint16_t)c->setpoint_q15;
    case PIEZO_HREG_COMMAND: return 0u;
    case PIEZO_HREG_REF_SOURCE: return c->ref_source;
    case PIEZO_HREG_U2_Q15: return (uint16_t)c->sig[PIEZO_SIG_U2];
    case PIEZO_HREG_WAVE_KIND: return w->kind;
    case PIEZO_HREG_WAVE_OFFSET_Q15: return (uint16_t)w->offset_q15;
    case PIEZO_HREG_WAVE_AMPLITUDE_Q15: return (uint16_t)w->amplitude_q15;
    case PIEZO_HREG_WAVE_FREQ_WORD: return w->freq_word;
    case PIEZO_HREG_WAVE_CHIRP_RATE_WORD: return w->chirp_rate_word;
    case PIEZO_HREG_WAVE_CHIRP_END_WORD: return w->chirp_end_word;
    case PIEZO_HREG_WAVE_CYCLES: return w->cycles;
    case PIEZO_HREG_WAVE_N_TONES: return w->n_tones;
    case PIEZO_HREG_WAVE_N_LEVELS: return w->n_levels;
    case PIEZO_HREG_WAVE_HOLD_TICKS: return w->hold_ticks;
    case PIEZO_HREG_WAVE_TONES: {
        /* 5 registers a tone: amplitude, freq high, freq low, phase high, phase low */
        uint32_t t = 0u, r = elem;
        while (r >= 5u) {
            r -= 5u;
            t++;
        }
        const piezo_wave_tone_t *tone = &c->tones[t];
        switch (r) {
        case 0: return (uint16_t)tone->amplitude_q15;
        case 1: return tone->freq_word >> 16;
        case 2: return tone->freq_word & 0xFFFFu;
        case 3: return tone->phase_word >> 16;
        default: return tone->phase_word & 0xFFFFu;
        }
    }
    case PIEZO_HREG_WAVE_LEVELS: return (uint16_t)c->levels_q15[elem];
    case PIEZO_HREG_WAVE_DURATIONS: return c->durations[elem];
    case PIEZO_HREG_WAVE_FF_N: return m->wave_ff_n;
    case PIEZO_HREG_WAVE_FF_FREQ_WORD: return m->wave_ff_freq_word;
    case PIEZO_HREG_WAVE_FF_COMMAND: return 0u;
    case PIEZO_HREG_WAVE_FF_LEVELS: return elem < PIEZO_CTL_WAVE_FF_MAX ? (uint16_t)c->wave_ff_staged_q15[elem] : 0u;
    case PIEZO_HREG_REC_N_CHANNELS: return m->rec_cfg.n_channels;
    case PIEZO_HREG_REC_SIGNALS: return m->rec_cfg.signal[elem];
    case PIEZO_HREG_REC_DECIMATION: return m->rec_cfg.decimation;
    case PIEZO_HREG_REC_PRETRIGGER: return m->rec_cfg.pretrigger;
    case PIEZO_HREG_REC_TRIGGER: return m->rec_cfg.trigger;
    case PIEZO_HREG_REC_TRIGGER_SIGNAL: return m->rec_cfg.trigger_signal;
    case PIEZO_HREG_REC_TRIGGER_LEVEL_Q15: return (uint16_t)m->rec_cfg.trigger_level_q15;
    case PIEZO_HREG_REC_RING: return m->rec_cfg.ring;
    case PIEZO_HREG_REC_READ_INDEX: return m->rec_read_index;
    case PIEZO_HREG_REC_WINDOW: return (uint16_t)rec_sample(c, m->rec_read_index + elem);
    case PIEZO_HREG_TABLE_OFFSET: return m->table_offset;
    case PIEZO_HREG_TABLE_WINDOW: {
        uint32_t off = m->table_offset + 2u * elem;
        uint32_t lo = off < sizeof c->staged ? c->staged[off] : 0u;
        uint32_t hi = off + 1u < sizeof c->staged ? c->staged[off + 1u] : 0u;
        return lo | (hi << 8);
    }
    case PIEZO_HREG_TABLE_COMMAND: return 0u;
    case PIEZO_HREG_PARAMS_COMMAND: return 0u;
    case PIEZO_HREG_PID_KP_Q24: return u32_of_i(g->pid.kp_q24);
    case PIEZO_HREG_PID_KI_Q24: return u32_of_i(g->pid.ki_q24);
    case PIEZO_HREG_PID_KD_Q24: return u32_of_i(g->pid.kd_q24);
    case PIEZO_HREG_PID_OUT_MIN_Q15: return (uint16_t)g->pid.out_min_q15;
    case PIEZO_HREG_PID_OUT_MAX_Q15: return (uint16_t)g->pid.out_max_q15;
    case PIEZO_HREG_LIMIT_MIN_Q15: return (uint16_t)g->limit.min_q15;
    case PIEZO_HREG_LIMIT_MAX_Q15: return (uint16_t)g->limit.max_q15;
    case PIEZO_HREG_LIMIT_MAX_STEP_Q15: return (uint16_t)g->limit.max_step_q15;
    case PIEZO_HREG_NOTCH_ON: return g->notch_on;
    case PIEZO_HREG_NOTCH_B0_Q24: return u32_of_i(g->notch.b0_q24);
    case PIEZO_HREG_NOTCH_B1_Q24: return u32_of_i(g->notch.b1_q24);
    case PIEZO_HREG_NOTCH_B2_Q24: return u32_of_i(g->notch.b2_q24);
    case PIEZO_HREG_NOTCH_A1_Q24: return u32_of_i(g->notch.a1_q24);
    case PIEZO_HREG_NOTCH_A2_Q24: return u32_of_i(g->notch.a2_q24);
    case PIEZO_HREG_MAX_JUMP_Q15: return (uint16_t)g->max_jump_q15;
    case PIEZO_HREG_BAD_LIMIT: return g->bad_limit;
    case PIEZO_HREG_OVERRUN_LIMIT: return g->overrun_limit;
    case PIEZO_HREG_PREVIEW_TICKS: return g->preview_ticks;
    case PIEZO_HREG_SHAPER_TICKS: return g->shaper_ticks;
    case PIEZO_HREG_SHAPER_Q15: return (uint16_t)g->shaper_q15[elem];
    case PIEZO_HREG_XCOUPLE_BYPASS: return g->xcouple_bypass;
    case PIEZO_HREG_DYNINV_TAPS: return g->dyninv.n_taps;
    case PIEZO_HREG_DYNINV_TICKS: return g->dyninv.spacing;
    case PIEZO_HREG_DYNINV_Q13: return (uint16_t)g->dyninv.h_q13[elem];
    default: return 0u;
    }
}

static uint8_t read_holding(void *ctx, uint16_t addr, uint16_t count, uint16_t *out)
{
    return read_space(ctx, piezo_holding_regs, PIEZO_HREG_N, holding_value, addr, count, out);
}

/* A pending write of one holding element: its new value, composed from the
 * request's words and, for a half-written 32-bit value, the current other half. */
typedef struct {
    const piezo_reg_desc_t *d;
    uint32_t elem;
    uint32_t value;
} pending_t;

#define MAX_PENDING 125u

static int16_t s16(uint32_t v) { return (int16_t)(uint16_t)v; }
static int32_t s32(uint32_t v) { return (int32_t)v; }

/* Is the new value legal for its register, given the unit's state? */
static int legal(const piezo_regmap_t *m, const pending_t *p)
{
    const piezo_ctl_t *c = m->ctl;
    uint32_t v = p->value;
    switch (p->d->id) {
    case PIEZO_HREG_UNLOCK: return v == 0u;
    case PIEZO_HREG_MODE: return v < PIEZO_MODE_N && !c->st.armed;
    case PIEZO_HREG_ARM: return v <= 1u && (v == 0u || c->st.faults == 0u);
    case PIEZO_HREG_COMMAND:
        if (v == PIEZO_CMD_SERVO_OFF) {
            return c->st.armed; /* disarmed, the drive rests at u_safe already */
        }
        if (v == PIEZO_CMD_SERVO_ON) {
            return c->st.armed || c->st.faults == 0u;
        }
        if (v == PIEZO_CMD_ARM_RECORDER) {
            /* arming applies the recorder configuration: it must fit */
            piezo_rec_t trial = c->rec;
            trial.state = PIEZO_REC_IDLE;
            return piezo_rec_configure(&trial, &m->rec_cfg) == PIEZO_OK;
        }
        return v > PIEZO_CMD_NONE && v < PIEZO_CMD_N;
    case PIEZO_HREG_REF_SOURCE: return v < PIEZO_REF_N;
    case PIEZO_HREG_WAVE_KIND: return v < PIEZO_WAVE_KIND_N;
    case PIEZO_HREG_WAVE_N_TONES: return v <= PIEZO_WAVE_MAX_TONES;
    case PIEZO_HREG_WAVE_N_LEVELS: return v <= PIEZO_CTL_WAVE_MAX_LEVELS;
    case PIEZO_HREG_WAVE_FF_N: return v <= PIEZO_CTL_WAVE_FF_MAX; /* 0 and a freq word 0: the commit refuses */
    case PIEZO_HREG_WAVE_FF_COMMAND: return v > PIEZO_WAVE_FF_CMD_NONE && v < PIEZO_WAVE_FF_CMD_N;
    case PIEZO_HREG_WAVE_FF_LEVELS: return p->elem < PIEZO_CTL_WAVE_FF_MAX; /* this target's capacity */
    case PIEZO_HREG_REC_N_CHANNELS: return v >= 1u && v <= PIEZO_REC_MAX_CHANNELS;
    case PIEZO_HREG_REC_SIGNALS:
    case PIEZO_HREG_REC_TRIGGER_SIGNAL: return v < PIEZO_SIG_N;
    case PIEZO_HREG_REC_DECIMATION: return v >= 1u && v <= 0xFFFFu;
    case PIEZO_HREG_REC_TRIGGER: return v < PIEZO_REC_TRIGGER_N;
    case PIEZO_HREG_REC_RING: return v <= 1u;
    case PIEZO_HREG_TABLE_OFFSET: return v < PIEZO_TABLE_MAX_BYTES && (v & 1u) == 0u;
    case PIEZO_HREG_TABLE_WINDOW:
        /* this session's upload, or a new one */
        return piezo_ctl_is_unlocked(c, m->session) &&
               (c->staged_len == 0u || c->staged_owner < 0 || c->staged_owner == (int8_t)m->session);
    case PIEZO_HREG_TABLE_COMMAND:
        return v > PIEZO_TABLE_CMD_NONE && v < PIEZO_TABLE_CMD_N && piezo_ctl_is_unlocked(c, m->session);
    case PIEZO_HREG_PARAMS_COMMAND: return v > PIEZO_PARAMS_CMD_NONE && v < PIEZO_PARAMS_CMD_N; /* refusals: params_result */
    case PIEZO_HREG_BAD_LIMIT: return v >= 1u;
    case PIEZO_HREG_PREVIEW_TICKS: return v <= PIEZO_CTL_MAX_PREVIEW;
    case PIEZO_HREG_SHAPER_TICKS: return v <= PIEZO_CTL_MAX_SHAPER;
    case PIEZO_HREG_XCOUPLE_BYPASS: return v <= 1u;
    case PIEZO_HREG_DYNINV_TAPS: return v <= PIEZO_FIR_MAX_TAPS;
    case PIEZO_HREG_DYNINV_TICKS: return v <= PIEZO_FIR_MAX_SPACING;
    case PIEZO_HREG_MAX_JUMP_Q15:
    case PIEZO_HREG_LIMIT_MAX_STEP_Q15: return s16(v) >= 0;
    default: return 1;
    }
}

/* Stores a configuration value into g; 0 if p is not a configuration register. */
static int apply_config(piezo_ctl_cfg_t *g, const pending_t *p)
{
    uint32_t v = p->value;
    switch (p->d->id) {
    case PIEZO_HREG_PID_KP_Q24: g->pid.kp_q24 = s32(v); break;
    case PIEZO_HREG_PID_KI_Q24: g->pid.ki_q24 = s32(v); break;
    case PIEZO_HREG_PID_KD_Q24: g->pid.kd_q24 = s32(v); break;
    case PIEZO_HREG_PID_OUT_MIN_Q15: g->pid.out_min_q15 = s16(v); break;
    case PIEZO_HREG_PID_OUT_MAX_Q15: g->pid.out_max_q15 = s16(v); break;
    case PIEZO_HREG_LIMIT_MIN_Q15: g->limit.min_q15 = s16(v); break;
    case PIEZO_HREG_LIMIT_MAX_Q15: g->limit.max_q15 = s16(v); break;
    case PIEZO_HREG_LIMIT_MAX_STEP_Q15: g->limit.max_step_q15 = s16(v); break;
    case PIEZO_HREG_NOTCH_ON: g->notch_on = (uint8_t)(v != 0u); break;
    case PIEZO_HREG_NOTCH_B0_Q24: g->notch.b0_q24 = s32(v); break;
    case PIEZO_HREG_NOTCH_B1_Q24: g->notch.b1_q24 = s32(v); break;
    case PIEZO_HREG_NOTCH_B2_Q24: g->notch.b2_q24 = s32(v); break;
    case PIEZO_HREG_NOTCH_A1_Q24: g->notch.a1_q24 = s32(v); break;
    case PIEZO_HREG_NOTCH_A2_Q24: g->notch.a2_q24 = s32(v); break;
    case PIEZO_HREG_MAX_JUMP_Q15: g->max_jump_q15 = s16(v); break;
    case PIEZO_HREG_BAD_LIMIT: g->bad_limit = (uint16_t)v; break;
    case PIEZO_HREG_OVERRUN_LIMIT: g->overrun_limit = (uint16_t)v; break;
    case PIEZO_HREG_PREVIEW_TICKS: g->preview_ticks = (uint8_t)v; break;
    case PIEZO_HREG_SHAPER_TICKS: g->shaper_ticks = (uint8_t)v; break;
    case PIEZO_HREG_SHAPER_Q15: g->shaper_q15[p->elem] = s16(v); break;
    case PIEZO_HREG_XCOUPLE_BYPASS: g->xcouple_bypass = (uint8_t)v; break;
    case PIEZO_HREG_DYNINV_TAPS: g->dyninv.n_taps = (uint8_t)v; break;
    case PIEZO_HREG_DYNINV_TICKS: g->dyninv.spacing = (uint8_t)v; break;
    case PIEZO_HREG_DYNINV_Q13: g->dyninv.h_q13[p->elem] = s16(v); break;
    default: return 0;
    }
    return 1;
}

/* Would the controller accept this configuration? (its modules' own checks) */
static int config_ok(const piezo_ctl_cfg_t *g)
{
    piezo_pid_t pid;
    piezo_biquad_t bq;
    piezo_limit_t lim;
    return piezo_pid_init(&pid, &g->pid) == PIEZO_OK && piezo_biquad_init(&bq, &g->notch) == PIEZO_OK &&
           piezo_limit_init(&lim, &g->limit, 0) == PIEZO_OK && g->bad_limit >= 1u &&
           piezo_fir_check(&g->dyninv) == PIEZO_OK;
}

/* Stores a checked value; runs its action. */
static void apply(piezo_regmap_t *m, const pending_t *p, uint16_t *table_cmd, uint16_t *params_cmd,
                  uint16_t *ff_cmd)
{
    piezo_ctl_t *c = m->ctl;
    piezo_wave_cfg_t *w = &c->wave_cfg;
    uint32_t v = p->value;
    if (apply_config(&c->cfg, p)) {
        return;
    }
    switch (p->d->id) {
    case PIEZO_HREG_UNLOCK: piezo_ctl_lock(c, m->session); break;
    case PIEZO_HREG_UNLOCK_KEY: break; /* done before anything else (write_holding) */
    case PIEZO_HREG_MODE: (void)piezo_ctl_set_mode(c, (uint8_t)v); break;
    case PIEZO_HREG_ARM: (void)piezo_ctl_arm(c, (uint8_t)v); break;
    case PIEZO_HREG_SETPOINT_Q15: c->setpoint_q15 = s16(v); break;
    case PIEZO_HREG_COMMAND:
        switch (v) {
        case PIEZO_CMD_CLEAR_FAULTS: piezo_ctl_clear_faults(c); break;
        case PIEZO_CMD_START_WAVE: (void)piezo_ctl_start_wave(c); break;
        case PIEZO_CMD_START_WAVE_ON_TRIGGER: (void)piezo_ctl_start_wave_on_trigger(c); break;
        case PIEZO_CMD_STOP_WAVE: piezo_ctl_stop_wave(c); break;
        case PIEZO_CMD_ARM_RECORDER:
            piezo_rec_reset(&c->rec);
            (void)piezo_rec_configure(&c->rec, &m->rec_cfg); /* checked in legal() */
            piezo_rec_arm(&c->rec);
            break;
        case PIEZO_CMD_TRIGGER_RECORDER: piezo_rec_trigger(&c->rec); break;
        case PIEZO_CMD_SERVO_OFF: (void)piezo_ctl_servo(c, 0u); break; /* checked in legal() */
        case PIEZO_CMD_SERVO_ON: (void)piezo_ctl_servo(c, 1u); break;
        default: piezo_rec_reset(&c->rec); break;
        }
        break;
    case PIEZO_HREG_REF_SOURCE: c->ref_source = (uint8_t)v; break;
    case PIEZO_HREG_U2_Q15: c->sig[PIEZO_SIG_U2] = s16(v); break;
    case PIEZO_HREG_WAVE_KIND: w->kind = (uint8_t)v; break;
    case PIEZO_HREG_WAVE_OFFSET_Q15: w->offset_q15 = s16(v); break;
    case PIEZO_HREG_WAVE_AMPLITUDE_Q15: w->amplitude_q15 = s16(v); break;
    case PIEZO_HREG_WAVE_FREQ_WORD: w->freq_word = v; break;
    case PIEZO_HREG_WAVE_CHIRP_RATE_WORD: w->chirp_rate_word = v; break;
    case PIEZO_HREG_WAVE_CHIRP_END_WORD: w->chirp_end_word = v; break;
    case PIEZO_HREG_WAVE_CYCLES: w->cycles = v; break;
    case PIEZO_HREG_WAVE_N_TONES: w->n_tones = (uint16_t)v; break;
    case PIEZO_HREG_WAVE_N_LEVELS: w->n_levels = (uint16_t)v; break;
    case PIEZO_HREG_WAVE_HOLD_TICKS: w->hold_ticks = v; break;
    case PIEZO_HREG_WAVE_TONES: {
        uint32_t t = 0u, r = p->elem;
        while (r >= 5u) {
            r -= 5u;
            t++;
        }
        piezo_wave_tone_t *tone = &c->tones[t];
        if (r == 0u) {
            tone->amplitude_q15 = s16(v);
        } else if (r == 1u) {
            tone->freq_word = (tone->freq_word & 0xFFFFu) | (v << 16);
        } else if (r == 2u) {
            tone->freq_word = (tone->freq_word & 0xFFFF0000u) | (v & 0xFFFFu);
        } else if (r == 3u) {
            tone->phase_word = (tone->phase_word & 0xFFFFu) | (v << 16);
        } else {
            tone->phase_word = (tone->phase_word & 0xFFFF0000u) | (v & 0xFFFFu);
        }
        break;
    }
    case PIEZO_HREG_WAVE_LEVELS: c->levels_q15[p->elem] = s16(v); break;
    case PIEZO_HREG_WAVE_DURATIONS: c->durations[p->elem] = v; break;
    case PIEZO_HREG_WAVE_FF_N: m->wave_ff_n = (uint16_t)v; break;
    case PIEZO_HREG_WAVE_FF_FREQ_WORD: m->wave_ff_freq_word = v; break;
    case PIEZO_HREG_WAVE_FF_COMMAND: *ff_cmd = (uint16_t)v; break;
    case PIEZO_HREG_WAVE_FF_LEVELS: c->wave_ff_staged_q15[p->elem] = s16(v); break;
    case PIEZO_HREG_REC_N_CHANNELS: m->rec_cfg.n_channels = (uint8_t)v; break;
    case PIEZO_HREG_REC_SIGNALS: m->rec_cfg.signal[p->elem] = (uint8_t)v; break;
    case PIEZO_HREG_REC_DECIMATION: m->rec_cfg.decimation = (uint16_t)v; break;
    case PIEZO_HREG_REC_PRETRIGGER: m->rec_cfg.pretrigger = v; break;
    case PIEZO_HREG_REC_TRIGGER: m->rec_cfg.trigger = (uint8_t)v; break;
    case PIEZO_HREG_REC_TRIGGER_SIGNAL: m->rec_cfg.trigger_signal = (uint8_t)v; break;
    case PIEZO_HREG_REC_TRIGGER_LEVEL_Q15: m->rec_cfg.trigger_level_q15 = s16(v); break;
    case PIEZO_HREG_REC_RING: m->rec_cfg.ring = (uint8_t)v; break;
    case PIEZO_HREG_REC_READ_INDEX: m->rec_read_index = v; break;
    case PIEZO_HREG_TABLE_OFFSET: m->table_offset = v; break;
    case PIEZO_HREG_TABLE_WINDOW: {
        uint8_t b[2] = {(uint8_t)v, (uint8_t)(v >> 8)};
        (void)piezo_ctl_stage_write(c, m->session, m->table_offset + 2u * p->elem, b, 2u); /* checked */
        break;
    }
    case PIEZO_HREG_TABLE_COMMAND: *table_cmd = (uint16_t)v; break;
    case PIEZO_HREG_PARAMS_COMMAND: *params_cmd = (uint16_t)v; break;
    default: break;
    }
}

/* Checked configuration into the running controller: re-binding resets the
 * filter, the integrator and the preview line (the unit is disarmed). */
static void rebind(piezo_ctl_t *c)
{
    c->fifo_pos = 0u;
    c->shaper_pos = 0u;
    piezo_fir_reset(&c->dyninv, c->setpoint_q15); /* the arm fills it with the reference again */
    (void)piezo_pid_init(&c->pid, &c->cfg.pid);
    (void)piezo_biquad_init(&c->notch, &c->cfg.notch);
    (void)piezo_limit_init(&c->limit, &c->cfg.limit, c->limit.prev_q15);
    piezo_ctl_config_changed(c); /* the tick's cached view of cfg (ref_stages) */
}

/* ---------------------------------------------------------------- parameters
 * The payload of a parameter record (param_store.h) is 16-bit words,
 * little-endian (word k at bytes 2k, 2k + 1):
 *   0, 1  interface CRC, low word first: a record of another register map is refused
 *   2     word count W = PIEZO_PARAMS_WORDS
 *   3     sections: bit 0 = the wave section follows (PARAMS_SECTION_WAVE)
 *   4 ..  the configuration block's register words, PIEZO_PARAMS_FIRST on (W)
 * then the wave section, each register's words as a read gives them (32-bit
 * values high word first):
 *   15          wave_kind .. wave_hold_ticks (0x1100 ..)
 *   40          wave_tones
 *   L, 2 L      wave_levels and wave_durations [0, L), L = the wave_n_levels above
 *   3           the learned feedforward being played: its entries n (0 = none)
 *               and its freq word (high, low)
 *   n           its entries (q15)
 * The wave is saved with the parameters because its learned correction
 * belongs to the settings it was learned with. It is left out (params_wave
 * left_out) when the target's slot has no room for it. */
#define PARAMS_HEAD_WORDS 4u
#define PARAMS_SECTION_WAVE 1u
#define WAVE_REG_WORDS (PIEZO_HOLDING_WAVE_HOLD_TICKS + 2u - PIEZO_HOLDING_WAVE_KIND)
#define WAVE_FF_HEAD_WORDS 3u
#define COMPOSE_WORDS 32u /* words checked or applied per pass (even: 32-bit values stay whole) */
typedef char wave_reg_words_check[(WAVE_REG_WORDS == 15u) ? 1 : -1];

/* One holding register word as a read gives it. */
static uint16_t holding_word(const piezo_regmap_t *m, uint16_t addr)
{
    uint16_t w = 0u;
    (void)read_space(m, piezo_holding_regs, PIEZO_HREG_N, holding_value, addr, 1u, &w);
    return w;
}

/* The wave section's registers, in record order, for a wave of nl levels:
 * the one layout the save, its length and the load walk. */
typedef struct {
    uint16_t addr;
    uint32_t words;
} reg_span_t;
#define WAVE_SPANS 4u

static void wave_spans(uint32_t nl, reg_span_t *sp)
{
    sp[0].addr = PIEZO_HOLDING_WAVE_KIND;
    sp[0].words = WAVE_REG_WORDS; /* holds wave_n_levels: nl of the spans below */
    sp[1].addr = PIEZO_HOLDING_WAVE_TONES;
    sp[1].words = PIEZO_HOLDING_WAVE_TONES_COUNT;
    sp[2].addr = PIEZO_HOLDING_WAVE_LEVELS;
    sp[2].words = nl;
    sp[3].addr = PIEZO_HOLDING_WAVE_DURATIONS;
    sp[3].words = 2u * nl;
}

/* Words of the wave's register spans (without the learned feedforward). */
static uint32_t wave_span_words(const reg_span_t *sp)
{
    uint32_t n = 0u;
    for (unsigned i = 0; i < WAVE_SPANS; i++) {
        n += sp[i].words;
    }
    return n;
}

typedef struct {
    const piezo_regmap_t *m;
    uint16_t sections;
    reg_span_t spans[WAVE_SPANS];
    const piezo_ctl_wave_ff_t *ff;
    uint32_t last_k; /* the word computed last (each word serves two bytes) */
    uint16_t last_w;
} save_ctx_t;

static uint16_t save_word(const save_ctx_t *s, uint32_t k)
{
    const piezo_regmap_t *m = s->m;
    uint32_t n_ff = s->ff != NULL ? s->ff->n : 0u;
    if (k < 2u) {
        return (uint16_t)(PIEZO_INTERFACE_CRC32 >> (16u * k));
    }
    if (k == 2u) {
        return (uint16_t)PIEZO_PARAMS_WORDS;
    }
    if (k == 3u) {
        return s->sections;
    }
    k -= PARAMS_HEAD_WORDS;
    if (k < PIEZO_PARAMS_WORDS) {
        return holding_word(m, (uint16_t)(PIEZO_PARAMS_FIRST + k));
    }
    k -= PIEZO_PARAMS_WORDS;
    for (unsigned i = 0; i < WAVE_SPANS; i++) {
        if (k < s->spans[i].words) {
            return holding_word(m, (uint16_t)(s->spans[i].addr + k));
        }
        k -= s->spans[i].words;
    }
    if (k == 0u) {
        return (uint16_t)n_ff;
    }
    if (k < WAVE_FF_HEAD_WORDS) {
        uint32_t f = s->ff != NULL ? s->ff->freq_word : 0u;
        return (uint16_t)(k == 1u ? f >> 16 : f);
    }
    k -= WAVE_FF_HEAD_WORDS;
    return k < n_ff ? (uint16_t)s->ff->c_q15[k] : 0u;
}

static int save_fill(void *ctx, uint32_t off, uint8_t *buf, uint32_t n)
{
    save_ctx_t *s = ctx;
    for (uint32_t i = 0; i < n; i++) {
        uint32_t k = (off + i) >> 1;
        if (k != s->last_k) {
            s->last_w = save_word(s, k);
            s->last_k = k;
        }
        buf[i] = (uint8_t)(((off + i) & 1u) ? s->last_w >> 8 : s->last_w);
    }
    return 0;
}

/* Words of a stored record, read in order in chunks (no record-sized buffer). */
typedef struct {
    const piezo_pstore_t *ps;
    uint32_t len, off; /* payload bytes; the next word's byte offset */
    uint32_t buf_off, buf_n;
    uint8_t buf[64];
    int err;
} reader_t;

static void reader_at(reader_t *r, const piezo_pstore_t *ps, uint32_t word)
{
    r->ps = ps;
    r->len = piezo_pstore_len(ps);
    r->off = 2u * word;
    r->buf_off = 0u;
    r->buf_n = 0u;
    r->err = 0;
}

static uint16_t next_word(reader_t *r)
{
    uint32_t i;
    if (r->err || r->off + 2u > r->len) {
        r->err = 1;
        return 0u;
    }
    if (r->off < r->buf_off || r->off + 2u > r->buf_off + r->buf_n) {
        uint32_t n = r->len - r->off < sizeof r->buf ? r->len - r->off : (uint32_t)sizeof r->buf;
        if (piezo_pstore_read(r->ps, r->off, r->buf, n) != PIEZO_OK) {
            r->err = 1;
            return 0u;
        }
        r->buf_off = r->off;
        r->buf_n = n;
    }
    i = r->off - r->buf_off;
    r->off += 2u;
    return (uint16_t)(r->buf[i] | (uint16_t)(r->buf[i + 1u] << 8));
}

/* Adds holding register word `addr` (value `word`) to p: 1 when p holds a
 * whole value (its low word was the last), 0 after the high word of a 32-bit
 * value, -1 when addr is no register a write may set. */
static int compose_word(pending_t *p, uint16_t addr, uint16_t word)
{
    uint32_t w;
    const piezo_reg_desc_t *d = find(piezo_holding_regs, PIEZO_HREG_N, addr, &w);
    if (d == NULL || (d->flags & PIEZO_REG_READONLY)) {
        return -1;
    }
    p->d = d;
    p->elem = d->words == 2u ? w >> 1 : w;
    if (d->words == 1u) {
        p->value = word;
    } else if ((w & 1u) == 0u) {
        p->value = (uint32_t)word << 16;
        return 0; /* the low word completes it */
    } else {
        p->value |= word;
    }
    return 1;
}

/* Registers [addr, addr + n) from the record's next n words: each value
 * checked as a register write checks it and, with apply_now, stored. A
 * 32-bit register must lie whole in the n words. 0 or -1. */
static int compose(piezo_regmap_t *m, reader_t *r, uint16_t addr, uint32_t n, int apply_now)
{
    uint16_t unused = 0u;
    pending_t p = {NULL, 0u, 0u};
    int whole = 1;
    for (uint32_t i = 0; i < n; i++) {
        uint16_t word = next_word(r);
        whole = compose_word(&p, (uint16_t)(addr + i), word);
        if (r->err || whole < 0) {
            return -1;
        }
        if (whole == 0) {
            continue;
        }
        if (!legal(m, &p)) {
            return -1;
        }
        if (apply_now) {
            apply(m, &p, &unused, &unused, &unused);
        }
    }
    return whole == 1 ? 0 : -1; /* not half a value at the end */
}

/* The configuration the record's next PIEZO_PARAMS_WORDS words give, checked
 * as a register write checks it (each value legal, the whole accepted by
 * the modules), into out. 0 or -1. */
static int params_config(const piezo_regmap_t *m, reader_t *r, piezo_ctl_cfg_t *out)
{
    piezo_ctl_cfg_t trial = m->ctl->cfg;
    pending_t p = {NULL, 0u, 0u};
    for (uint16_t i = 0; i < PIEZO_PARAMS_WORDS; i++) {
        uint16_t word = next_word(r);
        int whole = compose_word(&p, (uint16_t)(PIEZO_PARAMS_FIRST + i), word);
        if (r->err || whole < 0 || (p.d->flags & PIEZO_REG_CONFIG) == 0u) {
            return -1;
        }
        if (whole == 1 && !legal(m, &p)) {
            return -1;
        }
        if (whole == 1) {
            (void)apply_config(&trial, &p);
        }
    }
    if (!config_ok(&trial)) {
        return -1;
    }
    *out = trial;
    return 0;
}

/* Registers [addr, addr + n) in passes of COMPOSE_WORDS. */
static int compose_all(piezo_regmap_t *m, reader_t *r, uint16_t addr, uint32_t n, int apply_now)
{
    for (uint32_t i = 0; i < n; i += COMPOSE_WORDS) {
        uint32_t k = n - i < COMPOSE_WORDS ? n - i : COMPOSE_WORDS;
        if (compose(m, r, (uint16_t)(addr + i), k, apply_now) != 0) {
            return -1;
        }
    }
    return 0;
}

/* The wave section from r: checked (apply_now 0; nothing changes) or
 * stored and its learned feedforward committed (apply_now 1, after a check
 * passed). Returns a PIEZO_PARAMS_REASON_*. */
static uint16_t wave_section(piezo_regmap_t *m, reader_t *r, int apply_now)
{
    piezo_ctl_t *c = m->ctl;
    reg_span_t sp[WAVE_SPANS];
    uint32_t start = r->off, nl, n_ff, freq;
    if (compose(m, r, PIEZO_HOLDING_WAVE_KIND, WAVE_REG_WORDS, 0) != 0) {
        return PIEZO_PARAMS_REASON_OUT_OF_RANGE;
    }
    /* wave_n_levels (checked against this target's capacity just now) */
    {
        reader_t again = *r;
        again.off = start + 2u * (PIEZO_HOLDING_WAVE_N_LEVELS - PIEZO_HOLDING_WAVE_KIND);
        nl = next_word(&again);
    }
    wave_spans(nl, sp);
    if (apply_now) {
        r->off = start;
        (void)compose(m, r, sp[0].addr, sp[0].words, 1);
    }
    for (unsigned i = 1; i < WAVE_SPANS; i++) {
        if (compose_all(m, r, sp[i].addr, sp[i].words, apply_now) != 0) {
            return PIEZO_PARAMS_REASON_OUT_OF_RANGE;
        }
    }
    n_ff = next_word(r);
    freq = (uint32_t)next_word(r) << 16;
    freq |= next_word(r);
    if (r->err) {
        return PIEZO_PARAMS_REASON_BAD_LENGTH;
    }
    if (n_ff > PIEZO_CTL_WAVE_FF_MAX || (n_ff > 0u && freq == 0u)) {
        return PIEZO_PARAMS_REASON_OUT_OF_RANGE; /* e.g. saved by a target that holds more */
    }
    for (uint32_t k = 0; k < n_ff; k++) {
        uint16_t v = next_word(r);
        if (apply_now) {
            c->wave_ff_staged_q15[k] = (int16_t)v;
        }
    }
    if (r->err || r->off != r->len) {
        return PIEZO_PARAMS_REASON_BAD_LENGTH; /* the section must end the record */
    }
    if (c->wave_ff_pending >= 0) {
        /* a swap the tick has not taken yet (it takes one every tick): nothing is changed */
        return PIEZO_PARAMS_REASON_STORAGE_FAILED;
    }
    if (apply_now) {
        m->wave_ff_n = (uint16_t)n_ff;
        m->wave_ff_freq_word = freq;
        if (n_ff > 0u) {
            (void)piezo_ctl_wave_ff_commit(c, c->wave_ff_staged_q15, (uint16_t)n_ff, freq);
        } else if (piezo_ctl_wave_ff_n(c) != 0u) {
            (void)piezo_ctl_wave_ff_off(c);
        }
    }
    return PIEZO_PARAMS_REASON_OK;
}

/* Load the active record into the controller (boot, params load): every
 * value is checked before anything changes. */
static uint16_t params_load(piezo_regmap_t *m)
{
    piezo_ctl_t *c = m->ctl;
    piezo_ctl_cfg_t cfg;
    reader_t r;
    uint16_t head[PARAMS_HEAD_WORDS], sections, reason;
    uint32_t len, wave_start = PARAMS_HEAD_WORDS + PIEZO_PARAMS_WORDS;
    if (!m->have_pstore) {
        return PIEZO_PARAMS_REASON_STORAGE_FAILED;
    }
    len = piezo_pstore_len(&m->pstore);
    if (len == 0u) {
        return m->pstore.active < 0 ? PIEZO_PARAMS_REASON_NONE_STORED : PIEZO_PARAMS_REASON_STORAGE_FAILED;
    }
    reader_at(&r, &m->pstore, 0u);
    for (uint32_t i = 0; i < PARAMS_HEAD_WORDS; i++) {
        head[i] = next_word(&r);
    }
    if (r.err || ((uint32_t)head[0] | (uint32_t)head[1] << 16) != PIEZO_INTERFACE_CRC32) {
        return PIEZO_PARAMS_REASON_BAD_LAYOUT;
    }
    sections = head[3];
    if (head[2] != PIEZO_PARAMS_WORDS || (len & 1u) != 0u || (sections & ~PARAMS_SECTION_WAVE) != 0u ||
        ((sections & PARAMS_SECTION_WAVE) == 0u && len != 2u * wave_start) || len < 2u * wave_start) {
        return PIEZO_PARAMS_REASON_BAD_LENGTH;
    }
    if (params_config(m, &r, &cfg) != 0) {
        return r.err ? PIEZO_PARAMS_REASON_STORAGE_FAILED : PIEZO_PARAMS_REASON_OUT_OF_RANGE;
    }
    if (sections & PARAMS_SECTION_WAVE) {
        reader_at(&r, &m->pstore, wave_start);
        reason = wave_section(m, &r, 0);
        if (reason != PIEZO_PARAMS_REASON_OK) {
            return reason;
        }
        reader_at(&r, &m->pstore, wave_start);
        (void)wave_section(m, &r, 1);
    }
    c->cfg = cfg;
    rebind(c);
    m->params_source = PIEZO_PARAMS_SRC_FLASH;
    m->params_wave = (sections & PARAMS_SECTION_WAVE) ? PIEZO_PARAMS_WAVE_SAVED : PIEZO_PARAMS_WAVE_NONE;
    return PIEZO_PARAMS_REASON_OK;
}

/* Save the parameters, with the wave and its learned feedforward where the
 * slot has room. */
static uint16_t params_save(piezo_regmap_t *m)
{
    const piezo_ctl_t *c = m->ctl;
    save_ctx_t s;
    uint32_t len, wave_len;
    uint16_t r;
    if (!m->have_pstore) {
        return PIEZO_PARAMS_REASON_STORAGE_FAILED;
    }
    s.m = m;
    wave_spans(c->wave_cfg.n_levels, s.spans);
    s.ff = piezo_ctl_wave_ff_played(c);
    s.last_k = UINT32_MAX;
    s.last_w = 0u;
    len = 2u * (PARAMS_HEAD_WORDS + PIEZO_PARAMS_WORDS);
    wave_len = 2u * (wave_span_words(s.spans) + WAVE_FF_HEAD_WORDS + (s.ff != NULL ? s.ff->n : 0u));
    s.sections = (len + wave_len <= piezo_pstore_capacity(&m->pstore)) ? PARAMS_SECTION_WAVE : 0u;
    if (s.sections) {
        len += wave_len;
    }
    r = piezo_pstore_save_stream(&m->pstore, len, save_fill, &s);
    if (r == PIEZO_PARAMS_REASON_OK) {
        m->params_source = PIEZO_PARAMS_SRC_FLASH;
        m->params_wave = s.sections ? PIEZO_PARAMS_WAVE_SAVED : PIEZO_PARAMS_WAVE_LEFT_OUT;
    }
    return r;
}

/* params_command: save, load or defaults, by an unlocked session on a disarmed unit. */
static void params_command(piezo_regmap_t *m, uint16_t cmd)
{
    piezo_ctl_t *c = m->ctl;
    uint16_t r;
    if (!piezo_ctl_is_unlocked(c, m->session)) {
        r = PIEZO_PARAMS_REASON_LOCKED;
    } else if (c->st.armed) {
        r = PIEZO_PARAMS_REASON_ARMED;
    } else if (cmd == PIEZO_PARAMS_CMD_SAVE) {
        r = params_save(m);
    } else if (cmd == PIEZO_PARAMS_CMD_LOAD) {
        r = params_load(m);
    } else {
        c->cfg = m->params_defaults;
        rebind(c);
        m->params_source = PIEZO_PARAMS_SRC_DEFAULTS;
        r = PIEZO_PARAMS_REASON_OK;
    }
    m->params_result = r;
}

uint16_t piezo_regmap_attach_params(piezo_regmap_t *m, const piezo_storage_t *io)
{
    if (piezo_pstore_open(&m->pstore, io) != PIEZO_OK) {
        m->have_pstore = 0u;
        m->params_result = PIEZO_PARAMS_REASON_STORAGE_FAILED;
        return m->params_result;
    }
    m->have_pstore = 1u;
    m->params_ignored = piezo_pstore_ignored(&m->pstore);
    m->params_result = params_load(m);
    if (m->params_result != PIEZO_PARAMS_REASON_OK && m->params_result != PIEZO_PARAMS_REASON_NONE_STORED) {
        m->params_ignored = m->params_result; /* the active record itself: the defaults run */
    }
    return m->params_result;
}

static uint8_t write_holding(void *ctx, uint16_t addr, uint16_t count, const uint16_t *values)
{
    piezo_regmap_t *m = ctx;
    piezo_ctl_t *c = m->ctl;
    pending_t p[MAX_PENDING];
    unsigned n = 0u;
    uint16_t table_cmd = 0u, params_cmd = 0u, ff_cmd = 0u;
    int config = 0;
    uint32_t offset = m->table_offset;
    if (count > MAX_PENDING) {
        return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
    }
    /* 1. every register exists and is writable; compose element values */
    for (uint16_t i = 0; i < count; i++) {
        uint32_t w;
        const piezo_reg_desc_t *d = find(piezo_holding_regs, PIEZO_HREG_N, (uint16_t)(addr + i), &w);
        uint32_t elem;
        if (d == NULL || (d->flags & PIEZO_REG_READONLY)) {
            return PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS;
        }
        elem = d->words == 2u ? w >> 1 : w;
        if (n == 0u || p[n - 1u].d != d || p[n - 1u].elem != elem) {
            p[n].d = d;
            p[n].elem = elem;
            p[n].value = holding_value(m, d, elem);
            n++;
        }
        if (d->words == 1u) {
            p[n - 1u].value = values[i];
        } else if ((w & 1u) == 0u) {
            p[n - 1u].value = (p[n - 1u].value & 0xFFFFu) | ((uint32_t)values[i] << 16);
        } else {
            p[n - 1u].value = (p[n - 1u].value & 0xFFFF0000u) | values[i];
        }
        config |= (d->flags & PIEZO_REG_CONFIG) != 0u;
    }
    /* 2. the key first: a request may unlock and write (a wrong key, or
     *    one during the backoff, refuses the whole request); then state and
     *    values: configuration needs this session unlocked and a disarmed
     *    unit; every value must be legal */
    for (unsigned i = 0; i < n; i++) {
        if (p[i].d->id == PIEZO_HREG_UNLOCK_KEY) {
            int rc;
            if (addr > p[i].d->addr || addr + count < p[i].d->addr + 2u) {
                return PIEZO_MB_EX_ILLEGAL_DATA_VALUE; /* both halves, one request */
            }
            rc = piezo_ctl_unlock(c, m->session, p[i].value, now_ms(m));
            if (rc == PIEZO_EBUSY) {
                return PIEZO_MB_EX_SERVER_DEVICE_BUSY;
            }
            if (rc != PIEZO_OK) {
                return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
            }
        }
    }
    if (config && (!piezo_ctl_is_unlocked(c, m->session) || c->st.armed)) {
        return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
    }
    for (unsigned i = 0; i < n; i++) {
        if (!legal(m, &p[i])) {
            return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
        }
        if (p[i].d->id == PIEZO_HREG_TABLE_OFFSET) {
            offset = p[i].value; /* a window in the same request lands here */
        } else if (p[i].d->id == PIEZO_HREG_TABLE_WINDOW && offset + 2u * p[i].elem + 2u > PIEZO_TABLE_MAX_BYTES) {
            return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
        }
    }
    if (config) {
        piezo_ctl_cfg_t trial = c->cfg;
        for (unsigned i = 0; i < n; i++) {
            (void)apply_config(&trial, &p[i]);
        }
        if (!config_ok(&trial)) {
            return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
        }
    }
    /* 3. store and act, in address order */
    for (unsigned i = 0; i < n; i++) {
        apply(m, &p[i], &table_cmd, &params_cmd, &ff_cmd);
    }
    if (config) {
        rebind(c);
        m->params_source = PIEZO_PARAMS_SRC_CHANGED;
    }
    switch (table_cmd) {
    case PIEZO_TABLE_CMD_COMMIT: (void)piezo_ctl_commit(c, m->session, 0u); break;
    case PIEZO_TABLE_CMD_ROLLBACK: (void)piezo_ctl_rollback(c, m->session); break;
    case PIEZO_TABLE_CMD_CLEAR_STAGED: (void)piezo_ctl_clear_staged(c, m->session); break;
    default: break;
    }
    if (params_cmd != PIEZO_PARAMS_CMD_NONE) {
        params_command(m, params_cmd);
    }
    /* the learned feedforward last (its count and frequency may come in the
     * same request); a refused commit leaves the played table as it was */
    if (ff_cmd != PIEZO_WAVE_FF_CMD_NONE) {
        int rc = (ff_cmd == PIEZO_WAVE_FF_CMD_COMMIT)
                     ? piezo_ctl_wave_ff_commit(c, c->wave_ff_staged_q15, m->wave_ff_n, m->wave_ff_freq_word)
                     : piezo_ctl_wave_ff_off(c);
        if (rc == PIEZO_EBUSY) {
            return PIEZO_MB_EX_SERVER_DEVICE_BUSY;
        }
        if (rc != PIEZO_OK) {
            return PIEZO_MB_EX_ILLEGAL_DATA_VALUE;
        }
    }
    return 0u;
}

static void session(void *ctx, uint8_t id, uint8_t event)
{
    piezo_regmap_t *m = ctx;
    if (event == PIEZO_MB_SESSION_END) {
        piezo_ctl_end_session(m->ctl, id);
    } else {
        m->session = id;
    }
}

piezo_mb_regs_t piezo_regmap_regs(piezo_regmap_t *m)
{
    piezo_mb_regs_t r = {m, read_input, read_holding, write_holding, session};
    return r;
}
