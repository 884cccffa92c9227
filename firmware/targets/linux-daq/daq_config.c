/* daq_config.c - the DAQ target's "key = value" configuration file. */
#include "daq_config.h"

#include <comedi.h>
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LINE_MAX_CHARS 1024
#define FILE_MAX_BYTES (256 * 1024)

enum key_type { K_PATH, K_CAL, K_U32, K_PRIO, K_SUBDEV, K_UINT, K_AREF, K_DBL, K_DBL_NONZERO };

typedef struct {
    const char *name;
    int axis_key;     /* 0: before any [axis N]; 1: inside one */
    enum key_type type;
    size_t offset;    /* into piezo_daq_config_t or piezo_daq_axis_cfg_t */
    size_t has;       /* offset of the "given" flag + 1, 0 = none */
    int required;
} key_t_;

#define G(f) offsetof(piezo_daq_config_t, f)
#define A(f) offsetof(piezo_daq_axis_cfg_t, f)

static const key_t_ keys[] = {
    {"device", 0, K_PATH, G(device), 0, 1},
    {"flash", 0, K_PATH, G(flash), 0, 1},
    {"calibration", 0, K_CAL, G(calibration), 0, 0},
    {"tick_hz", 0, K_U32, G(tick_hz), 0, 0},
    {"priority", 0, K_PRIO, G(priority), 0, 0},
    {"ao.subdevice", 1, K_SUBDEV, A(ao.subdevice), 0, 0},
    {"ao.channel", 1, K_UINT, A(ao.channel), 0, 1},
    {"ao.range", 1, K_UINT, A(ao.range), 0, 1},
    {"ao.aref", 1, K_AREF, A(ao.aref), 0, 0},
    {"ai.subdevice", 1, K_SUBDEV, A(ai.subdevice), 0, 0},
    {"ai.channel", 1, K_UINT, A(ai.channel), 0, 1},
    {"ai.range", 1, K_UINT, A(ai.range), 0, 1},
    {"ai.aref", 1, K_AREF, A(ai.aref), 0, 0},
    {"amplifier.gain", 1, K_DBL_NONZERO, A(amp_gain), 0, 1},
    {"amplifier.offset_v", 1, K_DBL, A(amp_offset_v), 0, 0},
    {"sensor.um_per_v", 1, K_DBL_NONZERO, A(sensor_um_per_v), 0, 1},
    {"sensor.offset_um", 1, K_DBL, A(sensor_offset_um), 0, 0},
    {"drive.safe_v", 1, K_DBL, A(safe_v), 0, 0},
    {"drive.min_v", 1, K_DBL, A(drive_min_v), A(has_drive_min) + 1u, 0},
    {"drive.max_v", 1, K_DBL, A(drive_max_v), A(has_drive_max) + 1u, 0},
};
#define N_KEYS (sizeof keys / sizeof keys[0])

typedef struct {
    const char *name;
    char *err;
    size_t errlen;
} ctx_t;

static int fail(const ctx_t *c, int line, const char *fmt, ...)
{
    va_list ap;
    int n = line > 0 ? snprintf(c->err, c->errlen, "%s:%d: ", c->name, line)
                     : snprintf(c->err, c->errlen, "%s: ", c->name);
    if (n >= 0 && (size_t)n < c->errlen) {
        va_start(ap, fmt);
        (void)vsnprintf(c->err + n, c->errlen - (size_t)n, fmt, ap);
        va_end(ap);
    }
    return -1;
}

static char *trim(char *s)
{
    char *e;
    while (*s == ' ' || *s == '\t') {
        s++;
    }
    e = s + strlen(s);
    while (e > s && isspace((unsigned char)e[-1])) {
        *--e = '\0';
    }
    return s;
}

static int parse_ulong(const char *v, unsigned long max, unsigned long *out)
{
    char *end;
    unsigned long x;
    if (!isdigit((unsigned char)v[0])) {
        return -1;
    }
    errno = 0;
    x = strtoul(v, &end, 10);
    if (errno != 0 || *end != '\0' || x > max) {
        return -1;
    }
    *out = x;
    return 0;
}

static int set_value(const ctx_t *c, int line, const key_t_ *k, char *base, const char *v)
{
    unsigned long u;
    char *end;
    double d;
    switch (k->type) {
    case K_PATH:
        if (v[0] == '\0') {
            return fail(c, line, "%s: needs a path", k->name);
        }
        if (strlen(v) >= PIEZO_DAQ_PATH_MAX) {
            return fail(c, line, "%s: path longer than %d characters", k->name, PIEZO_DAQ_PATH_MAX - 1);
        }
        strcpy(base + k->offset, v);
        return 0;
    case K_CAL: {
        piezo_daq_config_t *g = (piezo_daq_config_t *)(void *)base;
        if (strcmp(v, "auto") == 0) {
            g->calibration = PIEZO_DAQ_CAL_AUTO;
        } else if (strcmp(v, "none") == 0) {
            g->calibration = PIEZO_DAQ_CAL_NONE;
        } else if (v[0] == '\0' || strlen(v) >= PIEZO_DAQ_PATH_MAX) {
            return fail(c, line, "calibration: auto, none or the path of a calibration file");
        } else {
            g->calibration = PIEZO_DAQ_CAL_FILE;
            strcpy(g->calibration_path, v);
        }
        return 0;
    }
    case K_U32:
        if (parse_ulong(v, 100000ul, &u) != 0 || u < 100ul) {
            return fail(c, line, "%s: '%s' is not a rate in 100..100000 Hz", k->name, v);
        }
        *(uint32_t *)(void *)(base + k->offset) = (uint32_t)u;
        return 0;
    case K_PRIO:
        if (parse_ulong(v, 99ul, &u) != 0) {
            return fail(c, line, "%s: '%s' is not a SCHED_FIFO priority in 0..99 (0: none)", k->name, v);
        }
        *(int *)(void *)(base + k->offset) = (int)u;
        return 0;
    case K_SUBDEV:
        if (strcmp(v, "auto") == 0) {
            *(int *)(void *)(base + k->offset) = -1;
            return 0;
        }
        if (parse_ulong(v, 255ul, &u) != 0) {
            return fail(c, line, "%s: '%s' is not a subdevice number (0..255) or auto", k->name, v);
        }
        *(int *)(void *)(base + k->offset) = (int)u;
        return 0;
    case K_UINT:
        if (parse_ulong(v, 65535ul, &u) != 0) {
            return fail(c, line, "%s: '%s' is not a number in 0..65535", k->name, v);
        }
        *(unsigned *)(void *)(base + k->offset) = (unsigned)u;
        return 0;
    case K_AREF: {
        static const char *const names[4] = {"ground", "common", "diff", "other"};
        static const unsigned codes[4] = {AREF_GROUND, AREF_COMMON, AREF_DIFF, AREF_OTHER};
        for (int i = 0; i < 4; i++) {
            if (strcmp(v, names[i]) == 0) {
                *(unsigned *)(void *)(base + k->offset) = codes[i];
                return 0;
            }
        }
        return fail(c, line, "%s: '%s' is not one of ground, common, diff, other", k->name, v);
    }
    case K_DBL:
    case K_DBL_NONZERO:
        errno = 0;
        d = strtod(v, &end);
        if (v[0] == '\0' || *end != '\0' || errno != 0 || !isfinite(d)) {
            return fail(c, line, "%s: '%s' is not a number", k->name, v);
        }
        if (k->type == K_DBL_NONZERO && d == 0.0) {
            return fail(c, line, "%s: must not be 0", k->name);
        }
        *(double *)(void *)(base + k->offset) = d;
        if (k->has != 0u) {
            *(int *)(void *)(base + k->has - 1u) = 1;
        }
        return 0;
    }
    return fail(c, line, "%s: internal error", k->name);
}

static void axis_defaults(piezo_daq_axis_cfg_t *a)
{
    memset(a, 0, sizeof *a);
    a->ao.subdevice = -1;
    a->ai.subdevice = -1;
    a->ao.aref = AREF_GROUND;
    a->ai.aref = AREF_GROUND;
}

/* Required keys of a section that ended (axis -1: the global part). */
static int check_section(const ctx_t *c, int line, int axis, const unsigned char *seen)
{
    for (size_t i = 0; i < N_KEYS; i++) {
        if (keys[i].required && keys[i].axis_key == (axis >= 0) && !seen[i]) {
            if (axis >= 0) {
                return fail(c, line, "[axis %d]: missing key '%s'", axis, keys[i].name);
            }
            return fail(c, line, "missing key '%s'", keys[i].name);
        }
    }
    return 0;
}

static int check_axis(const ctx_t *c, int line, int axis, const piezo_daq_axis_cfg_t *a)
{
    if (a->has_drive_min && a->has_drive_max && !(a->drive_min_v < a->drive_max_v)) {
        return fail(c, line, "[axis %d]: drive.min_v must be below drive.max_v", axis);
    }
    if ((a->has_drive_min && a->safe_v < a->drive_min_v) || (a->has_drive_max && a->safe_v > a->drive_max_v)) {
        return fail(c, line, "[axis %d]: drive.safe_v %g V outside drive.min_v..drive.max_v", axis, a->safe_v);
    }
    return 0;
}

int piezo_daq_config_parse(const char *text, const char *name, piezo_daq_config_t *cfg, char *errbuf, size_t errlen)
{
    ctx_t c = {name != NULL ? name : "(config)", errbuf, errlen};
    unsigned char seen[N_KEYS];
    const char *p = text;
    int lineno = 0, axis = -1, section_line = 0;
    if (text == NULL || cfg == NULL) {
        return fail(&c, 0, "no configuration");
    }
    memset(cfg, 0, sizeof *cfg);
    cfg->calibration = PIEZO_DAQ_CAL_AUTO;
    cfg->tick_hz = 10000u;
    cfg->priority = 80;
    for (int i = 0; i < PIEZO_DAQ_MAX_AXES; i++) {
        axis_defaults(&cfg->axis[i]);
    }
    memset(seen, 0, sizeof seen);
    while (*p != '\0') {
        char line[LINE_MAX_CHARS], *s, *eq, *hash;
        const char *nl = strchr(p, '\n');
        size_t len = nl != NULL ? (size_t)(nl - p) : strlen(p);
        lineno++;
        if (len >= sizeof line) {
            return fail(&c, lineno, "line longer than %d characters", LINE_MAX_CHARS - 1);
        }
        memcpy(line, p, len);
        line[len] = '\0';
        p += len + (nl != NULL ? 1u : 0u);
        /* comments: '#' at the start or after a blank */
        for (hash = line; (hash = strchr(hash, '#')) != NULL; hash++) {
            if (hash == line || hash[-1] == ' ' || hash[-1] == '\t') {
                *hash = '\0';
                break;
            }
        }
        s = trim(line);
        if (*s == '\0') {
            continue;
        }
        if (*s == '[') {
            char *close = strchr(s, ']');
            unsigned long n;
            char *num;
            if (close == NULL || trim(close + 1)[0] != '\0') {
                return fail(&c, lineno, "a section is \"[axis N]\"");
            }
            *close = '\0';
            num = trim(s + 1);
            if (strncmp(num, "axis", 4) != 0 || (num[4] != ' ' && num[4] != '\t')) {
                return fail(&c, lineno, "unknown section [%s] (only [axis 0] and [axis 1])", num);
            }
            num = trim(num + 4);
            if (parse_ulong(num, 1000ul, &n) != 0 || n >= PIEZO_DAQ_MAX_AXES) {
                return fail(&c, lineno, "[axis %s]: axes are 0 and 1", num);
            }
            if ((int)n != axis + 1) {
                return fail(&c, lineno, "[axis %lu]: expected [axis %d] here (axes in order, each once)", n, axis + 1);
            }
            if (check_section(&c, axis < 0 ? lineno : section_line, axis, seen) != 0 ||
                (axis >= 0 && check_axis(&c, section_line, axis, &cfg->axis[axis]) != 0)) {
                return -1;
            }
            for (size_t i = 0; i < N_KEYS; i++) {
                if (keys[i].axis_key) {
                    seen[i] = 0;
                }
            }
            axis = (int)n;
            section_line = lineno;
            continue;
        }
        eq = strchr(s, '=');
        if (eq == NULL) {
            return fail(&c, lineno, "expected \"key = value\", got \"%s\"", s);
        }
        *eq = '\0';
        {
            const char *key = trim(s), *val = trim(eq + 1);
            size_t i;
            for (i = 0; i < N_KEYS; i++) {
                if (strcmp(keys[i].name, key) == 0) {
                    break;
                }
            }
            if (i == N_KEYS) {
                return fail(&c, lineno, "unknown key '%s'", key);
            }
            if (keys[i].axis_key != (axis >= 0)) {
                return fail(&c, lineno, keys[i].axis_key ? "'%s' belongs in an [axis N] section"
                                                         : "'%s' belongs before the first [axis N] section",
                            key);
            }
            if (seen[i]) {
                return fail(&c, lineno, "'%s' given twice", key);
            }
            seen[i] = 1;
            if (set_value(&c, lineno, &keys[i], keys[i].axis_key ? (char *)&cfg->axis[axis] : (char *)cfg, val) != 0) {
                return -1;
            }
        }
    }
    if (axis < 0) {
        if (check_section(&c, lineno, -1, seen) != 0) {
            return -1;
        }
        return fail(&c, lineno, "no [axis 0] section");
    }
    if (check_section(&c, section_line, axis, seen) != 0 || check_axis(&c, section_line, axis, &cfg->axis[axis]) != 0) {
        return -1;
    }
    cfg->n_axes = axis + 1;
    return 0;
}

int piezo_daq_config_load(const char *path, piezo_daq_config_t *cfg, char *errbuf, size_t errlen)
{
    static char text[FILE_MAX_BYTES + 1];
    FILE *f;
    size_t n;
    ctx_t c = {path, errbuf, errlen};
    if (path == NULL) {
        return fail(&c, 0, "no configuration file");
    }
    f = fopen(path, "r");
    if (f == NULL) {
        return fail(&c, 0, "cannot read: %s", strerror(errno));
    }
    n = fread(text, 1, FILE_MAX_BYTES + 1, f);
    if (ferror(f)) {
        int e = errno;
        fclose(f);
        return fail(&c, 0, "cannot read: %s", strerror(e));
    }
    fclose(f);
    if (n > FILE_MAX_BYTES) {
        return fail(&c, 0, "larger than %d bytes: not a configuration file", FILE_MAX_BYTES);
    }
    if (memchr(text, '\0', n) != NULL) {
        return fail(&c, 0, "contains NUL bytes: not a text file");
    }
    text[n] = '\0';
    return piezo_daq_config_parse(text, path, cfg, errbuf, errlen);
}
