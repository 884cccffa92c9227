/* Stage model: a simulated piezo nanopositioning stage (one or two axes) for
 * software-in-the-loop runs and for the host's `simulate`.
 *
 * This is host-side simulation code, not firmware core: it computes in double
 * precision, but it is deterministic (its own seeded PRNG) and allocates
 * nothing. The firmware talks to it like to hardware: DAC codes in, ADC codes
 * out, one call per sample (10 kHz by default).
 *
 * Signal chain of one axis, in this order (docs/stage-model.md):
 *
 *   DAC code -> DAC [V] -> transport delay -> HV amplifier (gain, offset,
 *   first-order bandwidth, slew-rate limit, saturation) -> hysteresis
 *   (Bouc-Wen + asymmetric polynomial) -> creep (sum of first-order terms)
 *   -> actuator gain [um/V] -> mechanical modes -> cross-coupling from the
 *   other axis -> thermal drift = true displacement -> sensor (offset, gain
 *   error, nonlinearity) -> noise -> ADC code.
 *
 * Every effect is a block with an `enabled` flag; a disabled block is ideal
 * (identity). The nominal conversions (DAC and ADC code mapping, amplifier
 * gain and offset, actuator gain) always apply. Each linear block is
 * discretized exactly for a zero-order-hold input (its own input held over the
 * sample); stage_step() returns the values at the END of the sample period,
 * i.e. what the firmware's ADC read at the next tick sees.
 *
 * Units: volts [V], micrometres [um], seconds [s], hertz [Hz].
 */
#ifndef STAGE_MODEL_H
#define STAGE_MODEL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define STAGE_MAX_AXES 2
#define STAGE_MAX_MODES 4
#define STAGE_MAX_CREEP 8
#define STAGE_MAX_DELAY 64
#define STAGE_NAME_LEN 64

/* Return codes. */
#define STAGE_OK 0
#define STAGE_ERR_ARG (-1)   /* bad argument (NULL, wrong axis count, ...) */
#define STAGE_ERR_PARAM (-2) /* a parameter out of its range */
#define STAGE_ERR_FILE (-3)  /* file cannot be read */
#define STAGE_ERR_JSON (-4)  /* syntax error, unknown key, wrong type */

/* DAC: code in [0, 2^bits - 1] (straight binary) -> v = v_min + code * lsb,
 * lsb = (v_max - v_min) / 2^bits. Disabled: ideal converter (no quantization
 * or clamping) on the float path stage_step_f()/stage_run(); stage_step()
 * always maps codes this way. */
typedef struct {
    bool enabled;
    int bits;        /* 1..24 */
    double v_min;    /* [V] code 0 */
    double v_max;    /* [V] code 2^bits (one LSB above the top code) */
} stage_dac_params;

/* Transport delay in whole samples (conversion and computation latency). */
typedef struct {
    bool enabled;
    int samples; /* 0..STAGE_MAX_DELAY */
} stage_delay_params;

typedef struct {
    bool enabled;
    double hz; /* [Hz] -3 dB bandwidth of the first-order small-signal response */
} stage_bandwidth_params;

/* Slew-rate limit of the amplifier driving the piezo's capacitance:
 * |dv/dt| <= current_limit_a / load_capacitance_f. */
typedef struct {
    bool enabled;
    double current_limit_a;    /* [A] */
    double load_capacitance_f; /* [F] */
} stage_slew_params;

typedef struct {
    bool enabled;
    double v_min, v_max; /* [V] output rails */
} stage_saturation_params;

/* High-voltage amplifier: v_out = gain * v_in + offset_v, then the blocks. */
typedef struct {
    double gain;     /* [V/V] */
    double offset_v; /* [V] */
    stage_bandwidth_params bandwidth;
    stage_slew_params slew;
    stage_saturation_params saturation;
} stage_amp_params;

/* Optional rate dependence of the loop width: alpha is scaled by
 * 1 + gain * r / (r + ref_v_per_s), r = |dv/dt| of the amplifier output. */
typedef struct {
    bool enabled;
    double gain;        /* [1] relative growth of alpha at high rates */
    double ref_v_per_s; /* [V/s] rate at which half of it is reached */
} stage_rate_params;

/* Hysteresis, Bouc-Wen with an asymmetric polynomial, on xi = v / v_ref:
 *   w / v_ref = xi + a2 xi^2 + a3 xi^3 - h,
 *   dh = alpha dxi - beta |dxi| h - gamma dxi |h|   (beta > |gamma|, alpha > 0),
 * integrated exactly for the straight input path between samples.
 * Disabled: w = v. */
typedef struct {
    bool enabled;
    double v_ref; /* [V] normalization voltage */
    double alpha, beta, gamma;
    double a2, a3;
    stage_rate_params rate;
} stage_hyst_params;

typedef struct {
    double tau_s; /* [s] time constant */
    double gain;  /* [1] final creep of this term relative to the input */
} stage_creep_term;

/* Creep: w_out = w + sum_i gain_i * lowpass_{tau_i}(w). */
typedef struct {
    bool enabled;
    int n_terms;
    stage_creep_term term[STAGE_MAX_CREEP];
} stage_creep_params;

typedef struct {
    double freq_hz; /* [Hz] natural frequency */
    double damping; /* [1] damping ratio zeta >= 0 */
    double gain;    /* [1] DC gain of the mode */
} stage_mode;

/* Mechanical dynamics: x = sum_m gain_m * w_m^2 / (s^2 + 2 zeta_m w_m s + w_m^2)
 * applied to the static displacement. Disabled: x = static displacement. */
typedef struct {
    bool enabled;
    int n_modes;
    stage_mode mode[STAGE_MAX_MODES];
} stage_mech_params;

/* Thermal drift after a temperature step delta_k at t = 0:
 * d(t) = drift_um_per_k * delta_k * (1 - exp(-t / time_constant_s)). */
typedef struct {
    bool enabled;
    double drift_um_per_k;
    double delta_k;
    double time_constant_s;
} stage_thermal_params;

/* Sensor: y = offset_um + (1 + gain_error) x + nonlinearity * span * (1 - q^2),
 * q = 2 (x - centre) / span over [range_min_um, range_max_um]: an endpoint
 * nonlinearity (bow) of `nonlinearity` times the span at the centre. */
typedef struct {
    bool enabled;
    double offset_um;
    double gain_error;   /* [1] */
    double nonlinearity; /* [1] fraction of the span */
    double range_min_um, range_max_um;
} stage_sensor_params;

typedef struct {
    bool enabled;
    double rms_um; /* white Gaussian noise, standard deviation [um] */
} stage_noise_params;

/* ADC: code = round((y - y_min) / lsb) clamped to [0, 2^bits - 1],
 * lsb = (y_max - y_min) / 2^bits; y = y_min + code * lsb. */
typedef struct {
    bool enabled;
    int bits; /* 1..24 */
    double y_min_um, y_max_um;
} stage_adc_params;

typedef struct {
    stage_dac_params dac;
    stage_delay_params delay;
    stage_amp_params amp;
    stage_hyst_params hysteresis;
    stage_creep_params creep;
    double actuator_gain_um_per_v; /* static displacement per volt of w */
    stage_mech_params mechanics;
    stage_thermal_params thermal;
    stage_sensor_params sensor;
    stage_noise_params noise;
    stage_adc_params adc;
} stage_axis_params;

/* Coupling from the other axis j into axis i (index i = receiving axis):
 *   c_i = f_i * (static_percent/100 * x_j
 *               - dynamic_percent/100 * a_j / (2 pi ref_freq_hz)^2),
 *   f_i = 1 + position_slope_per_um * (x_i - position_center_um),
 * x_j, a_j: displacement and modal acceleration of axis j from its own drive,
 * x_i: that of axis i. For a sine of frequency f the coupled fraction is
 * f_i * (static + dynamic * (f / ref)^2) percent; a_j is zero when axis j's
 * mechanics block is disabled. */
typedef struct {
    double static_percent;
    double dynamic_percent;
    double ref_freq_hz;
    double position_slope_per_um; /* [1/um] */
    double position_center_um;
} stage_coupling_path;

typedef struct {
    bool enabled;
    stage_coupling_path into[STAGE_MAX_AXES];
} stage_coupling_params;

typedef struct {
    char name[STAGE_NAME_LEN];
    int num_axes;          /* 1 or 2 */
    double sample_rate_hz; /* [Hz] */
    stage_axis_params axis[STAGE_MAX_AXES];
    stage_coupling_params coupling;
} stage_params;

/* State of one axis (private: read it through the accessors). */
typedef struct {
    double dac_lsb, adc_lsb;
    int32_t dac_max_code, adc_max_code;
    double delay_buf[STAGE_MAX_DELAY];
    int delay_pos;
    double amp_a;         /* exp(-2 pi f T) */
    double slew_step_v;   /* max change per sample [V] */
    double v_hv;          /* amplifier output [V] */
    double hyst_xi, hyst_h;
    double creep_a[STAGE_MAX_CREEP], creep_x[STAGE_MAX_CREEP];
    double mode_phi[STAGE_MAX_MODES][4]; /* Phi row-major */
    double mode_gam[STAGE_MAX_MODES][2];
    double mode_x[STAGE_MAX_MODES][2];   /* position, velocity */
    double thermal_a, thermal_x;
    double x_own, a_own;  /* from its own drive: displacement, acceleration */
    double x_true;        /* true displacement [um] */
    double y_sensor;      /* sensor output incl. noise, before the ADC [um] */
} stage_axis_state;

/* A stage instance: caller-owned, no heap. */
typedef struct {
    stage_params p;
    double dt; /* [s] */
    stage_axis_state ax[STAGE_MAX_AXES];
    uint64_t rng;
    double gauss_spare;
    int has_spare;
    uint64_t k; /* samples done */
} stage_t;

/* The default one-axis stage (docs/stage-model.md gives the sources). */
stage_params stage_params_default(void);
/* The default two-axis stage (140 Hz first resonance, coupling). */
stage_params stage_params_two_axis(void);
/* Every block disabled, unit gains, one axis, 16-bit converters over 0..10 V
 * and 0..10 um: a starting point for tests of one block. */
stage_params stage_params_ideal(void);

/* Checks every parameter's range; on error writes "key: message" to errbuf. */
int stage_params_check(const stage_params *p, char *errbuf, size_t errlen);

/* Reads a JSON parameter file (docs/stage-model.md): keys not given keep the
 * value of the base ("base": "default" (the default), "two_axis" or "ideal").
 * Unknown keys, wrong types and out-of-range values are errors; errbuf gets
 * "path:line: message". */
int stage_params_load_json(const char *path, stage_params *p, char *errbuf, size_t errlen);
/* Same, from a string (name is used in error messages). */
int stage_params_parse_json(const char *text, const char *name, stage_params *p,
                            char *errbuf, size_t errlen);

/* Checks the parameters and sets the stage at rest (all states zero) with the
 * noise generator seeded from seed. */
int stage_init(stage_t *s, const stage_params *p, uint64_t seed);

/* One sample: DAC codes in (one per axis; dac_code[1] ignored for one axis),
 * ADC codes out. */
void stage_step(stage_t *s, const int32_t dac_code[], int32_t adc_code[]);

/* One sample on the float path: DAC output voltage in [V], measured
 * displacement out [um]. An enabled DAC/ADC quantizes exactly as stage_step(). */
void stage_step_f(stage_t *s, const double v_dac[], double y_um[]);

/* Convenience for the host: n samples of amplifier output drive u [V] (the
 * nominal piezo voltage, converted to the DAC input through the amplifier's
 * nominal gain and offset) in, measured displacement [um] out. u1/y1 are for
 * the second axis: ignored for one axis; on two axes u1 == NULL holds the
 * second axis at 0 V and y1 == NULL drops its output. Continues from the
 * stage's current state. */
int stage_run(stage_t *s, size_t n, const double *u0, const double *u1, double *y0, double *y1);

/* Loads the parameter file, initializes a stage (sample_rate_hz > 0 overrides
 * the file's rate) and runs stage_run(): the entry point for ctypes. */
int stage_simulate_file(const char *path, uint64_t seed, double sample_rate_hz, size_t n,
                        const double *u0, const double *u1, double *y0, double *y1,
                        char *errbuf, size_t errlen);

/* Loads and checks a parameter file and reports its axis count and sample
 * rate (for the host binding). */
int stage_file_info(const char *path, int *num_axes, double *sample_rate_hz, char *errbuf, size_t errlen);

/* Conversions (the same as stage_step uses). */
int32_t stage_drive_to_dac_code(const stage_t *s, int axis, double u_volts);
double stage_dac_code_to_volts(const stage_t *s, int axis, int32_t code);
int32_t stage_um_to_adc_code(const stage_t *s, int axis, double y_um);
double stage_adc_code_to_um(const stage_t *s, int axis, int32_t code);

/* Accessors (values at the end of the last sample). */
double stage_true_um(const stage_t *s, int axis);   /* noise-free displacement */
double stage_hv_volts(const stage_t *s, int axis);  /* amplifier output */
double stage_sensor_um(const stage_t *s, int axis); /* sensor output before the ADC */
int stage_num_axes(const stage_t *s);
double stage_sample_rate(const stage_t *s);

/* The noise generator (exposed for tests): splitmix64 and a polar-method
 * Gaussian. */
uint64_t stage_rng_next(uint64_t *state);
double stage_rng_gauss(stage_t *s);

/* ABI version for the host binding (bumped when a signature changes). */
int stage_abi_version(void);

#ifdef __cplusplus
}
#endif

#endif /* STAGE_MODEL_H */
