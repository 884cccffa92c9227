/* The stage parameter file: a small JSON reader of our own (RFC 8259 syntax,
 * numbers through strtod in the "C" locale) and the mapping of its keys onto
 * stage_params. Every error names the file, the line and the key. */
#include "stage_model.h"

#include <errno.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define JSON_MAX_DEPTH 32
#define JSON_MAX_FILE (1l << 20)

/* ------------------------------------------------------------- the reader */

typedef enum { J_NULL, J_BOOL, J_NUM, J_STR, J_ARR, J_OBJ } jtype;

typedef struct jnode {
    jtype type;
    int line;
    double num;
    int boolean;
    char *str;           /* J_STR: value */
    char *key;           /* member of an object: its key */
    struct jnode *child; /* J_ARR, J_OBJ: first element */
    struct jnode *next;  /* next sibling */
} jnode;

typedef struct {
    const char *s;
    size_t pos, len;
    int line;
    const char *name;
    char *errbuf;
    size_t errlen;
    int failed;
} jparser;

static void jerr(char *errbuf, size_t errlen, const char *name, int line, const char *fmt, ...)
{
    char msg[256];
    va_list ap;
    if (!errbuf || errlen == 0) {
        return;
    }
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (line > 0) {
        snprintf(errbuf, errlen, "%s:%d: %s", name, line, msg);
    } else {
        snprintf(errbuf, errlen, "%s: %s", name, msg);
    }
}

static jnode *jfail(jparser *ps, const char *msg)
{
    if (!ps->failed) {
        jerr(ps->errbuf, ps->errlen, ps->name, ps->line, "%s", msg);
        ps->failed = 1;
    }
    return NULL;
}

static void jfree(jnode *n)
{
    while (n) {
        jnode *next = n->next;
        jfree(n->child);
        free(n->str);
        free(n->key);
        free(n);
        n = next;
    }
}

static void skip_ws(jparser *ps)
{
    while (ps->pos < ps->len) {
        char c = ps->s[ps->pos];
        if (c == '\n') {
            ps->line++;
        } else if (c != ' ' && c != '\t' && c != '\r') {
            return;
        }
        ps->pos++;
    }
}

static jnode *new_node(jparser *ps, jtype t)
{
    jnode *n = calloc(1, sizeof *n);
    if (!n) {
        return jfail(ps, "out of memory");
    }
    n->type = t;
    n->line = ps->line;
    return n;
}

static int hexval(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* Parses a string at ps->pos (at the opening quote); returns it malloc'd. */
static char *parse_string(jparser *ps)
{
    size_t cap = 16, n = 0;
    char *out;
    ps->pos++; /* opening quote */
    out = malloc(cap);
    if (!out) {
        jfail(ps, "out of memory");
        return NULL;
    }
    for (;;) {
        unsigned char c;
        char buf[4];
        size_t nb = 1, i;
        if (ps->pos >= ps->len) {
            free(out);
            jfail(ps, "unterminated string");
            return NULL;
        }
        c = (unsigned char)ps->s[ps->pos++];
        if (c == '"') {
            break;
        }
        if (c < 0x20) {
            free(out);
            jfail(ps, "control character in a string");
            return NULL;
        }
        buf[0] = (char)c;
        if (c == '\\') {
            char e = ps->pos < ps->len ? ps->s[ps->pos++] : '\0';
            switch (e) {
            case '"': buf[0] = '"'; break;
            case '\\': buf[0] = '\\'; break;
            case '/': buf[0] = '/'; break;
            case 'b': buf[0] = '\b'; break;
            case 'f': buf[0] = '\f'; break;
            case 'n': buf[0] = '\n'; break;
            case 'r': buf[0] = '\r'; break;
            case 't': buf[0] = '\t'; break;
            case 'u': {
                unsigned cp = 0;
                for (i = 0; i < 4; i++) {
                    int h = ps->pos < ps->len ? hexval(ps->s[ps->pos]) : -1;
                    if (h < 0) {
                        free(out);
                        jfail(ps, "bad \\u escape in a string");
                        return NULL;
                    }
                    cp = cp * 16u + (unsigned)h;
                    ps->pos++;
                }
                if (cp < 0x80u) {
                    buf[0] = (char)cp;
                } else if (cp < 0x800u) {
                    buf[0] = (char)(0xC0u | (cp >> 6));
                    buf[1] = (char)(0x80u | (cp & 0x3Fu));
                    nb = 2;
                } else {
                    buf[0] = (char)(0xE0u | (cp >> 12));
                    buf[1] = (char)(0x80u | ((cp >> 6) & 0x3Fu));
                    buf[2] = (char)(0x80u | (cp & 0x3Fu));
                    nb = 3;
                }
                break;
            }
            default:
                free(out);
                jfail(ps, "bad escape in a string");
                return NULL;
            }
        }
        if (n + nb + 1 > cap) {
            char *grown;
            cap = cap * 2 + nb;
            grown = realloc(out, cap);
            if (!grown) {
                free(out);
                jfail(ps, "out of memory");
                return NULL;
            }
            out = grown;
        }
        for (i = 0; i < nb; i++) {
            out[n++] = buf[i];
        }
    }
    out[n] = '\0';
    return out;
}

static int is_digit(char c) { return c >= '0' && c <= '9'; }

static jnode *parse_number(jparser *ps)
{
    size_t start = ps->pos, p = ps->pos;
    char tok[64];
    char *end;
    jnode *n;
    /* JSON grammar: -?(0|[1-9][0-9]*)(\.[0-9]+)?([eE][+-]?[0-9]+)? */
    if (p < ps->len && ps->s[p] == '-') p++;
    if (p < ps->len && ps->s[p] == '0') {
        p++;
    } else if (p < ps->len && is_digit(ps->s[p])) {
        while (p < ps->len && is_digit(ps->s[p])) p++;
    } else {
        return jfail(ps, "bad number");
    }
    if (p < ps->len && ps->s[p] == '.') {
        p++;
        if (!(p < ps->len && is_digit(ps->s[p]))) return jfail(ps, "bad number: digits expected after '.'");
        while (p < ps->len && is_digit(ps->s[p])) p++;
    }
    if (p < ps->len && (ps->s[p] == 'e' || ps->s[p] == 'E')) {
        p++;
        if (p < ps->len && (ps->s[p] == '+' || ps->s[p] == '-')) p++;
        if (!(p < ps->len && is_digit(ps->s[p]))) return jfail(ps, "bad number: digits expected in the exponent");
        while (p < ps->len && is_digit(ps->s[p])) p++;
    }
    if (p < ps->len && (ps->s[p] == '_' || ps->s[p] == '.' || (ps->s[p] >= 'a' && ps->s[p] <= 'z') ||
                        (ps->s[p] >= 'A' && ps->s[p] <= 'Z') || is_digit(ps->s[p]))) {
        return jfail(ps, "bad number");
    }
    if (p - start >= sizeof tok) {
        return jfail(ps, "number too long");
    }
    memcpy(tok, ps->s + start, p - start);
    tok[p - start] = '\0';
    errno = 0;
    n = new_node(ps, J_NUM);
    if (!n) return NULL;
    n->num = strtod(tok, &end);
    if (errno == ERANGE && (n->num > 1.0 || n->num < -1.0)) {
        free(n);
        return jfail(ps, "number out of range");
    }
    ps->pos = p;
    return n;
}

static jnode *parse_value(jparser *ps, int depth);

static int match_word(jparser *ps, const char *w)
{
    size_t n = strlen(w);
    if (ps->len - ps->pos >= n && memcmp(ps->s + ps->pos, w, n) == 0) {
        ps->pos += n;
        return 1;
    }
    return 0;
}

static jnode *parse_container(jparser *ps, int depth, int is_obj)
{
    jnode *n = new_node(ps, is_obj ? J_OBJ : J_ARR);
    jnode **tail;
    char close = is_obj ? '}' : ']';
    if (!n) return NULL;
    tail = &n->child;
    ps->pos++;
    skip_ws(ps);
    if (ps->pos < ps->len && ps->s[ps->pos] == close) {
        ps->pos++;
        return n;
    }
    for (;;) {
        char *key = NULL;
        jnode *v;
        int key_line = ps->line;
        skip_ws(ps);
        if (is_obj) {
            jnode *m;
            if (ps->pos >= ps->len || ps->s[ps->pos] != '"') {
                jfree(n);
                return jfail(ps, "a key in double quotes expected");
            }
            key_line = ps->line;
            key = parse_string(ps);
            if (!key) {
                jfree(n);
                return NULL;
            }
            for (m = n->child; m; m = m->next) {
                if (strcmp(m->key, key) == 0) {
                    char msg[160];
                    snprintf(msg, sizeof msg, "duplicate key '%.100s'", key);
                    free(key);
                    jfree(n);
                    return jfail(ps, msg);
                }
            }
            skip_ws(ps);
            if (ps->pos >= ps->len || ps->s[ps->pos] != ':') {
                free(key);
                jfree(n);
                return jfail(ps, "':' expected after a key");
            }
            ps->pos++;
        }
        v = parse_value(ps, depth + 1);
        if (!v) {
            free(key);
            jfree(n);
            return NULL;
        }
        v->key = key;
        if (is_obj) {
            v->line = key_line;
        }
        *tail = v;
        tail = &v->next;
        skip_ws(ps);
        if (ps->pos < ps->len && ps->s[ps->pos] == ',') {
            ps->pos++;
            continue;
        }
        if (ps->pos < ps->len && ps->s[ps->pos] == close) {
            ps->pos++;
            return n;
        }
        jfree(n);
        return jfail(ps, is_obj ? "',' or '}' expected" : "',' or ']' expected");
    }
}

static jnode *parse_value(jparser *ps, int depth)
{
    char c;
    jnode *n;
    if (depth > JSON_MAX_DEPTH) {
        return jfail(ps, "nested too deeply");
    }
    skip_ws(ps);
    if (ps->pos >= ps->len) {
        return jfail(ps, "unexpected end of file");
    }
    c = ps->s[ps->pos];
    if (c == '{' || c == '[') {
        return parse_container(ps, depth, c == '{');
    }
    if (c == '"') {
        char *s = parse_string(ps);
        if (!s) return NULL;
        n = new_node(ps, J_STR);
        if (!n) {
            free(s);
            return NULL;
        }
        n->str = s;
        return n;
    }
    if (c == '-' || is_digit(c)) {
        return parse_number(ps);
    }
    if (match_word(ps, "true")) {
        n = new_node(ps, J_BOOL);
        if (n) n->boolean = 1;
        return n;
    }
    if (match_word(ps, "false")) {
        return new_node(ps, J_BOOL);
    }
    if (match_word(ps, "null")) {
        return new_node(ps, J_NULL);
    }
    return jfail(ps, "a value expected (number, string, true, false, null, object or array)");
}

/* ------------------------------------------------------------- the mapping */

typedef enum { F_BOOL, F_NUM, F_INT, F_RANGE, F_OBJ, F_ARRAY, F_NAME } ftype;

typedef struct field {
    const char *key;
    ftype type;
    size_t off;  /* F_RANGE: min; F_ARRAY: first element */
    size_t off2; /* F_RANGE: max; F_ARRAY: count (int), or (size_t)-1 */
    const struct field *sub; /* F_OBJ, F_ARRAY: the element's fields */
    size_t elem_size;        /* F_ARRAY */
    int max_count;           /* F_ARRAY */
} field;

#define NO_COUNT ((size_t)-1)
#define END {NULL, F_BOOL, 0, 0, NULL, 0, 0}
#define FB(k, T, m) {k, F_BOOL, offsetof(T, m), 0, NULL, 0, 0}
#define FN(k, T, m) {k, F_NUM, offsetof(T, m), 0, NULL, 0, 0}
#define FI(k, T, m) {k, F_INT, offsetof(T, m), 0, NULL, 0, 0}
#define FR(k, T, lo, hi) {k, F_RANGE, offsetof(T, lo), offsetof(T, hi), NULL, 0, 0}
#define FO(k, T, m, sub) {k, F_OBJ, offsetof(T, m), 0, sub, 0, 0}
#define FA(k, T, m, cnt, sub, ET, max) {k, F_ARRAY, offsetof(T, m), cnt, sub, sizeof(ET), max}

static const field f_dac[] = {
    FB("enabled", stage_dac_params, enabled), FI("bits", stage_dac_params, bits),
    FR("range_v", stage_dac_params, v_min, v_max), END};
static const field f_delay[] = {
    FB("enabled", stage_delay_params, enabled), FI("samples", stage_delay_params, samples), END};
static const field f_bw[] = {
    FB("enabled", stage_bandwidth_params, enabled), FN("hz", stage_bandwidth_params, hz), END};
static const field f_slew[] = {
    FB("enabled", stage_slew_params, enabled), FN("current_limit_a", stage_slew_params, current_limit_a),
    FN("load_capacitance_f", stage_slew_params, load_capacitance_f), END};
static const field f_sat[] = {
    FB("enabled", stage_saturation_params, enabled), FR("range_v", stage_saturation_params, v_min, v_max), END};
static const field f_amp[] = {
    FN("gain", stage_amp_params, gain), FN("offset_v", stage_amp_params, offset_v),
    FO("bandwidth", stage_amp_params, bandwidth, f_bw), FO("slew_rate", stage_amp_params, slew, f_slew),
    FO("saturation", stage_amp_params, saturation, f_sat), END};
static const field f_rate[] = {
    FB("enabled", stage_rate_params, enabled), FN("gain", stage_rate_params, gain),
    FN("ref_v_per_s", stage_rate_params, ref_v_per_s), END};
static const field f_hyst[] = {
    FB("enabled", stage_hyst_params, enabled), FN("v_ref", stage_hyst_params, v_ref),
    FN("alpha", stage_hyst_params, alpha), FN("beta", stage_hyst_params, beta),
    FN("gamma", stage_hyst_params, gamma), FN("a2", stage_hyst_params, a2), FN("a3", stage_hyst_params, a3),
    FO("rate", stage_hyst_params, rate, f_rate), END};
static const field f_creep_term[] = {
    FN("tau_s", stage_creep_term, tau_s), FN("gain", stage_creep_term, gain), END};
static const field f_creep[] = {
    FB("enabled", stage_creep_params, enabled),
    FA("terms", stage_creep_params, term, offsetof(stage_creep_params, n_terms), f_creep_term, stage_creep_term,
       STAGE_MAX_CREEP),
    END};
static const field f_actuator[] = {FN("gain_um_per_v", stage_axis_params, actuator_gain_um_per_v), END};
static const field f_mode[] = {
    FN("freq_hz", stage_mode, freq_hz), FN("damping", stage_mode, damping), FN("gain", stage_mode, gain), END};
static const field f_mech[] = {
    FB("enabled", stage_mech_params, enabled),
    FA("modes", stage_mech_params, mode, offsetof(stage_mech_params, n_modes), f_mode, stage_mode,
       STAGE_MAX_MODES),
    END};
static const field f_thermal[] = {
    FB("enabled", stage_thermal_params, enabled), FN("drift_um_per_k", stage_thermal_params, drift_um_per_k),
    FN("delta_k", stage_thermal_params, delta_k), FN("time_constant_s", stage_thermal_params, time_constant_s),
    END};
static const field f_sensor[] = {
    FB("enabled", stage_sensor_params, enabled), FN("offset_um", stage_sensor_params, offset_um),
    FN("gain_error", stage_sensor_params, gain_error), FN("nonlinearity", stage_sensor_params, nonlinearity),
    FR("range_um", stage_sensor_params, range_min_um, range_max_um), END};
static const field f_noise[] = {
    FB("enabled", stage_noise_params, enabled), FN("rms_um", stage_noise_params, rms_um), END};
static const field f_adc[] = {
    FB("enabled", stage_adc_params, enabled), FI("bits", stage_adc_params, bits),
    FR("range_um", stage_adc_params, y_min_um, y_max_um), END};
/* "actuator" maps onto the axis itself (offset 0). */
static const field f_axis[] = {
    FO("dac", stage_axis_params, dac, f_dac), FO("delay", stage_axis_params, delay, f_delay),
    FO("amplifier", stage_axis_params, amp, f_amp), FO("hysteresis", stage_axis_params, hysteresis, f_hyst),
    FO("creep", stage_axis_params, creep, f_creep), {"actuator", F_OBJ, 0, 0, f_actuator, 0, 0},
    FO("mechanics", stage_axis_params, mechanics, f_mech), FO("thermal", stage_axis_params, thermal, f_thermal),
    FO("sensor", stage_axis_params, sensor, f_sensor), FO("noise", stage_axis_params, noise, f_noise),
    FO("adc", stage_axis_params, adc, f_adc), END};
static const field f_cpath[] = {
    FN("static_percent", stage_coupling_path, static_percent),
    FN("dynamic_percent", stage_coupling_path, dynamic_percent),
    FN("ref_freq_hz", stage_coupling_path, ref_freq_hz),
    FN("position_slope_per_um", stage_coupling_path, position_slope_per_um),
    FN("position_center_um", stage_coupling_path, position_center_um), END};
static const field f_coupling[] = {
    FB("enabled", stage_coupling_params, enabled),
    FA("into", stage_coupling_params, into, NO_COUNT, f_cpath, stage_coupling_path, STAGE_MAX_AXES), END};
static const field f_top[] = {
    {"name", F_NAME, offsetof(stage_params, name), 0, NULL, 0, 0},
    FN("sample_rate_hz", stage_params, sample_rate_hz),
    FA("axes", stage_params, axis, offsetof(stage_params, num_axes), f_axis, stage_axis_params, STAGE_MAX_AXES),
    FO("coupling", stage_params, coupling, f_coupling), END};

typedef struct {
    const char *name;
    char *errbuf;
    size_t errlen;
} jmap;

static const char *type_name(jtype t)
{
    static const char *const names[] = {"null", "true/false", "a number", "a string", "an array", "an object"};
    return names[t];
}

static int map_error(jmap *m, const jnode *n, const char *keypath, const char *fmt, ...)
{
    char msg[200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    jerr(m->errbuf, m->errlen, m->name, n ? n->line : 0, "%s: %s", keypath, msg);
    return STAGE_ERR_JSON;
}

static int map_object(jmap *m, const jnode *obj, const field *fields, void *base, const char *path);

static int map_number(jmap *m, const jnode *v, const char *kp, double *out)
{
    if (v->type != J_NUM) {
        return map_error(m, v, kp, "must be a number, not %s", type_name(v->type));
    }
    *out = v->num;
    return STAGE_OK;
}

static int map_field(jmap *m, const jnode *v, const field *f, void *base, const char *kp)
{
    char *at = (char *)base + f->off;
    switch (f->type) {
    case F_BOOL:
        if (v->type != J_BOOL) {
            return map_error(m, v, kp, "must be true or false, not %s", type_name(v->type));
        }
        *(bool *)(void *)at = v->boolean != 0;
        return STAGE_OK;
    case F_NUM:
        return map_number(m, v, kp, (double *)(void *)at);
    case F_INT: {
        double d = 0.0;
        int rc = map_number(m, v, kp, &d);
        if (rc != STAGE_OK) return rc;
        if (d != (double)(long)d || d < -1e9 || d > 1e9) {
            return map_error(m, v, kp, "must be an integer, not %g", d);
        }
        *(int *)(void *)at = (int)d;
        return STAGE_OK;
    }
    case F_RANGE: {
        const jnode *lo = v->child, *hi = lo ? lo->next : NULL;
        if (v->type != J_ARR || !lo || !hi || hi->next || lo->type != J_NUM || hi->type != J_NUM) {
            return map_error(m, v, kp, "must be [min, max], two numbers");
        }
        *(double *)(void *)at = lo->num;
        *(double *)(void *)((char *)base + f->off2) = hi->num;
        return STAGE_OK;
    }
    case F_NAME:
        if (v->type != J_STR) {
            return map_error(m, v, kp, "must be a string, not %s", type_name(v->type));
        }
        snprintf(at, STAGE_NAME_LEN, "%s", v->str);
        return STAGE_OK;
    case F_OBJ:
        if (v->type != J_OBJ) {
            return map_error(m, v, kp, "must be an object, not %s", type_name(v->type));
        }
        return map_object(m, v, f->sub, at, kp);
    case F_ARRAY: {
        const jnode *e;
        int count = 0;
        if (v->type != J_ARR) {
            return map_error(m, v, kp, "must be an array, not %s", type_name(v->type));
        }
        for (e = v->child; e; e = e->next) {
            char ekp[256];
            int rc;
            if (count == f->max_count) {
                return map_error(m, e, kp, "at most %d entries", f->max_count);
            }
            snprintf(ekp, sizeof ekp, "%.200s[%d]", kp, count);
            if (e->type != J_OBJ) {
                return map_error(m, e, ekp, "must be an object, not %s", type_name(e->type));
            }
            rc = map_object(m, e, f->sub, at + (size_t)count * f->elem_size, ekp);
            if (rc != STAGE_OK) return rc;
            count++;
        }
        if (f->off2 != NO_COUNT) {
            *(int *)(void *)((char *)base + f->off2) = count;
        }
        return STAGE_OK;
    }
    }
    return STAGE_ERR_JSON;
}

static int map_object(jmap *m, const jnode *obj, const field *fields, void *base, const char *path)
{
    const jnode *v;
    for (v = obj->child; v; v = v->next) {
        const field *f;
        char kp[256];
        snprintf(kp, sizeof kp, "%.180s%s%.60s", path, path[0] ? "." : "", v->key);
        if (strcmp(v->key, "note") == 0) { /* free text, e.g. a number's source */
            if (v->type != J_STR) {
                return map_error(m, v, kp, "must be a string");
            }
            continue;
        }
        for (f = fields; f->key; f++) {
            if (strcmp(f->key, v->key) == 0) {
                break;
            }
        }
        if (!f->key) {
            char known[200];
            size_t n = 0;
            const field *g;
            known[0] = '\0';
            for (g = fields; g->key && n < sizeof known; g++) {
                int w = snprintf(known + n, sizeof known - n, "%s%s", n ? ", " : "", g->key);
                if (w < 0) break;
                n += (size_t)w;
            }
            return map_error(m, v, kp, "unknown key (known here: %s, note)", known);
        }
        {
            int rc = map_field(m, v, f, base, kp);
            if (rc != STAGE_OK) return rc;
        }
    }
    return STAGE_OK;
}

int stage_params_parse_json(const char *text, const char *name, stage_params *p, char *errbuf, size_t errlen)
{
    jparser ps;
    jmap m;
    jnode *root, *v;
    int rc;
    char perr[200];

    if (!text || !p) {
        return STAGE_ERR_ARG;
    }
    if (!name) {
        name = "<string>";
    }
    memset(&ps, 0, sizeof ps);
    ps.s = text;
    ps.len = strlen(text);
    ps.line = 1;
    ps.name = name;
    ps.errbuf = errbuf;
    ps.errlen = errlen;
    root = parse_value(&ps, 0);
    if (!root) {
        return STAGE_ERR_JSON;
    }
    skip_ws(&ps);
    if (ps.pos != ps.len) {
        jfree(root);
        jfail(&ps, "trailing characters after the top-level object");
        return STAGE_ERR_JSON;
    }
    m.name = name;
    m.errbuf = errbuf;
    m.errlen = errlen;
    if (root->type != J_OBJ) {
        rc = map_error(&m, root, "(top level)", "must be an object, not %s", type_name(root->type));
        jfree(root);
        return rc;
    }
    /* "base" first: the starting values for the keys the file leaves out */
    *p = stage_params_default();
    for (v = root->child; v; v = v->next) {
        if (strcmp(v->key, "base") == 0) {
            if (v->type == J_STR && strcmp(v->str, "default") == 0) {
                *p = stage_params_default();
            } else if (v->type == J_STR && strcmp(v->str, "two_axis") == 0) {
                *p = stage_params_two_axis();
            } else if (v->type == J_STR && strcmp(v->str, "ideal") == 0) {
                *p = stage_params_ideal();
            } else {
                rc = map_error(&m, v, "base", "must be \"default\", \"two_axis\" or \"ideal\"");
                jfree(root);
                return rc;
            }
        }
    }
    {
        /* map everything except "base" */
        jnode **pp = &root->child, *b = NULL;
        while (*pp) {
            if (strcmp((*pp)->key, "base") == 0) {
                b = *pp;
                *pp = b->next;
                b->next = NULL;
                break;
            }
            pp = &(*pp)->next;
        }
        jfree(b);
    }
    rc = map_object(&m, root, f_top, p, "");
    jfree(root);
    if (rc != STAGE_OK) {
        return rc;
    }
    rc = stage_params_check(p, perr, sizeof perr);
    if (rc != STAGE_OK) {
        jerr(errbuf, errlen, name, 0, "%s", perr);
    }
    return rc;
}

int stage_params_load_json(const char *path, stage_params *p, char *errbuf, size_t errlen)
{
    FILE *f;
    char *text;
    long size;
    size_t got;
    int rc;
    if (!path || !p) {
        return STAGE_ERR_ARG;
    }
    f = fopen(path, "rb");
    if (!f) {
        jerr(errbuf, errlen, path, 0, "cannot open the stage parameter file: %s", strerror(errno));
        return STAGE_ERR_FILE;
    }
    if (fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        jerr(errbuf, errlen, path, 0, "cannot read the stage parameter file");
        return STAGE_ERR_FILE;
    }
    if (size > JSON_MAX_FILE) {
        fclose(f);
        jerr(errbuf, errlen, path, 0, "file larger than %ld bytes", JSON_MAX_FILE);
        return STAGE_ERR_FILE;
    }
    text = malloc((size_t)size + 1);
    if (!text) {
        fclose(f);
        jerr(errbuf, errlen, path, 0, "out of memory");
        return STAGE_ERR_FILE;
    }
    got = fread(text, 1, (size_t)size, f);
    fclose(f);
    if (got != (size_t)size) {
        free(text);
        jerr(errbuf, errlen, path, 0, "cannot read the stage parameter file");
        return STAGE_ERR_FILE;
    }
    text[got] = '\0';
    if (strlen(text) != got) {
        free(text);
        jerr(errbuf, errlen, path, 0, "NUL byte in the file: not a JSON text file");
        return STAGE_ERR_JSON;
    }
    rc = stage_params_parse_json(text, path, p, errbuf, errlen);
    free(text);
    return rc;
}
