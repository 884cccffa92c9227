/* fake_comedi.c - link-time fake of comedilib's device calls (fake_comedi.h). */
#include "fake_comedi.h"

#include <comedi_errno.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The handle comedi_open() returns: the fake's own definition of the opaque type. */
struct comedi_t_struct {
    int open;
};

typedef struct {
    unsigned subdev, chan, range, aref;
} expect_t;

static struct {
    int have_board;
    char path[256];
    fake_board_t board;
    struct comedi_t_struct handle;
    int handle_given;
    int err;
    char violation[512];
    int have_cal;
    char cal_path[256];
    int cal_omit;
    comedi_calibration_t cal;
    int cal_live;
    expect_t expect[FAKE_MAX_EXPECT];
    int n_expect;
    double in_v[FAKE_MAX_SUBDEVS][FAKE_MAX_CHANNELS];
    lsampl_t out_raw[FAKE_MAX_SUBDEVS][FAKE_MAX_CHANNELS];
    unsigned out_range[FAKE_MAX_SUBDEVS][FAKE_MAX_CHANNELS];
    unsigned chanspec[FAKE_MAX_SUBDEVS][FAKE_MAX_CHANNELS];
    stage_t *stage;
    fake_wire_t wire[STAGE_MAX_AXES];
    int n_wired;
    int written[STAGE_MAX_AXES];
    int32_t stage_dac[STAGE_MAX_AXES];
    unsigned long fail_from, fail_count;
    int write_fails;
    fake_comedi_stats_t st;
} F;

static void violate(const char *fmt, ...)
{
    va_list ap;
    if (F.violation[0] != '\0') {
        return; /* keep the first */
    }
    va_start(ap, fmt);
    (void)vsnprintf(F.violation, sizeof F.violation, fmt, ap);
    va_end(ap);
}

static int set_err(int e)
{
    F.err = e;
    return -1;
}

/* ---- boards -------------------------------------------------------------- */

static comedi_range volts(double lo, double hi)
{
    comedi_range r;
    r.min = lo;
    r.max = hi;
    r.unit = UNIT_volt;
    return r;
}

fake_board_t fake_board_pci6221(void)
{
    fake_board_t b;
    fake_subdev_t *ai = &b.sub[0], *ao = &b.sub[1], *dio = &b.sub[2];
    memset(&b, 0, sizeof b);
    b.name = "pci-6221";
    b.n_subdevs = 3;
    ai->type = COMEDI_SUBD_AI;
    ai->n_channels = 16;
    ai->maxdata = 65535;
    ai->flags = SDF_READABLE | SDF_SOFT_CALIBRATED | SDF_GROUND | SDF_COMMON | SDF_DIFF | SDF_OTHER;
    ai->n_ranges = 4;
    ai->range[0] = volts(-10.0, 10.0);
    ai->range[1] = volts(-5.0, 5.0);
    ai->range[2] = volts(-1.0, 1.0);
    ai->range[3] = volts(-0.2, 0.2);
    ao->type = COMEDI_SUBD_AO;
    ao->n_channels = 2;
    ao->maxdata = 65535;
    ao->flags = SDF_WRITABLE | SDF_SOFT_CALIBRATED | SDF_GROUND;
    ao->n_ranges = 1;
    ao->range[0] = volts(-10.0, 10.0);
    dio->type = COMEDI_SUBD_DIO;
    dio->n_channels = 24;
    dio->maxdata = 1;
    dio->flags = SDF_READABLE | SDF_WRITABLE;
    dio->n_ranges = 1;
    dio->range[0] = volts(0.0, 5.0);
    return b;
}

fake_board_t fake_board_pci1716(void)
{
    static const double bip[5] = {5.0, 2.5, 1.25, 0.625, 10.0};
    static const double uni[4] = {10.0, 5.0, 2.5, 1.25};
    fake_board_t b;
    fake_subdev_t *ai = &b.sub[0], *ao = &b.sub[1];
    memset(&b, 0, sizeof b);
    b.name = "pci1716";
    b.n_subdevs = 4;
    ai->type = COMEDI_SUBD_AI;
    ai->n_channels = 16;
    ai->maxdata = 65535;
    ai->flags = SDF_READABLE | SDF_GROUND | SDF_DIFF;
    ai->n_ranges = 9;
    for (int i = 0; i < 5; i++) {
        ai->range[i] = volts(-bip[i], bip[i]);
    }
    for (int i = 0; i < 4; i++) {
        ai->range[5 + i] = volts(0.0, uni[i]);
    }
    ao->type = COMEDI_SUBD_AO;
    ao->n_channels = 2;
    ao->maxdata = 65535;
    ao->flags = SDF_WRITABLE | SDF_GROUND;
    ao->n_ranges = 2;
    ao->range[0] = volts(0.0, 5.0);
    ao->range[1] = volts(0.0, 10.0);
    for (int i = 2; i < 4; i++) {
        b.sub[i].type = i == 2 ? COMEDI_SUBD_DI : COMEDI_SUBD_DO;
        b.sub[i].n_channels = 16;
        b.sub[i].maxdata = 1;
        b.sub[i].flags = i == 2 ? SDF_READABLE : SDF_WRITABLE;
        b.sub[i].n_ranges = 1;
        b.sub[i].range[0] = volts(0.0, 5.0);
    }
    return b;
}

/* ---- test control -------------------------------------------------------- */

void fake_comedi_reset(void)
{
    memset(&F, 0, sizeof F);
    F.cal_omit = -1;
    for (int s = 0; s < FAKE_MAX_SUBDEVS; s++) {
        for (int c = 0; c < FAKE_MAX_CHANNELS; c++) {
            F.chanspec[s][c] = ~0u;
        }
    }
    for (int i = 0; i < STAGE_MAX_AXES; i++) {
        F.stage_dac[i] = -1;
    }
}

void fake_comedi_set_board(const char *path, const fake_board_t *b)
{
    F.have_board = 1;
    snprintf(F.path, sizeof F.path, "%s", path);
    F.board = *b;
}

void fake_comedi_set_calibration(const char *path, int omit_subdev)
{
    F.have_cal = path != NULL;
    snprintf(F.cal_path, sizeof F.cal_path, "%s", path != NULL ? path : "");
    F.cal_omit = omit_subdev;
}

void fake_comedi_expect_io(unsigned subdev, unsigned chan, unsigned range, unsigned aref)
{
    if (F.n_expect < FAKE_MAX_EXPECT) {
        expect_t e = {subdev, chan, range, aref};
        F.expect[F.n_expect++] = e;
    }
}

void fake_comedi_attach_stage(stage_t *s, const fake_wire_t *w, int n_axes)
{
    F.stage = s;
    F.n_wired = n_axes;
    for (int i = 0; i < n_axes; i++) {
        F.wire[i] = w[i];
        F.written[i] = 0;
        F.stage_dac[i] = -1;
    }
}

int32_t fake_comedi_stage_dac(int axis)
{
    return F.stage_dac[axis];
}

void fake_comedi_set_input_volts(unsigned subdev, unsigned chan, double v)
{
    F.in_v[subdev][chan] = v;
}

lsampl_t fake_comedi_output_raw(unsigned subdev, unsigned chan)
{
    return F.out_raw[subdev][chan];
}

unsigned fake_comedi_last_chanspec(unsigned subdev, unsigned chan)
{
    return F.chanspec[subdev][chan];
}

void fake_comedi_fail_insnlist(unsigned long n, unsigned long count, int write_fails)
{
    F.fail_from = F.st.insnlists + n;
    F.fail_count = count;
    F.write_fails = write_fails;
}

const fake_comedi_stats_t *fake_comedi_stats(void)
{
    return &F.st;
}

const char *fake_comedi_violation(void)
{
    return F.violation[0] != '\0' ? F.violation : NULL;
}

/* ---- the analog side ----------------------------------------------------- */

static double ideal_volts(const fake_subdev_t *sd, unsigned range, lsampl_t raw)
{
    const comedi_range *r = &sd->range[range];
    return r->min + (r->max - r->min) * (double)raw / (double)sd->maxdata;
}

double fake_comedi_output_volts(unsigned subdev, unsigned chan)
{
    const fake_subdev_t *sd = &F.board.sub[subdev];
    return ideal_volts(sd, F.out_range[subdev][chan], F.out_raw[subdev][chan]) * (1.0 + sd->gain_error) + sd->offset_v;
}

static lsampl_t input_raw(unsigned subdev, unsigned chan, unsigned range)
{
    const fake_subdev_t *sd = &F.board.sub[subdev];
    const comedi_range *r = &sd->range[range];
    double v = F.in_v[subdev][chan] * (1.0 + sd->gain_error) + sd->offset_v;
    double q = floor((v - r->min) / (r->max - r->min) * (double)sd->maxdata + 0.5);
    return q <= 0.0 ? 0u : (q >= (double)sd->maxdata ? sd->maxdata : (lsampl_t)q);
}

/* The stage's sensor at the wired inputs. */
static void stage_inputs(const int32_t adc[])
{
    for (int i = 0; i < F.n_wired; i++) {
        const fake_wire_t *w = &F.wire[i];
        double um = stage_adc_code_to_um(F.stage, i, adc[i]);
        F.in_v[w->ai_subdev][w->ai_chan] = (um - w->sensor_offset_um) / w->sensor_um_per_v;
    }
}

/* After an output sample: one stage sample once every wired output has one. */
static void output_written(unsigned subdev, unsigned chan)
{
    int all = 1;
    if (F.stage == NULL) {
        return;
    }
    for (int i = 0; i < F.n_wired; i++) {
        if (F.wire[i].ao_subdev == subdev && F.wire[i].ao_chan == chan) {
            F.written[i] = 1;
        }
        all = all && F.written[i];
    }
    if (all) {
        int32_t dac[STAGE_MAX_AXES] = {0}, adc[STAGE_MAX_AXES] = {0};
        for (int i = 0; i < F.n_wired; i++) {
            const stage_axis_params *a = &F.stage->p.axis[i];
            double v = fake_comedi_output_volts(F.wire[i].ao_subdev, F.wire[i].ao_chan);
            dac[i] = stage_drive_to_dac_code(F.stage, i, a->amp.gain * v + a->amp.offset_v);
            F.stage_dac[i] = dac[i];
            F.written[i] = 0;
        }
        stage_step(F.stage, dac, adc);
        F.st.steps++;
        stage_inputs(adc);
    }
}

/* ---- checks shared by the calls ------------------------------------------ */

static int check_handle(const comedi_t *it, const char *fn)
{
    if (it == NULL || it != &F.handle || !F.handle_given) {
        violate("%s: not a handle from comedi_open", fn);
        return set_err(EBAD_CT);
    }
    if (!it->open) {
        violate("%s: called after comedi_close", fn);
        return set_err(EBAD_CT);
    }
    return 0;
}

static const fake_subdev_t *check_subdev(const comedi_t *it, unsigned subdev, const char *fn)
{
    if (check_handle(it, fn) != 0) {
        return NULL;
    }
    if (subdev >= F.board.n_subdevs) {
        violate("%s: subdevice %u does not exist", fn, subdev);
        set_err(EINVAL_SUBD);
        return NULL;
    }
    return &F.board.sub[subdev];
}

static const fake_subdev_t *check_chan(const comedi_t *it, unsigned subdev, unsigned chan, const char *fn)
{
    const fake_subdev_t *sd = check_subdev(it, subdev, fn);
    if (sd != NULL && chan >= sd->n_channels) {
        violate("%s: subdevice %u has no channel %u", fn, subdev, chan);
        set_err(EINVAL_CHAN);
        return NULL;
    }
    return sd;
}

/* One sample in or out: every rule of an instruction. */
static int check_io(const comedi_t *it, int write, unsigned subdev, unsigned chan, unsigned range, unsigned aref,
                    unsigned n, const lsampl_t *data, const char *fn)
{
    static const int aref_flags[4] = {SDF_GROUND, SDF_COMMON, SDF_DIFF, SDF_OTHER};
    const fake_subdev_t *sd = check_chan(it, subdev, chan, fn);
    if (sd == NULL) {
        return -1;
    }
    if (write ? (sd->type != COMEDI_SUBD_AO || (sd->flags & SDF_WRITABLE) == 0)
              : (sd->type != COMEDI_SUBD_AI || (sd->flags & SDF_READABLE) == 0)) {
        violate("%s: %s on subdevice %u, which is not an analog %s", fn, write ? "write" : "read", subdev,
                write ? "output" : "input");
        return set_err(EINVAL_SUBD);
    }
    if (range >= sd->n_ranges) {
        violate("%s: subdevice %u has no range %u", fn, subdev, range);
        return set_err(EINVAL);
    }
    if (aref > 3u || (sd->flags & aref_flags[aref]) == 0) {
        violate("%s: subdevice %u does not support aref %u", fn, subdev, aref);
        return set_err(EINVAL);
    }
    if (n != 1u || data == NULL) {
        violate("%s: %u samples (data %p) where one is expected", fn, n, (const void *)data);
        return set_err(EINVAL);
    }
    if (write && data[0] > sd->maxdata) {
        violate("%s: sample %u beyond maxdata %u", fn, data[0], sd->maxdata);
        return set_err(EINVAL);
    }
    if (F.n_expect > 0) {
        int ok = 0;
        for (int i = 0; i < F.n_expect; i++) {
            const expect_t *e = &F.expect[i];
            ok = ok || (e->subdev == subdev && e->chan == chan && e->range == range && e->aref == aref);
        }
        if (!ok) {
            violate("%s: unexpected channel: subdevice %u channel %u range %u aref %u", fn, subdev, chan, range, aref);
            return set_err(EINVAL);
        }
    }
    F.chanspec[subdev][chan] = CR_PACK(chan, range, aref);
    return 0;
}

static void do_write(unsigned subdev, unsigned chan, unsigned range, lsampl_t v)
{
    F.out_raw[subdev][chan] = v;
    F.out_range[subdev][chan] = range;
    output_written(subdev, chan);
}

/* ---- the wrapped comedilib functions ------------------------------------- */

comedi_t *__wrap_comedi_open(const char *fn);
int __wrap_comedi_close(comedi_t *it);
int __wrap_comedi_errno(void);
int __wrap_comedi_get_n_subdevices(comedi_t *it);
int __wrap_comedi_find_subdevice_by_type(comedi_t *it, int type, unsigned int subd);
int __wrap_comedi_get_subdevice_type(comedi_t *it, unsigned int subdevice);
int __wrap_comedi_get_subdevice_flags(comedi_t *it, unsigned int subdevice);
int __wrap_comedi_get_n_channels(comedi_t *it, unsigned int subdevice);
int __wrap_comedi_get_n_ranges(comedi_t *it, unsigned int subdevice, unsigned int chan);
comedi_range *__wrap_comedi_get_range(comedi_t *it, unsigned int subdevice, unsigned int chan, unsigned int range);
lsampl_t __wrap_comedi_get_maxdata(comedi_t *it, unsigned int subdevice, unsigned int chan);
int __wrap_comedi_do_insnlist(comedi_t *it, comedi_insnlist *il);
int __wrap_comedi_data_read(comedi_t *it, unsigned int subd, unsigned int chan, unsigned int range,
                            unsigned int aref, lsampl_t *data);
int __wrap_comedi_data_write(comedi_t *it, unsigned int subd, unsigned int chan, unsigned int range,
                             unsigned int aref, lsampl_t data);
char *__wrap_comedi_get_default_calibration_path(comedi_t *dev);
comedi_calibration_t *__wrap_comedi_parse_calibration_file(const char *cal_file_path);
void __wrap_comedi_cleanup_calibration(comedi_calibration_t *calibration);
int __wrap_comedi_get_softcal_converter(unsigned subdevice, unsigned channel, unsigned range,
                                        enum comedi_conversion_direction direction,
                                        const comedi_calibration_t *calibration, comedi_polynomial_t *polynomial);
int __wrap_comedi_get_hardcal_converter(comedi_t *dev, unsigned subdevice, unsigned channel, unsigned range,
                                        enum comedi_conversion_direction direction, comedi_polynomial_t *polynomial);

comedi_t *__wrap_comedi_open(const char *fn)
{
    F.st.opens++;
    if (!F.have_board || fn == NULL || strcmp(fn, F.path) != 0) {
        set_err(ENOENT);
        return NULL;
    }
    if (F.handle_given && F.handle.open) {
        violate("comedi_open: %s opened twice", fn);
    }
    F.handle_given = 1;
    F.handle.open = 1;
    return &F.handle;
}

int __wrap_comedi_close(comedi_t *it)
{
    F.st.closes++;
    if (check_handle(it, "comedi_close") != 0) {
        return -1;
    }
    if (F.cal_live) {
        violate("comedi_close: calibration still allocated");
    }
    it->open = 0;
    return 0;
}

int __wrap_comedi_errno(void)
{
    return F.err;
}

int __wrap_comedi_get_n_subdevices(comedi_t *it)
{
    if (check_handle(it, "comedi_get_n_subdevices") != 0) {
        return -1;
    }
    return (int)F.board.n_subdevs;
}

int __wrap_comedi_find_subdevice_by_type(comedi_t *it, int type, unsigned int subd)
{
    if (check_handle(it, "comedi_find_subdevice_by_type") != 0) {
        return -1;
    }
    for (unsigned i = subd; i < F.board.n_subdevs; i++) {
        if (F.board.sub[i].type == type) {
            return (int)i;
        }
    }
    return set_err(EINVAL_SUBD);
}

int __wrap_comedi_get_subdevice_type(comedi_t *it, unsigned int subdevice)
{
    const fake_subdev_t *sd = check_subdev(it, subdevice, "comedi_get_subdevice_type");
    return sd != NULL ? sd->type : -1;
}

int __wrap_comedi_get_subdevice_flags(comedi_t *it, unsigned int subdevice)
{
    const fake_subdev_t *sd = check_subdev(it, subdevice, "comedi_get_subdevice_flags");
    return sd != NULL ? sd->flags : -1;
}

int __wrap_comedi_get_n_channels(comedi_t *it, unsigned int subdevice)
{
    const fake_subdev_t *sd = check_subdev(it, subdevice, "comedi_get_n_channels");
    return sd != NULL ? (int)sd->n_channels : -1;
}

int __wrap_comedi_get_n_ranges(comedi_t *it, unsigned int subdevice, unsigned int chan)
{
    const fake_subdev_t *sd = check_chan(it, subdevice, chan, "comedi_get_n_ranges");
    return sd != NULL ? (int)sd->n_ranges : -1;
}

comedi_range *__wrap_comedi_get_range(comedi_t *it, unsigned int subdevice, unsigned int chan, unsigned int range)
{
    const fake_subdev_t *sd = check_chan(it, subdevice, chan, "comedi_get_range");
    if (sd == NULL) {
        return NULL;
    }
    if (range >= sd->n_ranges) {
        violate("comedi_get_range: subdevice %u has no range %u", subdevice, range);
        set_err(EINVAL);
        return NULL;
    }
    return &F.board.sub[subdevice].range[range];
}

lsampl_t __wrap_comedi_get_maxdata(comedi_t *it, unsigned int subdevice, unsigned int chan)
{
    const fake_subdev_t *sd = check_chan(it, subdevice, chan, "comedi_get_maxdata");
    return sd != NULL ? sd->maxdata : 0u;
}

int __wrap_comedi_do_insnlist(comedi_t *it, comedi_insnlist *il)
{
    unsigned done = 0;
    F.st.insnlists++;
    if (check_handle(it, "comedi_do_insnlist") != 0) {
        return -1;
    }
    if (il == NULL || il->insns == NULL || il->n_insns == 0u) {
        violate("comedi_do_insnlist: empty list");
        return set_err(EINVAL);
    }
    if (F.fail_count > 0u && F.st.insnlists >= F.fail_from) {
        F.fail_count--;
        return set_err(EIO);
    }
    for (; done < il->n_insns; done++) {
        const comedi_insn *in = &il->insns[done];
        unsigned chan = CR_CHAN(in->chanspec), range = CR_RANGE(in->chanspec), aref = CR_AREF(in->chanspec);
        int write = in->insn == INSN_WRITE;
        if (in->insn != INSN_READ && !write) {
            violate("comedi_do_insnlist: instruction %u: only INSN_READ and INSN_WRITE are expected", done);
            set_err(EINVAL);
            break;
        }
        if (check_io(it, write, in->subdev, chan, range, aref, in->n, in->data, "comedi_do_insnlist") != 0) {
            break;
        }
        F.st.insns++;
        if (write) {
            do_write(in->subdev, chan, range, in->data[0]);
        } else {
            in->data[0] = input_raw(in->subdev, chan, range);
        }
    }
    return done == 0u ? -1 : (int)done;
}

int __wrap_comedi_data_read(comedi_t *it, unsigned int subd, unsigned int chan, unsigned int range,
                            unsigned int aref, lsampl_t *data)
{
    F.st.data_reads++;
    if (check_io(it, 0, subd, chan, range, aref, 1u, data, "comedi_data_read") != 0) {
        return -1;
    }
    *data = input_raw(subd, chan, range);
    return 1;
}

int __wrap_comedi_data_write(comedi_t *it, unsigned int subd, unsigned int chan, unsigned int range,
                             unsigned int aref, lsampl_t data)
{
    F.st.data_writes++;
    if (check_io(it, 1, subd, chan, range, aref, 1u, &data, "comedi_data_write") != 0) {
        return -1;
    }
    if (F.write_fails) {
        return set_err(EIO);
    }
    do_write(subd, chan, range, data);
    return 1;
}

char *__wrap_comedi_get_default_calibration_path(comedi_t *dev)
{
    char *p;
    if (check_handle(dev, "comedi_get_default_calibration_path") != 0) {
        return NULL;
    }
    if (!F.have_cal) {
        set_err(ENOENT);
        return NULL;
    }
    p = malloc(strlen(F.cal_path) + 1u); /* the caller frees it, as with comedilib */
    if (p != NULL) {
        strcpy(p, F.cal_path);
    }
    return p;
}

comedi_calibration_t *__wrap_comedi_parse_calibration_file(const char *cal_file_path)
{
    if (!F.have_cal || cal_file_path == NULL || strcmp(cal_file_path, F.cal_path) != 0) {
        set_err(ENOENT);
        return NULL;
    }
    if (F.cal_live) {
        violate("comedi_parse_calibration_file: previous calibration not freed");
    }
    F.st.calibrations_parsed++;
    F.cal_live = 1;
    memset(&F.cal, 0, sizeof F.cal);
    return &F.cal;
}

void __wrap_comedi_cleanup_calibration(comedi_calibration_t *calibration)
{
    if (calibration != &F.cal || !F.cal_live) {
        violate("comedi_cleanup_calibration: not a live calibration");
        return;
    }
    F.st.calibrations_freed++;
    F.cal_live = 0;
}

static void linear(comedi_polynomial_t *p, double c0, double c1)
{
    memset(p, 0, sizeof *p);
    p->coefficients[0] = c0;
    p->coefficients[1] = c1;
    p->expansion_origin = 0.0;
    p->order = 1;
}

int __wrap_comedi_get_softcal_converter(unsigned subdevice, unsigned channel, unsigned range,
                                        enum comedi_conversion_direction direction,
                                        const comedi_calibration_t *calibration, comedi_polynomial_t *polynomial)
{
    const fake_subdev_t *sd;
    double lo, hi, g, o, md;
    F.st.softcal_lookups++;
    if (calibration != &F.cal || !F.cal_live) {
        violate("comedi_get_softcal_converter: not a live calibration");
        return set_err(EINVAL);
    }
    if (subdevice >= F.board.n_subdevs || polynomial == NULL) {
        violate("comedi_get_softcal_converter: subdevice %u", subdevice);
        return set_err(EINVAL_SUBD);
    }
    sd = &F.board.sub[subdevice];
    if (channel >= sd->n_channels || range >= sd->n_ranges) {
        violate("comedi_get_softcal_converter: channel %u range %u of subdevice %u", channel, range, subdevice);
        return set_err(EINVAL);
    }
    if ((sd->flags & SDF_SOFT_CALIBRATED) == 0 || (int)subdevice == F.cal_omit) {
        return set_err(EINVAL); /* the file has nothing for it */
    }
    lo = sd->range[range].min;
    hi = sd->range[range].max;
    g = 1.0 + sd->gain_error;
    o = sd->offset_v;
    md = (double)sd->maxdata;
    if (sd->type == COMEDI_SUBD_AI && direction == COMEDI_TO_PHYSICAL) {
        /* input volts = (ideal(raw) - offset) / (1 + gain error) */
        linear(polynomial, (lo - o) / g, (hi - lo) / (md * g));
        return 0;
    }
    if (sd->type == COMEDI_SUBD_AO && direction == COMEDI_FROM_PHYSICAL) {
        /* raw such that ideal(raw) (1 + gain error) + offset = volts */
        linear(polynomial, (-o / g - lo) * md / (hi - lo), md / ((hi - lo) * g));
        return 0;
    }
    return set_err(EINVAL); /* like comedi_soft_calibrate's files: one direction per subdevice */
}

int __wrap_comedi_get_hardcal_converter(comedi_t *dev, unsigned subdevice, unsigned channel, unsigned range,
                                        enum comedi_conversion_direction direction, comedi_polynomial_t *polynomial)
{
    const fake_subdev_t *sd = check_chan(dev, subdevice, channel, "comedi_get_hardcal_converter");
    double lo, hi, md;
    F.st.hardcal_lookups++;
    if (sd == NULL) {
        return -1;
    }
    if (range >= sd->n_ranges || polynomial == NULL) {
        violate("comedi_get_hardcal_converter: range %u of subdevice %u", range, subdevice);
        return set_err(EINVAL);
    }
    lo = sd->range[range].min;
    hi = sd->range[range].max;
    md = (double)sd->maxdata;
    if (direction == COMEDI_TO_PHYSICAL) {
        linear(polynomial, lo, (hi - lo) / md);
    } else {
        linear(polynomial, -lo * md / (hi - lo), md / (hi - lo));
    }
    return 0;
}
