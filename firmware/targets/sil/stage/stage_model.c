/* Stage model: parameters, their defaults and checks, and the per-sample
 * simulation. See stage_model.h and docs/stage-model.md. */
#include "stage_model.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#define STAGE_PI 3.14159265358979323846

/* ---------------------------------------------------------------- defaults */

static void axis_ideal(stage_axis_params *a)
{
    memset(a, 0, sizeof *a);
    a->dac.bits = 16;
    a->dac.v_min = 0.0;
    a->dac.v_max = 10.0;
    a->delay.samples = 0;
    a->amp.gain = 1.0;
    a->amp.offset_v = 0.0;
    a->amp.bandwidth.hz = 1000.0;
    a->amp.slew.current_limit_a = 0.1;
    a->amp.slew.load_capacitance_f = 1e-6;
    a->amp.saturation.v_min = -1e9;
    a->amp.saturation.v_max = 1e9;
    a->hysteresis.v_ref = 1.0;
    a->hysteresis.alpha = 0.3;
    a->hysteresis.beta = 2.0;
    a->hysteresis.gamma = 0.5;
    a->hysteresis.rate.gain = 0.0;
    a->hysteresis.rate.ref_v_per_s = 1.0;
    a->actuator_gain_um_per_v = 1.0;
    a->thermal.time_constant_s = 1.0;
    a->sensor.range_min_um = 0.0;
    a->sensor.range_max_um = 10.0;
    a->adc.bits = 16;
    a->adc.y_min_um = 0.0;
    a->adc.y_max_um = 10.0;
}

stage_params stage_params_ideal(void)
{
    stage_params p;
    memset(&p, 0, sizeof p);
    snprintf(p.name, sizeof p.name, "ideal");
    p.num_axes = 1;
    p.sample_rate_hz = 10000.0;
    axis_ideal(&p.axis[0]);
    axis_ideal(&p.axis[1]);
    p.coupling.into[0].ref_freq_hz = 100.0;
    p.coupling.into[1].ref_freq_hz = 100.0;
    return p;
}

/* The numbers and their sources: docs/stage-model.md, "Default stage". */
static void axis_default(stage_axis_params *a)
{
    static const double creep_tau[5] = {0.05, 0.3, 2.0, 15.0, 100.0};
    int i;

    axis_ideal(a);
    a->dac.enabled = true; /* 16 bit over 0..10 V */
    a->delay.enabled = true;
    a->delay.samples = 1;
    a->amp.gain = 15.0; /* 0..10 V -> 0..150 V */
    a->amp.offset_v = 0.0;
    a->amp.bandwidth.enabled = true;
    a->amp.bandwidth.hz = 2000.0;
    a->amp.slew.enabled = true;
    a->amp.slew.current_limit_a = 0.1;
    a->amp.slew.load_capacitance_f = 1.5e-6; /* 66.7 V/ms */
    a->amp.saturation.enabled = true;
    a->amp.saturation.v_min = -20.0;
    a->amp.saturation.v_max = 150.0;
    a->hysteresis.enabled = true;
    a->hysteresis.v_ref = 150.0;
    a->hysteresis.alpha = 0.32;
    a->hysteresis.beta = 2.2;
    a->hysteresis.gamma = 0.6;
    a->hysteresis.a2 = 0.15;
    a->hysteresis.a3 = 0.0;
    a->hysteresis.rate.enabled = true;
    a->hysteresis.rate.gain = 0.3;
    a->hysteresis.rate.ref_v_per_s = 10000.0;
    a->creep.enabled = true;
    a->creep.n_terms = 5;
    for (i = 0; i < 5; i++) {
        a->creep.term[i].tau_s = creep_tau[i];
        a->creep.term[i].gain = 0.008;
    }
    a->actuator_gain_um_per_v = 0.11;
    a->mechanics.enabled = true;
    a->mechanics.n_modes = 2;
    a->mechanics.mode[0].freq_hz = 970.0;
    a->mechanics.mode[0].damping = 0.012;
    a->mechanics.mode[0].gain = 0.97;
    a->mechanics.mode[1].freq_hz = 3100.0;
    a->mechanics.mode[1].damping = 0.02;
    a->mechanics.mode[1].gain = 0.03;
    a->thermal.enabled = true;
    a->thermal.drift_um_per_k = 0.05;
    a->thermal.delta_k = 0.5;
    a->thermal.time_constant_s = 600.0;
    a->sensor.enabled = true;
    a->sensor.offset_um = 0.02;
    a->sensor.gain_error = 0.002;
    a->sensor.nonlinearity = 0.0005;
    a->sensor.range_min_um = 0.0;
    a->sensor.range_max_um = 20.0;
    a->noise.enabled = true;
    a->noise.rms_um = 0.002;
    a->adc.enabled = true;
    a->adc.bits = 16;
    a->adc.y_min_um = -2.0;
    a->adc.y_max_um = 22.0;
}

stage_params stage_params_default(void)
{
    stage_params p = stage_params_ideal();
    snprintf(p.name, sizeof p.name, "default");
    p.num_axes = 1;
    axis_default(&p.axis[0]);
    axis_default(&p.axis[1]);
    return p;
}

stage_params stage_params_two_axis(void)
{
    stage_params p = stage_params_default();
    int i;
    snprintf(p.name, sizeof p.name, "two_axis");
    p.num_axes = 2;
    for (i = 0; i < 2; i++) {
        stage_mech_params *m = &p.axis[i].mechanics;
        m->n_modes = 2;
        m->mode[0].freq_hz = 140.0;
        m->mode[0].damping = 0.04;
        m->mode[0].gain = 0.98;
        m->mode[1].freq_hz = 620.0;
        m->mode[1].damping = 0.03;
        m->mode[1].gain = 0.02;
        p.coupling.into[i].static_percent = 0.30;
        p.coupling.into[i].dynamic_percent = 6.04;
        p.coupling.into[i].ref_freq_hz = 100.0;
        p.coupling.into[i].position_slope_per_um = 0.02;
        p.coupling.into[i].position_center_um = 9.0;
    }
    p.coupling.enabled = true;
    return p;
}

/* ------------------------------------------------------------------ checks */

static int fail(char *errbuf, size_t errlen, const char *fmt, ...)
{
    if (errbuf && errlen > 0) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(errbuf, errlen, fmt, ap);
        va_end(ap);
    }
    return STAGE_ERR_PARAM;
}

#define FINITE(x) (isfinite(x))

int stage_params_check(const stage_params *p, char *errbuf, size_t errlen)
{
    int i, j;
    if (!p) {
        return fail(errbuf, errlen, "no parameters");
    }
    if (p->num_axes < 1 || p->num_axes > STAGE_MAX_AXES) {
        return fail(errbuf, errlen, "num_axes: %d, must be 1 or 2", p->num_axes);
    }
    if (!FINITE(p->sample_rate_hz) || p->sample_rate_hz <= 0.0) {
        return fail(errbuf, errlen, "sample_rate_hz: must be > 0");
    }
    for (i = 0; i < p->num_axes; i++) {
        const stage_axis_params *a = &p->axis[i];
        if (a->dac.bits < 1 || a->dac.bits > 24) {
            return fail(errbuf, errlen, "axes[%d].dac.bits: %d, must be 1..24", i, a->dac.bits);
        }
        if (!FINITE(a->dac.v_min) || !FINITE(a->dac.v_max) || !(a->dac.v_max > a->dac.v_min)) {
            return fail(errbuf, errlen, "axes[%d].dac.range_v: needs min < max", i);
        }
        if (a->delay.samples < 0 || a->delay.samples > STAGE_MAX_DELAY) {
            return fail(errbuf, errlen, "axes[%d].delay.samples: %d, must be 0..%d", i,
                        a->delay.samples, STAGE_MAX_DELAY);
        }
        if (!FINITE(a->amp.gain) || a->amp.gain == 0.0 || !FINITE(a->amp.offset_v)) {
            return fail(errbuf, errlen, "axes[%d].amplifier.gain: must be finite and non-zero", i);
        }
        if (a->amp.bandwidth.enabled && !(a->amp.bandwidth.hz > 0.0 && FINITE(a->amp.bandwidth.hz))) {
            return fail(errbuf, errlen, "axes[%d].amplifier.bandwidth.hz: must be > 0", i);
        }
        if (a->amp.slew.enabled &&
            !(a->amp.slew.current_limit_a > 0.0 && a->amp.slew.load_capacitance_f > 0.0 &&
              FINITE(a->amp.slew.current_limit_a / a->amp.slew.load_capacitance_f))) {
            return fail(errbuf, errlen,
                        "axes[%d].amplifier.slew_rate: current_limit_a and load_capacitance_f must be > 0", i);
        }
        if (a->amp.saturation.enabled && !(a->amp.saturation.v_max > a->amp.saturation.v_min)) {
            return fail(errbuf, errlen, "axes[%d].amplifier.saturation.range_v: needs min < max", i);
        }
        if (a->hysteresis.enabled) {
            const stage_hyst_params *h = &a->hysteresis;
            if (!(h->v_ref > 0.0) || !FINITE(h->v_ref)) {
                return fail(errbuf, errlen, "axes[%d].hysteresis.v_ref: must be > 0", i);
            }
            if (!(h->alpha > 0.0) || !FINITE(h->alpha)) {
                return fail(errbuf, errlen, "axes[%d].hysteresis.alpha: must be > 0", i);
            }
            if (!FINITE(h->beta) || !FINITE(h->gamma) || !(h->beta > fabs(h->gamma))) {
                return fail(errbuf, errlen, "axes[%d].hysteresis: needs beta > |gamma|", i);
            }
            if (!FINITE(h->a2) || !FINITE(h->a3)) {
                return fail(errbuf, errlen, "axes[%d].hysteresis.a2/a3: must be finite", i);
            }
            if (h->rate.enabled && !(h->rate.gain >= 0.0 && h->rate.ref_v_per_s > 0.0)) {
                return fail(errbuf, errlen,
                            "axes[%d].hysteresis.rate: needs gain >= 0 and ref_v_per_s > 0", i);
            }
        }
        if (a->creep.n_terms < 0 || a->creep.n_terms > STAGE_MAX_CREEP) {
            return fail(errbuf, errlen, "axes[%d].creep.terms: at most %d", i, STAGE_MAX_CREEP);
        }
        for (j = 0; j < a->creep.n_terms; j++) {
            if (!(a->creep.term[j].tau_s > 0.0) || !FINITE(a->creep.term[j].tau_s) ||
                !FINITE(a->creep.term[j].gain)) {
                return fail(errbuf, errlen, "axes[%d].creep.terms[%d]: tau_s must be > 0", i, j);
            }
        }
        if (!FINITE(a->actuator_gain_um_per_v)) {
            return fail(errbuf, errlen, "axes[%d].actuator.gain_um_per_v: must be finite", i);
        }
        if (a->mechanics.n_modes < 0 || a->mechanics.n_modes > STAGE_MAX_MODES) {
            return fail(errbuf, errlen, "axes[%d].mechanics.modes: at most %d", i, STAGE_MAX_MODES);
        }
        for (j = 0; j < a->mechanics.n_modes; j++) {
            const stage_mode *m = &a->mechanics.mode[j];
            if (!(m->freq_hz > 0.0) || !FINITE(m->freq_hz)) {
                return fail(errbuf, errlen, "axes[%d].mechanics.modes[%d].freq_hz: must be > 0", i, j);
            }
            if (!(m->damping >= 0.0) || !FINITE(m->damping) || !FINITE(m->gain)) {
                return fail(errbuf, errlen, "axes[%d].mechanics.modes[%d].damping: must be >= 0", i, j);
            }
        }
        if (a->thermal.enabled && !(a->thermal.time_constant_s > 0.0)) {
            return fail(errbuf, errlen, "axes[%d].thermal.time_constant_s: must be > 0", i);
        }
        if (a->sensor.enabled && !(a->sensor.range_max_um > a->sensor.range_min_um)) {
            return fail(errbuf, errlen, "axes[%d].sensor.range_um: needs min < max", i);
        }
        if (a->noise.enabled && !(a->noise.rms_um >= 0.0 && FINITE(a->noise.rms_um))) {
            return fail(errbuf, errlen, "axes[%d].noise.rms_um: must be >= 0", i);
        }
        if (a->adc.bits < 1 || a->adc.bits > 24) {
            return fail(errbuf, errlen, "axes[%d].adc.bits: %d, must be 1..24", i, a->adc.bits);
        }
        if (!FINITE(a->adc.y_min_um) || !FINITE(a->adc.y_max_um) || !(a->adc.y_max_um > a->adc.y_min_um)) {
            return fail(errbuf, errlen, "axes[%d].adc.range_um: needs min < max", i);
        }
    }
    if (p->coupling.enabled) {
        if (p->num_axes != 2) {
            return fail(errbuf, errlen, "coupling: enabled on a stage with %d axis", p->num_axes);
        }
        for (i = 0; i < 2; i++) {
            const stage_coupling_path *c = &p->coupling.into[i];
            if (!(c->ref_freq_hz > 0.0) || !FINITE(c->static_percent) || !FINITE(c->dynamic_percent) ||
                !FINITE(c->position_slope_per_um) || !FINITE(c->position_center_um)) {
                return fail(errbuf, errlen, "coupling.into[%d]: needs ref_freq_hz > 0 and finite values", i);
            }
        }
    }
    return STAGE_OK;
}

/* ------------------------------------------------------------------- noise */

uint64_t stage_rng_next(uint64_t *state)
{
    /* splitmix64 */
    uint64_t z = (*state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static double rng_uniform_pm1(uint64_t *state)
{
    /* 53 random bits -> [-1, 1) */
    return (double)(stage_rng_next(state) >> 11) * (2.0 / 9007199254740992.0) - 1.0;
}

double stage_rng_gauss(stage_t *s)
{
    double u, v, q, f;
    if (s->has_spare) {
        s->has_spare = 0;
        return s->gauss_spare;
    }
    do { /* Marsaglia's polar method */
        u = rng_uniform_pm1(&s->rng);
        v = rng_uniform_pm1(&s->rng);
        q = u * u + v * v;
    } while (q >= 1.0 || q == 0.0);
    f = sqrt(-2.0 * log(q) / q);
    s->gauss_spare = v * f;
    s->has_spare = 1;
    return u * f;
}

/* -------------------------------------------------------------------- init */

/* Exact zero-order-hold discretization of x'' = w^2 (u - x) - 2 z w x'. */
static void mode_discretize(const stage_mode *m, double dt, double phi[4], double gam[2])
{
    double w = 2.0 * STAGE_PI * m->freq_hz;
    double z = m->damping;
    double sg = -z * w; /* half the trace of A */
    double c, sn; /* Phi = c I + sn (A - sg I), exp(sg dt) included */
    if (z < 1.0) {
        double e = exp(sg * dt), wd = w * sqrt(1.0 - z * z);
        c = e * cos(wd * dt);
        sn = e * sin(wd * dt) / wd;
    } else if (z > 1.0) {
        /* e cosh(q dt) and e sinh(q dt) from the two real poles (no overflow) */
        double q = w * sqrt(z * z - 1.0);
        double e1 = exp((sg + q) * dt), e2 = exp((sg - q) * dt);
        c = 0.5 * (e1 + e2);
        sn = 0.5 * (e1 - e2) / q;
    } else {
        double e = exp(sg * dt);
        c = e;
        sn = e * dt;
    }
    /* A - sg I = [[-sg, 1], [-w^2, -2 z w - sg]] */
    phi[0] = c + sn * (-sg);
    phi[1] = sn;
    phi[2] = sn * (-w * w);
    phi[3] = c + sn * (-2.0 * z * w - sg);
    /* Gamma = A^-1 (Phi - I) B, B = [0, w^2] */
    gam[0] = -2.0 * z * w * phi[1] - (phi[3] - 1.0);
    gam[1] = w * w * phi[1];
}

int stage_init(stage_t *s, const stage_params *p, uint64_t seed)
{
    int i, j, rc;
    if (!s || !p) {
        return STAGE_ERR_ARG;
    }
    rc = stage_params_check(p, NULL, 0);
    if (rc != STAGE_OK) {
        return rc;
    }
    memset(s, 0, sizeof *s);
    s->p = *p;
    s->dt = 1.0 / p->sample_rate_hz;
    s->rng = seed;
    for (i = 0; i < p->num_axes; i++) {
        const stage_axis_params *a = &p->axis[i];
        stage_axis_state *x = &s->ax[i];
        x->dac_max_code = (int32_t)((1l << a->dac.bits) - 1);
        x->adc_max_code = (int32_t)((1l << a->adc.bits) - 1);
        x->dac_lsb = (a->dac.v_max - a->dac.v_min) / (double)(1l << a->dac.bits);
        x->adc_lsb = (a->adc.y_max_um - a->adc.y_min_um) / (double)(1l << a->adc.bits);
        x->amp_a = a->amp.bandwidth.enabled ? exp(-2.0 * STAGE_PI * a->amp.bandwidth.hz * s->dt) : 0.0;
        x->slew_step_v = a->amp.slew.enabled
                             ? a->amp.slew.current_limit_a / a->amp.slew.load_capacitance_f * s->dt
                             : 0.0;
        for (j = 0; j < a->creep.n_terms; j++) {
            x->creep_a[j] = exp(-s->dt / a->creep.term[j].tau_s);
        }
        for (j = 0; j < a->mechanics.n_modes; j++) {
            mode_discretize(&a->mechanics.mode[j], s->dt, x->mode_phi[j], x->mode_gam[j]);
        }
        x->thermal_a = a->thermal.enabled ? exp(-s->dt / a->thermal.time_constant_s) : 1.0;
    }
    return STAGE_OK;
}

/* ------------------------------------------------------------- conversion */

static int32_t quantize(double q, int32_t max_code)
{
    /* q in LSB; round half up; NaN and negatives -> 0 */
    double r = floor(q + 0.5);
    if (!(r >= 0.0)) {
        return 0;
    }
    if (r >= (double)max_code) {
        return max_code;
    }
    return (int32_t)r;
}

static int32_t clamp_code(int32_t c, int32_t max_code)
{
    return c < 0 ? 0 : (c > max_code ? max_code : c);
}

double stage_dac_code_to_volts(const stage_t *s, int axis, int32_t code)
{
    const stage_axis_state *x = &s->ax[axis];
    return s->p.axis[axis].dac.v_min + (double)clamp_code(code, x->dac_max_code) * x->dac_lsb;
}

int32_t stage_drive_to_dac_code(const stage_t *s, int axis, double u_volts)
{
    const stage_axis_params *a = &s->p.axis[axis];
    double v = (u_volts - a->amp.offset_v) / a->amp.gain;
    return quantize((v - a->dac.v_min) / s->ax[axis].dac_lsb, s->ax[axis].dac_max_code);
}

int32_t stage_um_to_adc_code(const stage_t *s, int axis, double y_um)
{
    return quantize((y_um - s->p.axis[axis].adc.y_min_um) / s->ax[axis].adc_lsb, s->ax[axis].adc_max_code);
}

double stage_adc_code_to_um(const stage_t *s, int axis, int32_t code)
{
    const stage_axis_state *x = &s->ax[axis];
    return s->p.axis[axis].adc.y_min_um + (double)clamp_code(code, x->adc_max_code) * x->adc_lsb;
}

/* -------------------------------------------------------------- the blocks */

static double delay_line(const stage_axis_params *a, stage_axis_state *x, double v)
{
    double out;
    if (!a->delay.enabled || a->delay.samples == 0) {
        return v;
    }
    out = x->delay_buf[x->delay_pos];
    x->delay_buf[x->delay_pos] = v;
    if (++x->delay_pos == a->delay.samples) {
        x->delay_pos = 0;
    }
    return out;
}

static double amplifier(const stage_axis_params *a, stage_axis_state *x, double v)
{
    double target = a->amp.gain * v + a->amp.offset_v;
    double dv = target - x->v_hv;
    if (a->amp.bandwidth.enabled) {
        dv *= 1.0 - x->amp_a; /* exact first-order step for a held input */
    }
    if (a->amp.slew.enabled) {
        if (dv > x->slew_step_v) {
            dv = x->slew_step_v;
        } else if (dv < -x->slew_step_v) {
            dv = -x->slew_step_v;
        }
    }
    x->v_hv += dv;
    if (a->amp.saturation.enabled) {
        if (x->v_hv > a->amp.saturation.v_max) {
            x->v_hv = a->amp.saturation.v_max;
        } else if (x->v_hv < a->amp.saturation.v_min) {
            x->v_hv = a->amp.saturation.v_min;
        }
    }
    return x->v_hv;
}

/* Bouc-Wen along a straight input path of length len in direction d (+-1):
 * dh/dl = d alpha - (beta + gamma d sign(h)) h, linear while sign(h) holds,
 * so it is solved in closed form, splitting where h crosses zero. */
static double bouc_wen_path(double h, double d, double len, double alpha, double beta, double gamma)
{
    int seg;
    for (seg = 0; seg < 2; seg++) {
        double sg = h > 0.0 ? 1.0 : (h < 0.0 ? -1.0 : d);
        double c = beta + gamma * d * sg; /* > 0 since beta > |gamma| */
        double heq = d * alpha / c;
        if (sg != d) {
            /* h moves toward heq (sign d) and reaches 0 after l0 */
            double l0 = log(1.0 - h / heq) / c;
            if (l0 < len) {
                h = 0.0;
                len -= l0;
                continue;
            }
        }
        return heq + (h - heq) * exp(-c * len);
    }
    return h;
}

static double hysteresis(const stage_hyst_params *hp, stage_axis_state *x, double v, double dt)
{
    double xi, dxi, alpha;
    if (!hp->enabled) {
        return v;
    }
    xi = v / hp->v_ref;
    dxi = xi - x->hyst_xi;
    alpha = hp->alpha;
    if (hp->rate.enabled) {
        double r = fabs(dxi) * hp->v_ref / dt;
        alpha *= 1.0 + hp->rate.gain * r / (r + hp->rate.ref_v_per_s);
    }
    if (dxi != 0.0) {
        x->hyst_h = bouc_wen_path(x->hyst_h, dxi > 0.0 ? 1.0 : -1.0, fabs(dxi), alpha, hp->beta, hp->gamma);
    }
    x->hyst_xi = xi;
    return hp->v_ref * (xi + hp->a2 * xi * xi + hp->a3 * xi * xi * xi - x->hyst_h);
}

static double creep(const stage_creep_params *cp, stage_axis_state *x, double w)
{
    double out = w;
    int j;
    if (!cp->enabled) {
        return w;
    }
    for (j = 0; j < cp->n_terms; j++) {
        double a = x->creep_a[j];
        x->creep_x[j] = a * x->creep_x[j] + (1.0 - a) * cp->term[j].gain * w;
        out += x->creep_x[j];
    }
    return out;
}

/* Advances the modes with input u held; sets x->x_own and x->a_own. */
static void mechanics(const stage_mech_params *mp, stage_axis_state *x, double u)
{
    double pos = 0.0, acc = 0.0;
    int j;
    if (!mp->enabled) {
        x->x_own = u;
        x->a_own = 0.0;
        return;
    }
    for (j = 0; j < mp->n_modes; j++) {
        const double *phi = x->mode_phi[j], *gam = x->mode_gam[j];
        double *st = x->mode_x[j];
        double w = 2.0 * STAGE_PI * mp->mode[j].freq_hz;
        double p0 = st[0], v0 = st[1];
        st[0] = phi[0] * p0 + phi[1] * v0 + gam[0] * u;
        st[1] = phi[2] * p0 + phi[3] * v0 + gam[1] * u;
        pos += mp->mode[j].gain * st[0];
        acc += mp->mode[j].gain * (w * w * (u - st[0]) - 2.0 * mp->mode[j].damping * w * st[1]);
    }
    x->x_own = pos;
    x->a_own = acc;
}

static double sensor(const stage_sensor_params *sp, double x)
{
    double span, q;
    if (!sp->enabled) {
        return x;
    }
    span = sp->range_max_um - sp->range_min_um;
    q = 2.0 * (x - sp->range_min_um) / span - 1.0;
    return sp->offset_um + (1.0 + sp->gain_error) * x + sp->nonlinearity * span * (1.0 - q * q);
}

/* One sample of every axis from the DAC output voltages. */
static void advance(stage_t *s, const double v_dac[])
{
    const stage_params *p = &s->p;
    int i;
    for (i = 0; i < p->num_axes; i++) {
        const stage_axis_params *a = &p->axis[i];
        stage_axis_state *x = &s->ax[i];
        double v = delay_line(a, x, v_dac[i]);
        double v_hv = amplifier(a, x, v);
        double w = hysteresis(&a->hysteresis, x, v_hv, s->dt);
        double x_static = a->actuator_gain_um_per_v * creep(&a->creep, x, w);
        mechanics(&a->mechanics, x, x_static);
        x->x_true = x->x_own;
    }
    if (p->coupling.enabled) {
        for (i = 0; i < 2; i++) {
            const stage_coupling_path *c = &p->coupling.into[i];
            const stage_axis_state *o = &s->ax[1 - i];
            double wr = 2.0 * STAGE_PI * c->ref_freq_hz;
            double f = 1.0 + c->position_slope_per_um * (s->ax[i].x_own - c->position_center_um);
            s->ax[i].x_true +=
                f * (0.01 * c->static_percent * o->x_own - 0.01 * c->dynamic_percent * o->a_own / (wr * wr));
        }
    }
    for (i = 0; i < p->num_axes; i++) {
        const stage_axis_params *a = &p->axis[i];
        stage_axis_state *x = &s->ax[i];
        if (a->thermal.enabled) {
            double target = a->thermal.drift_um_per_k * a->thermal.delta_k;
            x->thermal_x = x->thermal_a * x->thermal_x + (1.0 - x->thermal_a) * target;
            x->x_true += x->thermal_x;
        }
        x->y_sensor = sensor(&a->sensor, x->x_true);
        if (a->noise.enabled) {
            x->y_sensor += a->noise.rms_um * stage_rng_gauss(s);
        }
    }
    s->k++;
}

void stage_step(stage_t *s, const int32_t dac_code[], int32_t adc_code[])
{
    double v[STAGE_MAX_AXES] = {0.0, 0.0};
    int i;
    for (i = 0; i < s->p.num_axes; i++) {
        v[i] = stage_dac_code_to_volts(s, i, dac_code[i]);
    }
    advance(s, v);
    for (i = 0; i < s->p.num_axes; i++) {
        adc_code[i] = stage_um_to_adc_code(s, i, s->ax[i].y_sensor);
    }
}

void stage_step_f(stage_t *s, const double v_dac[], double y_um[])
{
    double v[STAGE_MAX_AXES] = {0.0, 0.0};
    int i;
    for (i = 0; i < s->p.num_axes; i++) {
        const stage_axis_params *a = &s->p.axis[i];
        v[i] = v_dac[i];
        if (a->dac.enabled) {
            int32_t code = quantize((v[i] - a->dac.v_min) / s->ax[i].dac_lsb, s->ax[i].dac_max_code);
            v[i] = stage_dac_code_to_volts(s, i, code);
        }
    }
    advance(s, v);
    for (i = 0; i < s->p.num_axes; i++) {
        y_um[i] = s->ax[i].y_sensor;
        if (s->p.axis[i].adc.enabled) {
            y_um[i] = stage_adc_code_to_um(s, i, stage_um_to_adc_code(s, i, y_um[i]));
        }
    }
}

int stage_run(stage_t *s, size_t n, const double *u0, const double *u1, double *y0, double *y1)
{
    size_t k;
    int i;
    if (!s || (n > 0 && (!u0 || !y0))) {
        return STAGE_ERR_ARG;
    }
    for (k = 0; k < n; k++) {
        double u[STAGE_MAX_AXES], v[STAGE_MAX_AXES], y[STAGE_MAX_AXES];
        u[0] = u0[k];
        u[1] = u1 ? u1[k] : 0.0;
        for (i = 0; i < s->p.num_axes; i++) {
            const stage_amp_params *amp = &s->p.axis[i].amp;
            v[i] = (u[i] - amp->offset_v) / amp->gain;
        }
        stage_step_f(s, v, y);
        y0[k] = y[0];
        if (y1 && s->p.num_axes > 1) {
            y1[k] = y[1];
        }
    }
    return STAGE_OK;
}

int stage_simulate_file(const char *path, uint64_t seed, double sample_rate_hz, size_t n,
                        const double *u0, const double *u1, double *y0, double *y1,
                        char *errbuf, size_t errlen)
{
    stage_params p;
    stage_t s;
    int rc = stage_params_load_json(path, &p, errbuf, errlen);
    if (rc != STAGE_OK) {
        return rc;
    }
    if (sample_rate_hz > 0.0) {
        p.sample_rate_hz = sample_rate_hz;
    }
    rc = stage_params_check(&p, errbuf, errlen);
    if (rc != STAGE_OK) {
        return rc;
    }
    rc = stage_init(&s, &p, seed);
    if (rc != STAGE_OK) {
        return fail(errbuf, errlen, "stage_init failed (%d)", rc);
    }
    if (p.num_axes == 2 && !y1) {
        if (errbuf && errlen) {
            snprintf(errbuf, errlen, "%s: a two-axis stage needs an output buffer for axis 2", path);
        }
        return STAGE_ERR_ARG;
    }
    return stage_run(&s, n, u0, u1, y0, y1);
}

int stage_file_info(const char *path, int *num_axes, double *sample_rate_hz, char *errbuf, size_t errlen)
{
    stage_params p;
    int rc = stage_params_load_json(path, &p, errbuf, errlen);
    if (rc != STAGE_OK) {
        return rc;
    }
    if (num_axes) {
        *num_axes = p.num_axes;
    }
    if (sample_rate_hz) {
        *sample_rate_hz = p.sample_rate_hz;
    }
    return STAGE_OK;
}

/* --------------------------------------------------------------- accessors */

double stage_true_um(const stage_t *s, int axis) { return s->ax[axis].x_true; }
double stage_hv_volts(const stage_t *s, int axis) { return s->ax[axis].v_hv; }
double stage_sensor_um(const stage_t *s, int axis) { return s->ax[axis].y_sensor; }
int stage_num_axes(const stage_t *s) { return s->p.num_axes; }
double stage_sample_rate(const stage_t *s) { return s->p.sample_rate_hz; }
int stage_abi_version(void) { return 1; }
