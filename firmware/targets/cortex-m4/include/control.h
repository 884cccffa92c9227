/*
 * control.h - the firmware image's control loop (src/control.c): one
 * controller instance, its boot configuration, and the ADC/DAC seams.
 */
#ifndef PIEZO_CM4_CONTROL_H
#define PIEZO_CM4_CONTROL_H

#include <stdint.h>

#include "controller.h"
#include "store.h"

/** The axis the tick runs (piezo_control_tick() in tick.h). */
extern piezo_ctl_t piezo_axis;

/** The boot configuration: 16-bit ADC and DAC codes, mid-scale zero, full
 *  drive range, PID output unlimited, notch pass-through, u_safe = 0. */
void piezo_control_default_cfg(piezo_ctl_cfg_t *cfg);

/** Physical values of q15 -1 and +1 (the identity registers). */
typedef struct {
    int32_t drive_min_mv, drive_max_mv;
    int32_t position_min_nm, position_max_nm;
} piezo_control_range_t;

/** The ranges of the image's converters, set by piezo_control_init(). */
extern piezo_control_range_t piezo_control_range;

/** The board's configuration and ranges (weak; the PIL image overrides it
 *  with the stage model's converters). */
void piezo_control_board(piezo_ctl_cfg_t *cfg, piezo_control_range_t *range);

/** piezo_ctl_init() with the board's configuration (piezo_control_board): disarmed, IDLE, no table. */
int piezo_control_init(void);

/** The table storage the image attaches at boot (weak: the flash sectors 10
 *  and 11; the PIL image: RAM). */
const piezo_storage_t *piezo_control_storage(void);

/** The parameter storage the image attaches at boot (weak: the flash sectors
 *  8 and 9; the PIL image: RAM). */
const piezo_storage_t *piezo_control_params_storage(void);

/** ADC codes of this axis' sensor and the other axis' (weak default: zero codes). */
void piezo_adc_read(int32_t adc[2]);

/** The DAC code of this tick (weak default: discarded). */
void piezo_dac_write(int32_t code);

#endif /* PIEZO_CM4_CONTROL_H */
