/*
 * converters.h - what the host-side targets (sil, linux-daq) share about
 * their converters: the physical meaning of q15 full scale, and the
 * controller configuration that maps the full q15 range onto a DAC's and an
 * ADC's codes, with the safety defaults every target starts from.
 */
#ifndef PIEZO_CONVERTERS_H
#define PIEZO_CONVERTERS_H

#include <stdint.h>

#include "controller.h"

/* Physical value of q15 -32768 (min) and +32768 (max). */
typedef struct {
    double drive_min_v, drive_max_v;          /* amplifier output [V] */
    double position_min_um, position_max_um;
} piezo_scale_t;

/** q15 of a drive [V] / position [um], rounded half up, clamped to q15. */
int16_t piezo_scale_volts_to_q15(const piezo_scale_t *sc, double volts);
int16_t piezo_scale_um_to_q15(const piezo_scale_t *sc, double um);
/** Position [um] of a q15 value. */
double piezo_scale_q15_to_um(const piezo_scale_t *sc, int32_t q15);

/**
 * Controller configuration for straight-binary converters of dac_bits and
 * adc_bits (1..16): DAC code = 2^(b-1) + q15 * 2^b / 2^16, q15 = (ADC code -
 * 2^(b-1)) * 2^(16-b); the ADC rail codes are implausible, a jump of half the
 * range in one tick is implausible (no stage, even ringing), 3 bad samples
 * make the sensor fault, 100 overruns in a row the overrun fault; output
 * clamp the full range, no slew limit, PID and notch neutral, u_safe 0. The
 * target then sets u_safe and the clamp. Returns a piezo_err code.
 */
int piezo_converter_cfg(piezo_ctl_cfg_t *cfg, int dac_bits, int adc_bits);

#endif /* PIEZO_CONVERTERS_H */
