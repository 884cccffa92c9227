/*
 * daq_io.h - the controller's converters on a comedi board: one analog
 * output (drive) and one analog input (position sensor) per axis.
 *
 * The controller works in converter codes (controller.h). On this target its
 * codes are 16 bits over the configured comedi range, whatever the board's
 * resolution: code c means the voltage
 *     v(c) = min + (max - min) * c / 65535          (PIEZO_DAQ_CODE_MAX)
 * of the channel's range, so on a 16-bit board an ideal converter's raw
 * sample and the code are the same number. Between the two sits comedilib's
 * conversion, calibrated where the board has a calibration:
 *   input   raw -> volts: comedi_to_physical(raw, polynomial) when there is a
 *           converter polynomial, else comedi_to_phys(raw, range, maxdata);
 *           volts -> code by v(c) above, rounded. The rails stay rails: raw 0
 *           and raw maxdata (the converter out of range) give codes 0 and
 *           65535, which the controller's plausibility check refuses.
 *   output  code -> volts by v(c); volts -> raw: comedi_from_physical(volts,
 *           polynomial), else comedi_from_phys(volts, range, maxdata); raw is
 *           clamped to 0..maxdata.
 * The polynomial comes from comedi_get_softcal_converter() for subdevices
 * that are soft-calibrated (SDF_SOFT_CALIBRATED, e.g. NI M-series such as the
 * PCI-6221) when a calibration file is found (comedi_soft_calibrate writes
 * it), from comedi_get_hardcal_converter() for boards calibrated in hardware
 * (e.g. Advantech PCI-1716); without either the ideal range functions are used.
 *
 * Per tick the inputs of all axes are read with one comedi_do_insnlist()
 * call and, after the controller ran, the outputs written with another: two
 * system calls per tick, and the drive is updated as soon as it is computed.
 *
 * comedi_open() sets comedilib's global out-of-range behaviour to
 * COMEDI_OOR_NUMBER (piezo_daq_open): rail samples convert to numbers.
 */
#ifndef PIEZO_DAQ_IO_H
#define PIEZO_DAQ_IO_H

#include <stddef.h>
#include <stdint.h>

#include <comedilib.h>

#include "controller.h"
#include "converters.h"
#include "daq_config.h"

#define PIEZO_DAQ_CODE_MAX 65535 /* the controller's code range: 0..65535 over the comedi range */

enum piezo_daq_conv {
    PIEZO_DAQ_CONV_IDEAL = 0,   /* comedi_to_phys / comedi_from_phys */
    PIEZO_DAQ_CONV_HARDCAL = 1, /* polynomial from comedi_get_hardcal_converter */
    PIEZO_DAQ_CONV_SOFTCAL = 2  /* polynomial from comedi_get_softcal_converter and a calibration file */
};

typedef struct {
    unsigned subdevice, channel, range, aref;
    lsampl_t maxdata;
    comedi_range rng;           /* a copy of the channel's range */
    comedi_polynomial_t poly;   /* the converter, unless conv is IDEAL */
    int conv;                   /* enum piezo_daq_conv */
} piezo_daq_chan_t;

typedef struct {
    comedi_t *dev;
    int n_axes;
    piezo_daq_chan_t ao[PIEZO_DAQ_MAX_AXES], ai[PIEZO_DAQ_MAX_AXES];
    int32_t safe_code[PIEZO_DAQ_MAX_AXES];    /* DAC code of u_safe (piezo_daq_ctl_config) */
    lsampl_t ai_raw[PIEZO_DAQ_MAX_AXES], ao_raw[PIEZO_DAQ_MAX_AXES];
    comedi_insn rd_insn[PIEZO_DAQ_MAX_AXES], wr_insn[PIEZO_DAQ_MAX_AXES];
    comedi_insnlist rd, wr;
    char calibration_file[PIEZO_DAQ_PATH_MAX]; /* the file the converters came from, "" none */
    char notes[1024];                         /* warnings of the open (uncalibrated channels) */
    uint64_t io_errors;
} piezo_daq_t;

/** Opens the device and checks every channel of the configuration against it
 *  (subdevice type, channel, range, reference, voltage range), reads the
 *  converters and builds the instruction lists. Writes nothing to the board.
 *  Returns 0, or -1 with a one-line message in errbuf (the device is closed). */
int piezo_daq_open(piezo_daq_t *d, const piezo_daq_config_t *cfg, char *errbuf, size_t errlen);

/** Closes the device (no further comedi call). */
void piezo_daq_close(piezo_daq_t *d);

/** Reads every axis' sensor: code[i] on the controller's scale. 0, or -1
 *  (comedi_errno() tells why). */
int piezo_daq_read(piezo_daq_t *d, int32_t code[]);

/** Writes every axis' drive from controller codes. 0 or -1. */
int piezo_daq_write(piezo_daq_t *d, const int32_t code[]);

/** Writes safe_code[] to every axis: one instruction list, and channel by
 *  channel with comedi_data_write() when the list fails. 0, or -1 when a
 *  channel could not be written. */
int piezo_daq_write_safe(piezo_daq_t *d);

/** The conversions (see the top of this file). */
int32_t piezo_daq_ai_code(const piezo_daq_chan_t *ch, lsampl_t raw);
lsampl_t piezo_daq_ao_raw(const piezo_daq_chan_t *ch, int32_t code);
/** Volts of a (possibly fractional) code on a channel's range. */
double piezo_daq_code_volts(const piezo_daq_chan_t *ch, double code);

/** The controller configuration of one axis on this board (the same
 *  defaults as the SIL target: plausibility at the rails, no slew limit, PID
 *  off until configured), its physical scale, and safe_code[axis]. The drive
 *  clamp is drive.min_v..drive.max_v when given. Returns a piezo_err code. */
int piezo_daq_ctl_config(piezo_daq_t *d, const piezo_daq_config_t *cfg, int axis, piezo_ctl_cfg_t *ctl,
                         piezo_scale_t *scale);


/* The closed loop of the target: the board and one controller per axis. */
typedef struct {
    piezo_daq_t *daq;
    piezo_ctl_t *ctl[PIEZO_DAQ_MAX_AXES];
    int32_t adc[PIEZO_DAQ_MAX_AXES];
    int32_t dac[PIEZO_DAQ_MAX_AXES];
} piezo_daq_loop_t;

/** One tick: read the sensors, tick each controller (its own axis' code
 *  first, the other axis' second), write the drives. On an I/O error the safe
 *  drive is written (as far as the board lets it) and -1 returned. */
int piezo_daq_loop_tick(piezo_daq_loop_t *l);

#endif /* PIEZO_DAQ_IO_H */
