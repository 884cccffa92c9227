#include "controller.h"

#include <stddef.h>
#include <string.h>

#include "fixed_q.h"
#include "piezo_err.h"
#include "piezo_interface.h"
#include "table_image.h"

/* The tick's own state lies within the first 4 KiB of the instance (an
 * LDR/STR immediate offset reaches 4095 bytes): the tick addresses it from
 * the instance pointer, with no base register per 4 KiB (controller.h). */
typedef char piezo_ctl_tick_state_near_check_t[(offsetof(piezo_ctl_t, ref_stages) < 4096u) ? 1 : -1];

/* The active feedforward set and the tick's pointers to it (ff_act,
 * set_act), always together. */
static void set_active(piezo_ctl_t *c, int8_t a)
{
    c->active = a;
    c->ff_act = a >= 0 ? &c->ff[a] : NULL;
    c->set_act = a >= 0 ? &c->set[a] : NULL;
}

static uint32_t jump_span_of(const piezo_ctl_t *c);

int piezo_ctl_init(piezo_ctl_t *c, const piezo_ctl_cfg_t *cfg)
{
    int rc;
    if (c == NULL || cfg == NULL || cfg->bad_limit == 0u || cfg->dac_min > cfg->dac_max ||
        cfg->adc_min_ok > cfg->adc_max_ok || cfg->max_jump_q15 < 0 || cfg->preview_ticks > PIEZO_CTL_MAX_PREVIEW ||
        cfg->shaper_ticks > PIEZO_CTL_MAX_SHAPER || piezo_fir_check(&cfg->dyninv) != PIEZO_OK) {
        return PIEZO_EINVAL;
    }
    memset(c, 0, sizeof *c);
    c->cfg = *cfg;
    set_active(c, -1);
    c->pending = -1;
    c->previous = -1;
    c->xc_active = -1;
    c->xc_pending = -1;
    c->xc_previous = -1;
    c->staged_owner = -1;
    c->wave_ff_active = -1;
    c->wave_ff_pending = -1;
    c->wave_cfg.kind = PIEZO_WAVE_OFF;
    c->ref_stages = piezo_ctl_ref_stages_of(c);
    c->jump_span = jump_span_of(c);
    if ((rc = piezo_pid_init(&c->pid, &c->cfg.pid)) != PIEZO_OK ||
        (rc = piezo_biquad_init(&c->notch, &c->cfg.notch)) != PIEZO_OK ||
        (rc = piezo_limit_init(&c->limit, &c->cfg.limit, cfg->u_safe_q15)) != PIEZO_OK ||
        (rc = piezo_wave_init(&c->wave, &c->wave_cfg)) != PIEZO_OK ||
        (rc = piezo_rec_init(&c->rec, c->rec_buf, PIEZO_CTL_REC_SAMPLES, PIEZO_SIG_N)) != PIEZO_OK) {
        return rc;
    }
    return PIEZO_OK;
}

static uint16_t check_stage(const piezo_ctl_t *c, const piezo_table_info_t *info);

/* A cross-coupling image into the coupling slot that is neither active nor
 * previous. */
static uint16_t load_xc_spare(piezo_ctl_t *c, const piezo_table_info_t *info, int8_t *spare)
{
    int8_t i = 0;
    while (i == c->xc_active || i == c->xc_previous) {
        i++;
    }
    *spare = i;
    return piezo_xcset_load_info(&c->xset[i], &c->xc[i], info);
}

/* Loads an image into the set that is neither active nor previous and binds
 * its kernel state; neither of those is touched. */
static uint16_t load_spare(piezo_ctl_t *c, const piezo_table_info_t *info, int8_t *spare, int sweep)
{
    uint16_t r;
    int8_t i = 0;
    while (i == c->active || i == c->previous) {
        i++;
    }
    *spare = i;
    r = piezo_coefset_load_info(&c->set[*spare], &c->ff[*spare], info);
    if (r == PIEZO_TABLE_REASON_OK && sweep) {
        /* the kernel over the whole reference range, here: never in the tick */
        r = piezo_coefset_sweep(&c->set[*spare], &c->ff[*spare], NULL);
        if (r != PIEZO_TABLE_REASON_OK) {
            c->set[*spare].kind = 0u;
        }
    }
    if (r == PIEZO_TABLE_REASON_OK && piezo_ff_bind(&c->ff[*spare], &c->set[*spare]) != PIEZO_OK) {
        c->set[*spare].kind = 0u;
        r = PIEZO_TABLE_REASON_OUT_OF_RANGE;
    }
    return r;
}

uint16_t piezo_ctl_attach_store(piezo_ctl_t *c, const piezo_storage_t *io)
{
    uint32_t len;
    int8_t spare;
    uint16_t r;
    piezo_table_info_t info;
    if (piezo_store_open(&c->store, io, c->staged) != PIEZO_OK) {
        return PIEZO_TABLE_REASON_STORAGE_FAILED;
    }
    c->have_store = 1u;
    len = piezo_store_load(&c->store, 0, c->staged, sizeof c->staged);
    if (len == 0u) {
        return PIEZO_TABLE_REASON_OK; /* nothing stored yet */
    }
    if ((r = piezo_table_check(c->staged, len, &info)) != PIEZO_TABLE_REASON_OK ||
                   (r = piezo_table_check_specs(&info)) != PIEZO_TABLE_REASON_OK ||
        (r = check_stage(c, &info)) != PIEZO_TABLE_REASON_OK || (r = load_spare(c, &info, &spare, 1)) != PIEZO_TABLE_REASON_OK) {
        return r;
    }
    set_active(c, spare); /* before the first tick: no swap needed */
    /* the previous table, kept loaded so a rollback needs no flash read */
    len = piezo_store_load(&c->store, 1, c->staged, sizeof c->staged);
    if (len != 0u && piezo_table_check(c->staged, len, &info) == PIEZO_TABLE_REASON_OK &&
        piezo_table_check_specs(&info) == PIEZO_TABLE_REASON_OK && check_stage(c, &info) == PIEZO_TABLE_REASON_OK && load_spare(c, &info, &spare, 1) == PIEZO_TABLE_REASON_OK) {
        c->previous = spare;
    }
    memset(c->staged, 0, sizeof c->staged);
    return PIEZO_TABLE_REASON_OK;
}

static void reset_loop_state(piezo_ctl_t *c)
{
    /* the preview line starts full of the present reference: no jump at arm */
    int16_t r0 = (c->ref_source == PIEZO_REF_WAVE) ? c->wave_cfg.offset_q15 : c->setpoint_q15;
    for (uint8_t i = 0; i < PIEZO_CTL_MAX_PREVIEW; i++) {
        c->ref_fifo[i] = r0;
    }
    for (uint8_t i = 0; i < 2u * PIEZO_CTL_MAX_SHAPER + 1u; i++) {
        c->shaper_hist[i] = r0;
    }
    piezo_fir_reset(&c->dyninv, r0);
    c->fifo_pos = 0u;
    c->shaper_pos = 0u;
    piezo_pid_reset(&c->pid);
    piezo_biquad_reset(&c->notch);
    if (c->active >= 0) {
        (void)piezo_ff_bind(&c->ff[c->active], &c->set[c->active]);
    }
    if (c->xc_active >= 0) {
        piezo_xc_reset(&c->xc[c->xc_active]);
    }
}

/* Three-tap input shaper on the early reference: sum_i a_i r(k - i m), one
 * rounding, saturated. The history is a ring of 2m + 1 samples. */
static int16_t shape(piezo_ctl_t *c, int16_t r)
{
    const piezo_ctl_cfg_t *g = &c->cfg;
    uint8_t m = g->shaper_ticks, n = (uint8_t)(2u * m + 1u), i1, i2;
    int64_t acc;
    if (m == 0u) {
        return r;
    }
    c->shaper_hist[c->shaper_pos] = r;
    i1 = (uint8_t)(c->shaper_pos >= m ? c->shaper_pos - m : c->shaper_pos + n - m);
    i2 = (uint8_t)(i1 >= m ? i1 - m : i1 + n - m);
    acc = (int64_t)g->shaper_q15[0] * r + (int64_t)g->shaper_q15[1] * c->shaper_hist[i1] +
          (int64_t)g->shaper_q15[2] * c->shaper_hist[i2];
    if (++c->shaper_pos >= n) {
        c->shaper_pos = 0u;
    }
    return piezo_sat_q15(piezo_rshift_rnd64(acc, 15u));
}

/* A sensor code's offset d (ADC codes) times the gain (q15 LSB per code,
 * q16) as q15: sat_q15(rshift_rnd64(d gain, 16)), with the range tested
 * before the shift. s = d gain + 2^15 lies in int32 iff s >> 16 lies in q15,
 * so one compare of the high word with the low word's sign, then one shift,
 * gives the same integer as the 64-bit shift, its range test and the SSAT
 * (about 5 instructions less per sensor on the Cortex-M4). */
static inline int16_t sensor_q15(int32_t d, int32_t gain_q16)
{
    const int64_t s = (int64_t)d * gain_q16 + ((int64_t)1 << 15);
    const int32_t lo = (int32_t)s, hi = (int32_t)(s >> 32);
    if (__builtin_expect(hi == (lo >> 31), 1)) { /* in line: the out-of-range case out of it */
        return (int16_t)(lo >> 16);
    }
    return hi < 0 ? PIEZO_Q15_MIN : PIEZO_Q15_MAX;
}

/* The jump test's bound (jump_span): 2 max_jump when the test is on
 * (max_jump > 0) and a good sample has been seen, else none (UINT32_MAX:
 * every jump passes). */
static uint32_t jump_span_of(const piezo_ctl_t *c)
{
    return (c->cfg.max_jump_q15 > 0 && c->have_y) ? 2u * (uint32_t)c->cfg.max_jump_q15 : UINT32_MAX;
}

/* A bad sample: counted (the fault at bad_limit in a row), the last good
 * value held. Out of line (round 17): the good path then keeps y alone. */
static __attribute__((noinline)) int16_t bad_sample(piezo_ctl_t *c)
{
    if (++c->bad_run >= c->cfg.bad_limit) {
        c->bad_run = c->cfg.bad_limit;
        c->st.faults |= PIEZO_FAULT_SENSOR_IMPLAUSIBLE;
    }
    return c->y_prev_q15;
}

/* Sensor plausibility: a code outside the valid range, or a jump no stage can
 * make in one tick. Bad samples hold the last good value. */
static int16_t read_sensor(piezo_ctl_t *c, int32_t code)
{
    const piezo_ctl_cfg_t *g = &c->cfg;
    int16_t y = sensor_q15(code - g->adc_zero, g->sensor_gain_q16);
    int32_t jump = (int32_t)y - c->y_prev_q15;
    /* |jump| > max as one unsigned compare: jump + max lies outside [0, 2 max]
     * (max in (0, 32767], |jump| <= 65535: no overflow); with the test off,
     * jump_span is UINT32_MAX and nothing lies above it (the tests of
     * max_jump > 0 and of have_y are in jump_span, derived when either
     * changes: init, the tick's step 1, the first good sample) */
    int bad = code < g->adc_min_ok || code > g->adc_max_ok ||
              (uint32_t)(jump + g->max_jump_q15) > c->jump_span;
    if (__builtin_expect(bad, 0)) {
        return bad_sample(c);
    }
    c->bad_run = 0u;
    c->y_prev_q15 = y;
    if (!c->have_y) {
        c->have_y = 1u; /* once: the jump test starts with the next sample */
        c->jump_span = jump_span_of(c);
    }
    return y;
}

/* Fill the preview line and the shaper history with r: a reference that has
 * been r forever (no step out of the delay lines). */
static void fill_reference(piezo_ctl_t *c, int16_t r)
{
    for (uint8_t i = 0; i < PIEZO_CTL_MAX_PREVIEW; i++) {
        c->ref_fifo[i] = r;
    }
    for (uint8_t i = 0; i < 2u * PIEZO_CTL_MAX_SHAPER + 1u; i++) {
        c->shaper_hist[i] = r;
    }
    piezo_fir_reset(&c->dyninv, r);
}

/* The servo switch, at a tick boundary (piezo_ctl_servo). u_now is the
 * drive the limit applied at the last tick. Off: hold it open loop (DIRECT
 * with the setpoint = that drive). On: FEEDBACK at the last position, the
 * integrator (q39) and the notch history preloaded so that e = 0 gives u_now. */
static void servo_switch(piezo_ctl_t *c, uint8_t req)
{
    int16_t u_now = c->limit.prev_q15;
    c->wave.running = 0u;
    c->wave_on_trigger = 0u; /* a pending start goes with the wave */
    c->ref_source = PIEZO_REF_SETPOINT;
    if (req == 1u) {
        if (!c->st.armed) {
            return;
        }
        c->setpoint_q15 = u_now;
        fill_reference(c, u_now);
        c->mode = PIEZO_MODE_DIRECT;
        return;
    }
    {
        const piezo_pid_coef_t *k = &c->cfg.pid;
        int16_t u = u_now < k->out_min_q15 ? k->out_min_q15 : (u_now > k->out_max_q15 ? k->out_max_q15 : u_now);
        c->setpoint_q15 = c->sig[PIEZO_SIG_Y];
        fill_reference(c, c->setpoint_q15);
        piezo_pid_reset(&c->pid);
        c->pid.integ_q39 = (int64_t)u * ((int64_t)1 << 24);
        c->pid.out_q15 = u;
        piezo_biquad_reset(&c->notch);
        c->notch.x1_q15 = u;
        c->notch.x2_q15 = u;
        c->notch.y1_q31 = (int32_t)u * 65536;
        c->notch.y2_q31 = (int32_t)u * 65536;
        c->mode = PIEZO_MODE_FEEDBACK;
    }
}

/* The learned feedforward at phase ph: linear interpolation between the two
 * entries around ph * n / 2^32 (the 16 fraction bits below the index), one
 * rounding (piezo_rshift_rnd64), wrapping from the last entry to the first.
 * Scaling: |b - a| < 2^16, times a fraction < 2^16: < 2^32 in int64; the
 * result lies between two q15 entries, so it needs no saturation. */
static int16_t wave_ff_at(const piezo_ctl_wave_ff_t *t, uint32_t ph)
{
    uint64_t pos = (uint64_t)ph * t->n;
    uint32_t i = (uint32_t)(pos >> 32), j = (i + 1u >= t->n) ? 0u : i + 1u;
    int32_t frac = (int32_t)((pos >> 16) & 0xFFFFu), a = t->c_q15[i], b = t->c_q15[j];
    return (int16_t)(a + piezo_rshift_rnd64((int64_t)(b - a) * frac, 16u));
}

uint8_t piezo_ctl_ref_stages_of(const piezo_ctl_t *c)
{
    const piezo_ctl_cfg_t *g = &c->cfg;
    return (uint8_t)(g->preview_ticks != 0u || c->wave_ff_active >= 0 || g->shaper_ticks != 0u ||
                     g->dyninv.n_taps != 0u);
}

void piezo_ctl_config_changed(piezo_ctl_t *c)
{
    c->boundary_req = 1u; /* the tick derives ref_stages and jump_span (only it writes them after init) */
}

/* The stages between the reference and the feedforward (step 4a-4c): r_ahead
 * in; out r_ahead, r and r_loop packed in bits 0, 16 and 32 (r0:r1 on the
 * Cortex-M4). Out of the tick's line (round 17): in line, gcc kept the three
 * in three registers and copied the reference into each on the stage-free
 * path (3 instructions a tick); out of line the stages pay a call and the
 * packing instead (8 more a tick on reference_dyninv32). */
static __attribute__((noinline)) uint64_t ref_stages_run(piezo_ctl_t *c, int16_t r_ahead, uint32_t wave_on)
{
    const piezo_ctl_cfg_t *g = &c->cfg;
    int16_t r = r_ahead, r_loop;
    if (g->preview_ticks != 0u) {
        r = c->ref_fifo[c->fifo_pos];
        c->ref_fifo[c->fifo_pos] = r_ahead;
        if (++c->fifo_pos >= g->preview_ticks) {
            c->fifo_pos = 0u;
        }
    }
    /* 4b. the wave's learned feedforward, in sync with it (controller.h):
     *     r_ahead + c(phase), and for the error r + c(phase - preview) */
    r_loop = r;
    c->wave_ff_q15 = 0;
    if (wave_on != 0u && c->wave_ff_active >= 0) {
        const piezo_ctl_wave_ff_t *t = &c->wave_ff[c->wave_ff_active];
        c->wave_ff_q15 = wave_ff_at(t, c->wave_ff_phase);
        r_ahead = piezo_sat_q15((int32_t)r_ahead + c->wave_ff_q15);
        r_loop = piezo_sat_q15((int32_t)r +
                               wave_ff_at(t, c->wave_ff_phase - (uint32_t)g->preview_ticks * t->freq_word));
        c->wave_ff_phase += t->freq_word;
    }

    /* 4c. shaper, then the dynamics inverse (none with 0 taps: one compare) */
    r_ahead = shape(c, r_ahead);
    if (g->dyninv.n_taps != 0u) {
        r_ahead = piezo_fir_q13_process(&c->dyninv, &g->dyninv, r_ahead);
    }
    return (uint16_t)r_ahead | (uint64_t)(uint16_t)r << 16 | (uint64_t)(uint16_t)r_loop << 32;
}

/* a mode's bit in the tick's mask of the running mode */
#define MODE_BIT(m) (1u << (m))

int32_t piezo_ctl_step(piezo_ctl_t *c, const int32_t adc[2])
{
    const piezo_ctl_cfg_t *g = &c->cfg;
    int16_t y, r, r_loop, r_ahead, u_ff = 0, u_fb = 0, u;
    int8_t pend;
    uint8_t mode = c->mode, rec_was;
    int run;
    uint32_t wave_on;
    uint32_t mb;
    int32_t dac; /* returned: no pointer kept and no store through it (round 16) */

    /* 1. a committed table takes over only here, between two ticks; one
     *    flag says whether anything waits (most ticks: one load and branch) */
    if (c->boundary_req != 0u) {
        c->boundary_req = 0u; /* before the requests are read: one published meanwhile sets it again */
        pend = c->pending;
        if (pend >= 0) {
            set_active(c, pend);
            c->pending = -1;
        }
        pend = c->xc_pending;
        if (pend >= 0) {
            c->xc_active = pend;
            c->xc_pending = -1;
        }
        pend = c->wave_ff_pending;
        if (pend >= 0) {
            c->wave_ff_active = (pend == PIEZO_CTL_WAVE_FF_OFF) ? (int8_t)-1 : pend;
            c->wave_ff_pending = -1;
        }
        /* the stages before the feedforward: any request (a configuration
         * change too) may have switched one of them on or off */
        c->ref_stages = piezo_ctl_ref_stages_of(c);
        c->wave_ff_q15 = 0;
        c->jump_span = jump_span_of(c); /* max_jump may have changed */
        if (c->servo_req != 0u) {
            servo_switch(c, c->servo_req);
            c->servo_req = 0u;
            mode = c->mode;
        }
    }

    /* 2-3. sensor */
    y = read_sensor(c, adc[0]);
    c->sig[PIEZO_SIG_Y2] = sensor_q15(adc[1] - g->adc_zero, g->sensor_gain_q16);
    /* each signal goes to sig[] (the recorder's and the register map's copy,
     * step 9) as soon as it is final: a value stored here needs no register
     * or stack slot across the calls below (the coupling, step 7, reads y2
     * back from sig[]; nothing else in the tick reads sig[] after the
     * boundary's servo switch) */
    c->sig[PIEZO_SIG_Y] = y;
    if (c->st.faults != 0u) {
        c->st.armed = 0u; /* any fault disarms */
    }
    /* the mode as one bit (1 << mode), none when disarmed: each test of the
     * mode below is one mask (mode <= PIEZO_MODE_DIRECT always: the only
     * writers are init, piezo_ctl_set_mode and servo_switch); IDLE's bit is in
     * no mask */
    mb = c->st.armed ? 1u << mode : 0u;

    /* 4. reference: r_ahead for the feedforward, r (preview_ticks later) for the rest */
    /* running as it was before this tick's step (the step may end the wave);
     * the byte itself, not a 0/1 of it (no normalising instructions) */
    wave_on = (c->ref_source == PIEZO_REF_WAVE) ? c->wave.running : 0u; /* (no call: the tick runs from RAM) */
    r_ahead = (c->ref_source == PIEZO_REF_WAVE) ? piezo_wave_process(&c->wave) : c->setpoint_q15;
    r = r_ahead;
    r_loop = r;
    /* 4a-4c. the stages between the reference and the feedforward, none in
     * most configurations: one test of them all (ref_stages, step 1), the
     * stages out of line (ref_stages_run) */
    if (c->ref_stages != 0u) {
        const uint64_t p = ref_stages_run(c, r_ahead, wave_on);
        r_ahead = (int16_t)(uint16_t)p;
        r = (int16_t)(uint16_t)(p >> 16);
        r_loop = (int16_t)(uint16_t)(p >> 32);
    }
    /* (wave_ff_q15 is 0 without the stages: step 1 clears it whenever it
     * derives ref_stages, before this tick's stages could set it) */
    c->sig[PIEZO_SIG_REF] = r;
    c->sig[PIEZO_SIG_ERR] = piezo_sat_q15((int32_t)r - y);

    /* 5. feedforward (of the shaped, inverted early reference) */
    {
        piezo_ff_state_t *const ff = c->ff_act; /* &ff[active]: no index arithmetic per tick */
        /* mb opaque here and at step 6 (an empty asm, no instruction): gcc
         * otherwise forms the masks of steps 5 and 6 when mb is made and
         * keeps them on the stack across the calls (two stores and two
         * loads, round 16's profile); now each is one TST/ANDS of mb, which
         * lives in a register across the calls anyway (round 17) */
        __asm__("" : "+r"(mb));
        if ((mb & (MODE_BIT(PIEZO_MODE_FEEDFORWARD) | MODE_BIT(PIEZO_MODE_FF_FEEDBACK))) != 0u && ff != NULL) {
            u_ff = piezo_ff_process(ff, c->set_act, r_ahead, c->limit.prev_q15);
        } else if ((mb & MODE_BIT(PIEZO_MODE_OPEN_LOOP)) != 0u && ff != NULL) {
            u_ff = piezo_line_q15(r_ahead, c->set_act->open_loop_gain_q24, c->set_act->open_loop_offset_q15);
        } else if ((mb & (MODE_BIT(PIEZO_MODE_OPEN_LOOP) | MODE_BIT(PIEZO_MODE_FEEDFORWARD) |
                          MODE_BIT(PIEZO_MODE_FF_FEEDBACK) | MODE_BIT(PIEZO_MODE_DIRECT))) != 0u) {
            u_ff = r_ahead; /* DIRECT, or no table: the reference is the drive */
        }
    }
    c->sig[PIEZO_SIG_FF] = u_ff;

    /* 6. feedback */
    __asm__("" : "+r"(mb));
    if ((mb & (MODE_BIT(PIEZO_MODE_FF_FEEDBACK) | MODE_BIT(PIEZO_MODE_FEEDBACK))) != 0u) {
        int16_t e = piezo_sat_q15((int32_t)r_loop - y);
        u_fb = piezo_pid_process(&c->pid, e);
        if (g->notch_on) {
            u_fb = piezo_biquad_process(&c->notch, u_fb);
        }
    }
    c->sig[PIEZO_SIG_FB] = u_fb;

    /* 7-8. sum, clamp, slew limit (also while ramping down after a disarm), DAC;
     * run from step 6's mb: gcc then knows it is set on the feedback's path */
    run = (mb & ~MODE_BIT(PIEZO_MODE_IDLE)) != 0u;
    u = run ? piezo_sat_q15((int32_t)u_ff + u_fb) : g->u_safe_q15;
    /* the term applied, xc_q15, is written here only with a coupling slot:
     * without one it is 0 since the slot went (init, piezo_ctl_rollback) */
    if (c->xc_active >= 0) {
        const piezo_xcset_t *xs = &c->xset[c->xc_active];
        /* y or y2 from sig[] (stored at step 3): not kept in a register across the calls */
        int16_t u_xc = piezo_xc_process(&c->xc[c->xc_active], c->sig[PIEZO_SIG_U2], c->sig[xs->x_source ? PIEZO_SIG_Y2 : PIEZO_SIG_Y]),
                applied = 0;
        if (!g->xcouple_bypass && (mb & (MODE_BIT(PIEZO_MODE_FEEDFORWARD) | MODE_BIT(PIEZO_MODE_FF_FEEDBACK) |
                                         MODE_BIT(PIEZO_MODE_FEEDBACK))) != 0u) {
            applied = u_xc;
            u = piezo_sat_q15((int32_t)u - u_xc);
        }
        c->xc_q15 = applied;
    }
    u = piezo_limit_step(&c->limit, u);
    if (c->limit.flags != 0u && run) {
        c->st.clamps++;
    }
    {
        /* |u * gain| <= 2^15 * 2^31, so the shifted product fits int32 (|.| <= 2^30);
         * the sum saturated to int32 and then clamped to [dac_min, dac_max] (int32)
         * is the clamp of the exact sum: the same code as in int64 */
        /* rshift_rnd64(u gain, 16) as the rounded high word of (u 2^16) gain
         * (one SMMULR on the Cortex-M4, round 17) */
        int32_t code = piezo_add_sat_i32(g->dac_zero, piezo_mul_hi_rnd((int32_t)((uint32_t)(int32_t)u << 16), g->dac_gain_q16));
        dac = code < g->dac_min ? g->dac_min : (code > g->dac_max ? g->dac_max : code);
    }

    /* 9. recorder and status (REF, Y, ERR, FF, FB, Y2 are in sig[] already;
     *    U2 is an input kept there by its writers, controller.h) */
    c->sig[PIEZO_SIG_U] = u;
    rec_was = c->rec.state;
    piezo_rec_process(&c->rec, c->sig);
    if (c->wave_on_trigger && rec_was == PIEZO_REC_ARMED && c->rec.state != PIEZO_REC_ARMED) {
        /* the wave was loaded at its start when this was armed: only switch to it */
        c->wave_on_trigger = 0u;
        c->ref_source = PIEZO_REF_WAVE;
        c->wave_ff_phase = 0u;
    }
    c->st.ticks++; /* (ends a run of overruns: piezo_ctl_overrun compares it) */
    return dac;
}

void piezo_ctl_overrun(piezo_ctl_t *c)
{
    c->st.overruns++;
    /* consecutive overruns: no tick completed since the last one. The tick
     * does not clear the run (a store per tick); the run starts again here
     * when the tick count moved (it would miss a gap of exactly 2^32 ticks,
     * 5 days at 10 kHz, between two overruns) */
    if (c->overrun_tick != c->st.ticks) {
        c->overrun_tick = c->st.ticks;
        c->overrun_run = 0u;
    }
    if (c->cfg.overrun_limit != 0u && ++c->overrun_run >= c->cfg.overrun_limit) {
        c->st.faults |= PIEZO_FAULT_OVERRUN;
    }
}

int piezo_ctl_set_mode(piezo_ctl_t *c, uint8_t mode)
{
    if (mode > PIEZO_MODE_DIRECT) {
        return PIEZO_EINVAL;
    }
    if (c->st.armed) {
        return PIEZO_EORDER; /* disarm first: a mode change under drive jumps */
    }
    c->mode = mode;
    return PIEZO_OK;
}

int piezo_ctl_arm(piezo_ctl_t *c, uint8_t on)
{
    if (!on) {
        c->st.armed = 0u;
        return PIEZO_OK;
    }
    if (c->st.faults != 0u) {
        return PIEZO_EORDER; /* clear the faults first */
    }
    reset_loop_state(c);
    c->st.armed = 1u;
    return PIEZO_OK;
}

int piezo_ctl_servo(piezo_ctl_t *c, uint8_t on)
{
    if (!on) {
        if (!c->st.armed) {
            return PIEZO_EORDER; /* disarmed: the drive rests at u_safe already */
        }
        c->servo_req = 1u;
        c->boundary_req = 1u;
        return PIEZO_OK;
    }
    if (c->st.armed) {
        c->servo_req = 2u;
        c->boundary_req = 1u;
        return PIEZO_OK;
    }
    if (c->st.faults != 0u) {
        return PIEZO_EORDER; /* clear the faults first */
    }
    /* the request before the arm: the tick that first runs armed has done it
     * (a tick in between runs it disarmed, which only sets state up) */
    reset_loop_state(c);
    c->servo_req = 2u;
    c->boundary_req = 1u;
    c->st.armed = 1u;
    return PIEZO_OK;
}

void piezo_ctl_clear_faults(piezo_ctl_t *c)
{
    c->st.faults = 0u;
    c->bad_run = 0u;
    c->overrun_run = 0u;
}

/* The wave configuration's pointers to the controller's tables, and its level count checked against them
   (shared by the immediate and the triggered start). */
static int bind_wave_tables(piezo_ctl_t *c)
{
    piezo_wave_cfg_t *w = &c->wave_cfg;
    w->tones = c->tones;
    w->levels_q15 = c->levels_q15;
    w->durations = c->durations;
    return w->n_levels > PIEZO_CTL_WAVE_MAX_LEVELS ? PIEZO_ERANGE : PIEZO_OK;
}

int piezo_ctl_start_wave(piezo_ctl_t *c)
{
    piezo_wave_cfg_t *w = &c->wave_cfg;
    int rc;
    if (bind_wave_tables(c) != PIEZO_OK) {
        return PIEZO_ERANGE;
    }
    rc = piezo_wave_init(&c->wave, w);
    if (rc != PIEZO_OK) {
        w->kind = PIEZO_WAVE_OFF;
        (void)piezo_wave_init(&c->wave, w);
        return rc;
    }
    c->ref_source = PIEZO_REF_WAVE;
    c->wave_on_trigger = 0u; /* started now: a pending start on the trigger is void */
    c->wave_ff_phase = 0u; /* the learned feedforward restarts with the wave */
    if (c->rec.state == PIEZO_REC_ARMED && c->rec.cfg.trigger == PIEZO_REC_SOFTWARE) {
        piezo_rec_trigger(&c->rec);
    }
    return PIEZO_OK;
}

void piezo_ctl_stop_wave(piezo_ctl_t *c)
{
    c->wave_on_trigger = 0u;
    c->wave.running = 0u;
}

int piezo_ctl_start_wave_on_trigger(piezo_ctl_t *c)
{
    piezo_wave_cfg_t *w = &c->wave_cfg;
    piezo_wave_t trial;
    int rc;
    if (bind_wave_tables(c) != PIEZO_OK) {
        return PIEZO_ERANGE;
    }
    if ((rc = piezo_wave_init(&trial, w)) != PIEZO_OK) {
        return rc; /* refused: nothing changes */
    }
    /* hold the wave's offset until the trigger, the wave loaded at its start */
    c->setpoint_q15 = w->offset_q15;
    c->ref_source = PIEZO_REF_SETPOINT;
    (void)piezo_wave_init(&c->wave, w);
    c->wave_on_trigger = 1u;
    return PIEZO_OK;
}

int piezo_ctl_wave_ff_commit(piezo_ctl_t *c, const int16_t *staged_q15, uint16_t n, uint32_t freq_word)
{
    int8_t spare;
    if (staged_q15 == NULL || n == 0u || n > PIEZO_CTL_WAVE_FF_MAX || freq_word == 0u) {
        return PIEZO_EINVAL;
    }
    if (c->wave_ff_pending >= 0) {
        return PIEZO_EBUSY; /* the tick has not taken the last one: its slot may be the spare */
    }
    spare = (c->wave_ff_active == 0) ? 1 : 0; /* never the slot being played */
    memcpy(c->wave_ff[spare].c_q15, staged_q15, (size_t)n * sizeof staged_q15[0]);
    c->wave_ff[spare].n = n;
    c->wave_ff[spare].freq_word = freq_word;
    c->wave_ff_pending = spare; /* published last: the tick sees a whole slot */
    c->boundary_req = 1u;
    return PIEZO_OK;
}

int piezo_ctl_wave_ff_off(piezo_ctl_t *c)
{
    if (c->wave_ff_pending >= 0) {
        return PIEZO_EBUSY;
    }
    c->wave_ff_pending = PIEZO_CTL_WAVE_FF_OFF;
    c->boundary_req = 1u;
    return PIEZO_OK;
}

const piezo_ctl_wave_ff_t *piezo_ctl_wave_ff_played(const piezo_ctl_t *c)
{
    int8_t a = c->wave_ff_pending >= 0 ? c->wave_ff_pending : c->wave_ff_active;
    return (a >= 0 && a != PIEZO_CTL_WAVE_FF_OFF) ? &c->wave_ff[a] : NULL;
}

uint16_t piezo_ctl_wave_ff_n(const piezo_ctl_t *c)
{
    const piezo_ctl_wave_ff_t *ff = piezo_ctl_wave_ff_played(c);
    return ff != NULL ? ff->n : 0u;
}

void piezo_ctl_set_key(piezo_ctl_t *c, uint32_t key)
{
    c->key = key;
    c->unlocked = 0u;
    c->unlock_bad_run = 0u;
}

void piezo_ctl_set_stage(piezo_ctl_t *c, const piezo_ctl_stage_t *stage)
{
    c->stage = *stage;
}

static uint8_t session_bit(uint8_t session)
{
    return (uint8_t)(1u << (session & 7u));
}

int piezo_ctl_is_unlocked(const piezo_ctl_t *c, uint8_t session)
{
    return session < PIEZO_CTL_SESSIONS && (c->unlocked & session_bit(session)) != 0u;
}

/* How long after the last wrong key every unlock is refused [ms]: none
 * before backoff_after wrong keys in a row, then backoff_base doubling up to
 * backoff_max, and lockout_ms from lockout_after on. */
static uint32_t wait_ms(uint32_t bad_run)
{
    uint32_t w = PIEZO_UNLOCK_BACKOFF_BASE_MS;
    if (bad_run >= PIEZO_UNLOCK_LOCKOUT_AFTER) {
        return PIEZO_UNLOCK_LOCKOUT_MS;
    }
    if (bad_run < PIEZO_UNLOCK_BACKOFF_AFTER) {
        return 0u;
    }
    for (uint32_t i = PIEZO_UNLOCK_BACKOFF_AFTER; i < bad_run && w < PIEZO_UNLOCK_BACKOFF_MAX_MS; i++) {
        w *= 2u;
    }
    return w < PIEZO_UNLOCK_BACKOFF_MAX_MS ? w : PIEZO_UNLOCK_BACKOFF_MAX_MS;
}

uint32_t piezo_ctl_unlock_wait_ms(const piezo_ctl_t *c, uint32_t now_ms)
{
    uint32_t w = wait_ms(c->unlock_bad_run), since = now_ms - c->bad_at_ms;
    return c->unlock_bad_run == 0u || since >= w ? 0u : w - since;
}

int piezo_ctl_unlock(piezo_ctl_t *c, uint8_t session, uint32_t key, uint32_t now_ms)
{
    if (session >= PIEZO_CTL_SESSIONS) {
        return PIEZO_EINVAL;
    }
    if (piezo_ctl_unlock_wait_ms(c, now_ms) != 0u) {
        return PIEZO_EBUSY; /* backoff or lockout: not even a right key counts */
    }
    if (c->key == 0u || key != c->key) {
        c->unlocked &= (uint8_t)~session_bit(session);
        c->st.bad_unlocks++;
        c->unlock_bad_run++;
        c->bad_at_ms = now_ms;
        return PIEZO_EKEY;
    }
    c->unlock_bad_run = 0u;
    c->unlocked |= session_bit(session);
    return PIEZO_OK;
}

void piezo_ctl_lock(piezo_ctl_t *c, uint8_t session)
{
    c->unlocked &= (uint8_t)~session_bit(session);
}

void piezo_ctl_end_session(piezo_ctl_t *c, uint8_t session)
{
    piezo_ctl_lock(c, session);
    if (c->staged_owner == (int8_t)session) {
        c->staged_len = 0u; /* the upload dies with its session */
        c->staged_owner = -1;
    }
}

/* May this session change the staged bank? (unlocked, and no other
 * session's upload in it) */
static uint16_t may_stage(const piezo_ctl_t *c, uint8_t session)
{
    if (!piezo_ctl_is_unlocked(c, session)) {
        return PIEZO_TABLE_REASON_LOCKED;
    }
    if (c->staged_len != 0u && c->staged_owner >= 0 && c->staged_owner != (int8_t)session) {
        return PIEZO_TABLE_REASON_NOT_OWNER;
    }
    return PIEZO_TABLE_REASON_OK;
}

int piezo_ctl_stage_write(piezo_ctl_t *c, uint8_t session, uint32_t offset, const uint8_t *data, uint32_t len)
{
    uint16_t r = may_stage(c, session);
    if (r != PIEZO_TABLE_REASON_OK) {
        c->st.table_result = r;
        return PIEZO_EPERM;
    }
    if (offset > sizeof c->staged || len > sizeof c->staged - offset) {
        c->st.table_result = PIEZO_TABLE_REASON_BAD_LENGTH;
        return PIEZO_ERANGE;
    }
    if (c->staged_len == 0u) {
        c->staged_owner = (int8_t)session;
    }
    memcpy(c->staged + offset, data, len);
    if (offset + len > c->staged_len) {
        c->staged_len = offset + len;
    }
    return PIEZO_OK;
}

int piezo_ctl_clear_staged(piezo_ctl_t *c, uint8_t session)
{
    uint16_t r = may_stage(c, session);
    if (r != PIEZO_TABLE_REASON_OK) {
        c->st.table_result = r;
        return PIEZO_EPERM;
    }
    c->staged_len = 0u;
    c->staged_owner = -1;
    return PIEZO_OK;
}

/* Is the image built for this controller's stage and axis? (1 mV / 1 nm of
 * rounding between the host's and the target's conversion) */
static uint16_t check_stage(const piezo_ctl_t *c, const piezo_table_info_t *info)
{
    const piezo_ctl_stage_t *s = &c->stage;
    if (!s->known) {
        return PIEZO_TABLE_REASON_OK; /* a target that does not say (unit tests, bench images) */
    }
    if (info->axis != s->axis) {
        return PIEZO_TABLE_REASON_WRONG_AXIS;
    }
    if ((int64_t)info->drive_min_mv - s->drive_min_mv > 1 || (int64_t)s->drive_min_mv - info->drive_min_mv > 1 ||
        (int64_t)info->drive_max_mv - s->drive_max_mv > 1 || (int64_t)s->drive_max_mv - info->drive_max_mv > 1 ||
        (int64_t)info->position_min_nm - s->position_min_nm > 1 ||
        (int64_t)s->position_min_nm - info->position_min_nm > 1 ||
        (int64_t)info->position_max_nm - s->position_max_nm > 1 ||
        (int64_t)s->position_max_nm - info->position_max_nm > 1) {
        return PIEZO_TABLE_REASON_WRONG_STAGE;
    }
    return PIEZO_TABLE_REASON_OK;
}

uint16_t piezo_ctl_commit(piezo_ctl_t *c, uint8_t session, uint32_t len)
{
    uint16_t r;
    int8_t spare;
    piezo_table_info_t info;
    if ((r = may_stage(c, session)) != PIEZO_TABLE_REASON_OK) {
        c->st.table_result = r;
        return r; /* someone else's upload stays theirs */
    } else if (c->pending >= 0 || c->xc_pending >= 0) {
        r = PIEZO_TABLE_REASON_BUSY;
    } else if (c->staged_len == 0u) {
        r = PIEZO_TABLE_REASON_NOTHING_STAGED;
    } else {
        if (len == 0u) {
            len = c->staged_len; /* the image is what was uploaded */
        }
        /* the header is read once, here, after its CRC: everything below
         * dispatches on info */
        if (len > c->staged_len) {
            r = PIEZO_TABLE_REASON_BAD_LENGTH;
        } else if ((r = piezo_table_check(c->staged, len, &info)) != PIEZO_TABLE_REASON_OK ||
                   (r = piezo_table_check_specs(&info)) != PIEZO_TABLE_REASON_OK ||
                   (r = check_stage(c, &info)) != PIEZO_TABLE_REASON_OK) {
            /* refused as it is */
        } else if (info.kind == PIEZO_TABLE_KIND_CROSS_COUPLING) {
            /* the coupling slot: not written to the store */
            if ((r = load_xc_spare(c, &info, &spare)) == PIEZO_TABLE_REASON_OK) {
                c->xc_previous = c->xc_active;
                c->xc_pending = spare;
                c->boundary_req = 1u;
                c->last_commit_xc = 1u;
            }
        } else if ((r = load_spare(c, &info, &spare, session != PIEZO_CTL_SESSION_LOCAL)) == PIEZO_TABLE_REASON_OK) {
            if (c->have_store && (r = piezo_store_save(&c->store, c->staged, len)) != PIEZO_TABLE_REASON_OK) {
                c->set[spare].kind = 0u;
            } else {
                c->staged_crc = c->set[spare].crc;
                c->previous = c->active;
                c->pending = spare;
                c->boundary_req = 1u;
                c->last_commit_xc = 0u;
            }
        }
    }
    if (r != PIEZO_TABLE_REASON_BUSY) {
        c->staged_len = 0u; /* every commit consumes the upload, good or bad */
        c->staged_owner = -1;
    }
    c->st.table_result = r;
    return r;
}

uint16_t piezo_ctl_load_image(piezo_ctl_t *c, const uint8_t *img, uint32_t len)
{
    uint8_t was = c->unlocked;
    uint16_t r;
    if (img == NULL) {
        return PIEZO_TABLE_REASON_BAD_LENGTH;
    }
    /* the target's own session: local code needs no key */
    c->unlocked |= session_bit(PIEZO_CTL_SESSION_LOCAL);
    c->staged_len = 0u;
    c->staged_owner = -1;
    if (piezo_ctl_stage_write(c, PIEZO_CTL_SESSION_LOCAL, 0u, img, len) != PIEZO_OK) {
        r = c->st.table_result;
    } else {
        r = piezo_ctl_commit(c, PIEZO_CTL_SESSION_LOCAL, len);
    }
    c->unlocked = (uint8_t)(was & ~session_bit(PIEZO_CTL_SESSION_LOCAL));
    return r;
}

uint16_t piezo_ctl_rollback(piezo_ctl_t *c, uint8_t session)
{
    uint16_t r;
    int8_t prev = c->previous;
    int unlocked = piezo_ctl_is_unlocked(c, session);
    if (unlocked && c->last_commit_xc) {
        /* the coupling slot (RAM only): back to the previous coupling table or none */
        if (c->xc_pending >= 0) {
            r = PIEZO_TABLE_REASON_BUSY;
        } else if (c->xc_active < 0) {
            r = PIEZO_TABLE_REASON_NO_PREVIOUS;
        } else {
            if (c->xc_previous >= 0) {
                piezo_xc_reset(&c->xc[c->xc_previous]);
            }
            c->xc_pending = c->xc_previous;
            c->boundary_req = 1u;
            if (c->xc_pending < 0) {
                c->xc_active = -1; /* no previous coupling table: compensation off */
                /* after it (both volatile: in that order): a tick from here on
                 * no longer writes the term, so it stays 0 */
                *(volatile int16_t *)&c->xc_q15 = 0;
            }
            c->xc_previous = -1;
            c->last_commit_xc = 0u;
            r = PIEZO_TABLE_REASON_OK;
        }
        c->st.table_result = r;
        return r;
    }
    if (!unlocked) {
        r = PIEZO_TABLE_REASON_LOCKED;
    } else if (c->pending >= 0) {
        r = PIEZO_TABLE_REASON_BUSY;
    } else if (c->active < 0 || prev < 0 || c->set[prev].kind == 0u) {
        r = PIEZO_TABLE_REASON_NO_PREVIOUS;
    } else if (c->have_store && (r = piezo_store_rollback(&c->store, c->staged)) != PIEZO_TABLE_REASON_OK) {
        /* flash unchanged or consistent: keep running the active table */
    } else {
        (void)piezo_ff_bind(&c->ff[prev], &c->set[prev]);
        c->previous = -1; /* one level: the rolled-back table is not kept */
        c->pending = prev;
        c->boundary_req = 1u;
        r = PIEZO_TABLE_REASON_OK;
    }
    c->st.table_result = r;
    return r;
}

uint32_t piezo_ctl_active_crc(const piezo_ctl_t *c)
{
    int8_t a = c->pending >= 0 ? c->pending : c->active;
    return a >= 0 ? c->set[a].crc : 0u;
}

uint32_t piezo_ctl_coupling_crc(const piezo_ctl_t *c)
{
    int8_t a = c->xc_pending >= 0 ? c->xc_pending : c->xc_active;
    return a >= 0 ? c->xset[a].crc : 0u;
}

uint32_t piezo_ctl_active_version(const piezo_ctl_t *c)
{
    int8_t a = c->pending >= 0 ? c->pending : c->active;
    return a >= 0 ? c->set[a].version : 0u;
}
