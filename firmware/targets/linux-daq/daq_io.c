/* daq_io.c - comedi analog I/O of the Linux DAQ target (daq_io.h). */
#include "daq_io.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "piezo_err.h"

static int fail(char *err, size_t len, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    (void)vsnprintf(err, len, fmt, ap);
    va_end(ap);
    return -1;
}

static void note(piezo_daq_t *d, const char *fmt, ...)
{
    size_t used = strlen(d->notes);
    va_list ap;
    if (used + 2u >= sizeof d->notes) {
        return;
    }
    if (used > 0u) {
        d->notes[used++] = '\n';
        d->notes[used] = '\0';
    }
    va_start(ap, fmt);
    (void)vsnprintf(d->notes + used, sizeof d->notes - used, fmt, ap);
    va_end(ap);
}

static const char *cerr(void)
{
    return comedi_strerror(comedi_errno());
}

static const char *aref_name(unsigned aref)
{
    switch (aref) {
    case AREF_GROUND: return "ground";
    case AREF_COMMON: return "common";
    case AREF_DIFF: return "diff";
    default: return "other";
    }
}

static int aref_flag(unsigned aref)
{
    switch (aref) {
    case AREF_GROUND: return SDF_GROUND;
    case AREF_COMMON: return SDF_COMMON;
    case AREF_DIFF: return SDF_DIFF;
    default: return SDF_OTHER;
    }
}

/* One channel of the configuration against the device: resolve and check. */
static int open_chan(piezo_daq_t *d, const piezo_daq_config_t *cfg, const comedi_calibration_t *cal, int axis,
                     int output, piezo_daq_chan_t *ch, char *err, size_t len)
{
    const piezo_daq_chan_cfg_t *cc = output ? &cfg->axis[axis].ao : &cfg->axis[axis].ai;
    const char *what = output ? "ao" : "ai";
    const int type = output ? COMEDI_SUBD_AO : COMEDI_SUBD_AI;
    const char *kind = output ? "analog output" : "analog input";
    comedi_range *r;
    int sd, flags, n;
    enum comedi_conversion_direction dir = output ? COMEDI_FROM_PHYSICAL : COMEDI_TO_PHYSICAL;

    memset(ch, 0, sizeof *ch);
    if (cc->subdevice < 0) {
        sd = comedi_find_subdevice_by_type(d->dev, type, 0u);
        if (sd < 0) {
            return fail(err, len, "%s: axis %d %s: the device has no %s subdevice", cfg->device, axis, what, kind);
        }
    } else {
        sd = cc->subdevice;
        n = comedi_get_n_subdevices(d->dev);
        if (n < 0 || sd >= n) {
            return fail(err, len, "%s: axis %d %s: no subdevice %d (the device has %d)", cfg->device, axis, what, sd,
                        n);
        }
        n = comedi_get_subdevice_type(d->dev, (unsigned)sd);
        if (n < 0) {
            return fail(err, len, "%s: axis %d %s: subdevice %d: %s", cfg->device, axis, what, sd, cerr());
        }
        if (n != type) {
            return fail(err, len, "%s: axis %d %s: subdevice %d is not an %s (type %d)", cfg->device, axis, what,
                        sd, kind, n);
        }
    }
    ch->subdevice = (unsigned)sd;
    ch->channel = cc->channel;
    ch->range = cc->range;
    ch->aref = cc->aref;
    n = comedi_get_n_channels(d->dev, ch->subdevice);
    if (n < 0 || cc->channel >= (unsigned)n) {
        return fail(err, len, "%s: axis %d %s: channel %u, subdevice %u has %d channels", cfg->device, axis, what,
                    cc->channel, ch->subdevice, n);
    }
    n = comedi_get_n_ranges(d->dev, ch->subdevice, ch->channel);
    if (n < 0 || cc->range >= (unsigned)n) {
        return fail(err, len, "%s: axis %d %s: range %u, channel %u of subdevice %u has %d ranges", cfg->device,
                    axis, what, cc->range, ch->channel, ch->subdevice, n);
    }
    flags = comedi_get_subdevice_flags(d->dev, ch->subdevice);
    if (flags < 0) {
        return fail(err, len, "%s: axis %d %s: subdevice %u: %s", cfg->device, axis, what, ch->subdevice, cerr());
    }
    if ((flags & aref_flag(cc->aref)) == 0) {
        return fail(err, len, "%s: axis %d %s: subdevice %u does not support aref %s", cfg->device, axis, what,
                    ch->subdevice, aref_name(cc->aref));
    }
    r = comedi_get_range(d->dev, ch->subdevice, ch->channel, ch->range);
    if (r == NULL) {
        return fail(err, len, "%s: axis %d %s: range %u: %s", cfg->device, axis, what, ch->range, cerr());
    }
    ch->rng = *r;
    if (ch->rng.unit != UNIT_volt || !(ch->rng.max > ch->rng.min)) {
        return fail(err, len, "%s: axis %d %s: range %u is not a voltage range (unit %u, %g..%g)", cfg->device,
                    axis, what, ch->range, ch->rng.unit, ch->rng.min, ch->rng.max);
    }
    ch->maxdata = comedi_get_maxdata(d->dev, ch->subdevice, ch->channel);
    if (ch->maxdata == 0u) {
        return fail(err, len, "%s: axis %d %s: maxdata 0: %s", cfg->device, axis, what, cerr());
    }

    /* the converter: a software calibration where the board needs one */
    ch->conv = PIEZO_DAQ_CONV_IDEAL;
    if ((flags & SDF_SOFT_CALIBRATED) != 0) {
        if (cal != NULL &&
            comedi_get_softcal_converter(ch->subdevice, ch->channel, ch->range, dir, cal, &ch->poly) == 0) {
            ch->conv = PIEZO_DAQ_CONV_SOFTCAL;
        } else if (cfg->calibration == PIEZO_DAQ_CAL_FILE) {
            return fail(err, len, "%s: axis %d %s: no calibration of subdevice %u channel %u range %u", d->calibration_file,
                        axis, what, ch->subdevice, ch->channel, ch->range);
        } else if (cfg->calibration == PIEZO_DAQ_CAL_AUTO) {
            note(d, "axis %d %s: subdevice %u is calibrated in software but %s: uncalibrated conversion "
                    "(run comedi_soft_calibrate)",
                 axis, what, ch->subdevice,
                 cal == NULL ? "no calibration file was found" : "the calibration file lacks this channel/range");
        }
    } else if (comedi_get_hardcal_converter(d->dev, ch->subdevice, ch->channel, ch->range, dir, &ch->poly) == 0) {
        ch->conv = PIEZO_DAQ_CONV_HARDCAL;
    }
    return 0;
}

int piezo_daq_open(piezo_daq_t *d, const piezo_daq_config_t *cfg, char *errbuf, size_t errlen)
{
    comedi_calibration_t *cal = NULL;
    int rc = 0;
    if (d == NULL || cfg == NULL || cfg->n_axes < 1 || cfg->n_axes > PIEZO_DAQ_MAX_AXES) {
        return fail(errbuf, errlen, "no configuration");
    }
    memset(d, 0, sizeof *d);
    d->n_axes = cfg->n_axes;
    (void)comedi_set_global_oor_behavior(COMEDI_OOR_NUMBER);
    d->dev = comedi_open(cfg->device);
    if (d->dev == NULL) {
        return fail(errbuf, errlen, "cannot open comedi device %s: %s (is the board's driver loaded and "
                    "attached with comedi_config?)", cfg->device, cerr());
    }
    if (cfg->calibration == PIEZO_DAQ_CAL_FILE) {
        snprintf(d->calibration_file, sizeof d->calibration_file, "%s", cfg->calibration_path);
    } else if (cfg->calibration == PIEZO_DAQ_CAL_AUTO) {
        char *path = comedi_get_default_calibration_path(d->dev);
        if (path != NULL) {
            snprintf(d->calibration_file, sizeof d->calibration_file, "%s", path);
            free(path);
        }
    }
    if (d->calibration_file[0] != '\0') {
        cal = comedi_parse_calibration_file(d->calibration_file);
        if (cal == NULL && cfg->calibration == PIEZO_DAQ_CAL_FILE) {
            rc = fail(errbuf, errlen, "%s: cannot read the calibration file: %s", d->calibration_file, cerr());
        }
        if (cal == NULL) {
            d->calibration_file[0] = '\0';
        }
    }
    for (int i = 0; rc == 0 && i < d->n_axes; i++) {
        rc = open_chan(d, cfg, cal, i, 1, &d->ao[i], errbuf, errlen);
        if (rc == 0) {
            rc = open_chan(d, cfg, cal, i, 0, &d->ai[i], errbuf, errlen);
        }
        for (int j = 0; rc == 0 && j < i; j++) {
            if (d->ao[j].subdevice == d->ao[i].subdevice && d->ao[j].channel == d->ao[i].channel) {
                rc = fail(errbuf, errlen, "%s: axes %d and %d drive the same output (subdevice %u channel %u)",
                          cfg->device, j, i, d->ao[i].subdevice, d->ao[i].channel);
            }
        }
    }
    if (cal != NULL) {
        comedi_cleanup_calibration(cal);
    }
    if (rc != 0) {
        piezo_daq_close(d);
        return -1;
    }
    for (int i = 0; i < d->n_axes; i++) {
        d->rd_insn[i].insn = INSN_READ;
        d->rd_insn[i].n = 1u;
        d->rd_insn[i].data = &d->ai_raw[i];
        d->rd_insn[i].subdev = d->ai[i].subdevice;
        d->rd_insn[i].chanspec = CR_PACK(d->ai[i].channel, d->ai[i].range, d->ai[i].aref);
        d->wr_insn[i].insn = INSN_WRITE;
        d->wr_insn[i].n = 1u;
        d->wr_insn[i].data = &d->ao_raw[i];
        d->wr_insn[i].subdev = d->ao[i].subdevice;
        d->wr_insn[i].chanspec = CR_PACK(d->ao[i].channel, d->ao[i].range, d->ao[i].aref);
        d->safe_code[i] = 0; /* piezo_daq_ctl_config sets the code of u_safe */
    }
    d->rd.n_insns = (unsigned)d->n_axes;
    d->rd.insns = d->rd_insn;
    d->wr.n_insns = (unsigned)d->n_axes;
    d->wr.insns = d->wr_insn;
    return 0;
}

void piezo_daq_close(piezo_daq_t *d)
{
    if (d != NULL && d->dev != NULL) {
        (void)comedi_close(d->dev);
        d->dev = NULL;
    }
}

double piezo_daq_code_volts(const piezo_daq_chan_t *ch, double code)
{
    return ch->rng.min + (ch->rng.max - ch->rng.min) * code / (double)PIEZO_DAQ_CODE_MAX;
}

int32_t piezo_daq_ai_code(const piezo_daq_chan_t *ch, lsampl_t raw)
{
    double v, c;
    if (raw == 0u) {
        return 0;
    }
    if (raw >= ch->maxdata) {
        return PIEZO_DAQ_CODE_MAX;
    }
    if (ch->conv == PIEZO_DAQ_CONV_IDEAL) {
        comedi_range r = ch->rng; /* comedi_to_phys takes a non-const range */
        v = comedi_to_phys(raw, &r, ch->maxdata);
    } else {
        v = comedi_to_physical(raw, &ch->poly);
    }
    c = floor((v - ch->rng.min) / (ch->rng.max - ch->rng.min) * (double)PIEZO_DAQ_CODE_MAX + 0.5);
    if (!(c >= 0.0)) {
        return 0; /* below the range, or NaN */
    }
    return c > (double)PIEZO_DAQ_CODE_MAX ? PIEZO_DAQ_CODE_MAX : (int32_t)c;
}

/* The polynomial's raw value, only to keep comedi_from_physical() inside
 * 0..maxdata (it does not range-check, and its result is unsigned). */
static double poly_raw(const comedi_polynomial_t *p, double v)
{
    double x = v - p->expansion_origin, s = 0.0, t = 1.0;
    for (unsigned i = 0; i <= p->order && i < COMEDI_MAX_NUM_POLYNOMIAL_COEFFICIENTS; i++) {
        s += p->coefficients[i] * t;
        t *= x;
    }
    return s;
}

lsampl_t piezo_daq_ao_raw(const piezo_daq_chan_t *ch, int32_t code)
{
    int32_t c = code < 0 ? 0 : (code > PIEZO_DAQ_CODE_MAX ? PIEZO_DAQ_CODE_MAX : code);
    double v = piezo_daq_code_volts(ch, (double)c), r;
    if (ch->conv == PIEZO_DAQ_CONV_IDEAL) {
        comedi_range rng = ch->rng;
        lsampl_t raw = comedi_from_phys(v, &rng, ch->maxdata);
        return raw > ch->maxdata ? ch->maxdata : raw;
    }
    r = poly_raw(&ch->poly, v);
    if (!(r >= 0.0)) {
        return 0u;
    }
    if (r >= (double)ch->maxdata) {
        return ch->maxdata;
    }
    return comedi_from_physical(v, &ch->poly);
}

int piezo_daq_read(piezo_daq_t *d, int32_t code[])
{
    if (d->dev == NULL || comedi_do_insnlist(d->dev, &d->rd) != (int)d->rd.n_insns) {
        d->io_errors++;
        return -1;
    }
    for (int i = 0; i < d->n_axes; i++) {
        code[i] = piezo_daq_ai_code(&d->ai[i], d->ai_raw[i]);
    }
    return 0;
}

int piezo_daq_write(piezo_daq_t *d, const int32_t code[])
{
    for (int i = 0; i < d->n_axes; i++) {
        d->ao_raw[i] = piezo_daq_ao_raw(&d->ao[i], code[i]);
    }
    if (d->dev == NULL || comedi_do_insnlist(d->dev, &d->wr) != (int)d->wr.n_insns) {
        d->io_errors++;
        return -1;
    }
    return 0;
}

int piezo_daq_write_safe(piezo_daq_t *d)
{
    int rc = 0;
    if (d->dev == NULL) {
        return -1;
    }
    if (piezo_daq_write(d, d->safe_code) == 0) {
        return 0;
    }
    /* the list failed somewhere: every channel on its own */
    for (int i = 0; i < d->n_axes; i++) {
        const piezo_daq_chan_t *ch = &d->ao[i];
        if (comedi_data_write(d->dev, ch->subdevice, ch->channel, ch->range, ch->aref, d->ao_raw[i]) != 1) {
            rc = -1;
        }
    }
    return rc;
}

int piezo_daq_ctl_config(piezo_daq_t *d, const piezo_daq_config_t *cfg, int axis, piezo_ctl_cfg_t *ctl,
                         piezo_scale_t *scale)
{
    const piezo_daq_axis_cfg_t *a;
    int16_t lo, hi;
    if (d == NULL || cfg == NULL || ctl == NULL || scale == NULL || axis < 0 || axis >= d->n_axes) {
        return PIEZO_EINVAL;
    }
    a = &cfg->axis[axis];
    /* q15 -32768 / +32768 are codes 0 / 65536 (one LSB above the top code) */
    scale->drive_min_v = a->amp_gain * piezo_daq_code_volts(&d->ao[axis], 0.0) + a->amp_offset_v;
    scale->drive_max_v = a->amp_gain * piezo_daq_code_volts(&d->ao[axis], 65536.0) + a->amp_offset_v;
    scale->position_min_um = a->sensor_offset_um + a->sensor_um_per_v * piezo_daq_code_volts(&d->ai[axis], 0.0);
    scale->position_max_um = a->sensor_offset_um + a->sensor_um_per_v * piezo_daq_code_volts(&d->ai[axis], 65536.0);

    /* 16-bit codes over the comedi range: DAC code = 32768 + q15, q15 = ADC code - 32768 */
    (void)piezo_converter_cfg(ctl, 16, 16);
    ctl->u_safe_q15 = piezo_scale_volts_to_q15(scale, a->safe_v);
    lo = a->has_drive_min ? piezo_scale_volts_to_q15(scale, a->drive_min_v) : -32768;
    hi = a->has_drive_max ? piezo_scale_volts_to_q15(scale, a->drive_max_v) : 32767;
    if (scale->drive_max_v < scale->drive_min_v) { /* inverting amplifier: volts fall as q15 rises */
        int16_t t = a->has_drive_max ? piezo_scale_volts_to_q15(scale, a->drive_max_v) : -32768;
        hi = a->has_drive_min ? piezo_scale_volts_to_q15(scale, a->drive_min_v) : 32767;
        lo = t;
    }
    if (lo > hi || ctl->u_safe_q15 < lo || ctl->u_safe_q15 > hi) {
        return PIEZO_ERANGE;
    }
    ctl->limit.min_q15 = lo;
    ctl->limit.max_q15 = hi;
    {
        int32_t code = 32768 + (int32_t)ctl->u_safe_q15;
        d->safe_code[axis] = code > PIEZO_DAQ_CODE_MAX ? PIEZO_DAQ_CODE_MAX : code;
    }
    return PIEZO_OK;
}

int piezo_daq_loop_tick(piezo_daq_loop_t *l)
{
    piezo_daq_t *d = l->daq;
    if (piezo_daq_read(d, l->adc) != 0) {
        (void)piezo_daq_write_safe(d);
        return -1;
    }
    for (int i = 0; i < d->n_axes; i++) {
        int32_t in[2] = {l->adc[i], d->n_axes > 1 ? l->adc[1 - i] : 0};
        piezo_ctl_tick(l->ctl[i], in, &l->dac[i]);
    }
    if (piezo_daq_write(d, l->dac) != 0) {
        (void)piezo_daq_write_safe(d);
        return -1;
    }
    return 0;
}
