/*
 * fake_comedi.h - a link-time fake of comedilib's device calls for the
 * Linux DAQ target's tests.
 *
 * The test executables link the real libcomedi (its conversion functions
 * comedi_to_phys, comedi_from_phys, comedi_to_physical, comedi_from_physical
 * and comedi_strerror are pure arithmetic and run for real) and replace every
 * call that would touch a device with -Wl,--wrap=<name> (tests/firmware/daq.cmake
 * lists them): comedi_open, comedi_close, comedi_errno, the subdevice,
 * channel, range and maxdata queries, the calibration functions,
 * comedi_do_insnlist, comedi_data_read and comedi_data_write.
 *
 * The fake holds one board (a table of subdevices modelled on the NI
 * PCI-6221 or the Advantech PCI-1716, or the test's own) at a device path.
 * Every call is checked: a valid, open handle (no call after comedi_close),
 * a subdevice of the right kind for the instruction, channel, range and
 * analog reference that the subdevice has, one sample per instruction, a
 * sample within maxdata; and, when the test lists the channels it expects
 * (fake_comedi_expect_io), exactly those. A broken rule is recorded (the
 * first message is kept) and the call fails with an error, so the code under
 * test sees what the real library would report.
 *
 * Analog behaviour: each converter has a gain and an offset error
 * (actual = ideal * (1 + gain_error) + offset_v). A calibration file, when
 * the test provides one, holds the polynomials that undo these errors
 * exactly (as comedi_soft_calibrate would measure them). With a stage model
 * attached, the board's outputs drive the stage and its sensor feeds the
 * inputs: whenever every wired output has been written since the last
 * sample, the stage advances one sample (stage_step) with the DAC codes the
 * output voltages quantize to, and the wired inputs then see its ADC codes
 * as sensor voltages. So a read-compute-write tick is one stage sample, as
 * in the SIL loop.
 */
#ifndef FAKE_COMEDI_H
#define FAKE_COMEDI_H

#include <comedilib.h>

#include "stage_model.h"

#define FAKE_MAX_SUBDEVS 8
#define FAKE_MAX_RANGES 10
#define FAKE_MAX_CHANNELS 32
#define FAKE_MAX_EXPECT 8

typedef struct {
    int type;               /* COMEDI_SUBD_* */
    unsigned n_channels;
    lsampl_t maxdata;
    int flags;              /* SDF_*: readable/writable, arefs, SDF_SOFT_CALIBRATED */
    unsigned n_ranges;
    comedi_range range[FAKE_MAX_RANGES];
    double gain_error;      /* converter error: actual = ideal * (1 + gain_error) + offset_v */
    double offset_v;
} fake_subdev_t;

typedef struct {
    const char *name;
    unsigned n_subdevs;
    fake_subdev_t sub[FAKE_MAX_SUBDEVS];
} fake_board_t;

/* NI PCI-6221 (ni_pcimio, M series): 0 AI 16 ch 16 bit, +-10/5/1/0.2 V,
 * soft-calibrated, ground/common/diff/other; 1 AO 2 ch 16 bit, +-10 V,
 * soft-calibrated, ground; 2 DIO. */
fake_board_t fake_board_pci6221(void);
/* Advantech PCI-1716 (adv_pci1710): 0 AI 16 ch 16 bit, ranges +-5, +-2.5,
 * +-1.25, +-0.625, +-10, 0..10, 0..5, 0..2.5, 0..1.25 V, ground/diff; 1 AO
 * 2 ch 16 bit, 0..5 and 0..10 V, ground; 2 DI; 3 DO. Calibrated in hardware. */
fake_board_t fake_board_pci1716(void);

/** Forgets everything: no device, no calibration, no stage, no expectations,
 *  counters and the violation cleared. */
void fake_comedi_reset(void);
/** The board answers comedi_open(path). */
void fake_comedi_set_board(const char *path, const fake_board_t *b);
/** comedi_get_default_calibration_path() returns path and a calibration file
 *  exists there (NULL: none); the file holds exact corrections of the board's
 *  converter errors for every channel and range of the soft-calibrated
 *  subdevices, except subdevice omit_subdev (-1: none). */
void fake_comedi_set_calibration(const char *path, int omit_subdev);
/** Each input/output instruction must use one of these (up to FAKE_MAX_EXPECT). */
void fake_comedi_expect_io(unsigned subdev, unsigned chan, unsigned range, unsigned aref);

typedef struct {
    unsigned ao_subdev, ao_chan;      /* drives stage axis i's DAC */
    unsigned ai_subdev, ai_chan;      /* reads stage axis i's sensor */
    double sensor_offset_um;          /* sensor electronics: volts = (um - offset) / um_per_v */
    double sensor_um_per_v;
} fake_wire_t;

/** Wires a stage (initialized by the test) to the board; n_axes wires. */
void fake_comedi_attach_stage(stage_t *s, const fake_wire_t *w, int n_axes);
/** The stage axis' DAC code of the last sample (-1 before the first). */
int32_t fake_comedi_stage_dac(int axis);

/** A voltage at an analog input (the stage's wired inputs overwrite theirs). */
void fake_comedi_set_input_volts(unsigned subdev, unsigned chan, double volts);
/** The voltage an analog output produces (its last sample through the converter error). */
double fake_comedi_output_volts(unsigned subdev, unsigned chan);
/** The last raw sample written to an output (0 before any). */
lsampl_t fake_comedi_output_raw(unsigned subdev, unsigned chan);
/** The chanspec of the last instruction on a channel (CR_PACK), ~0u if none. */
unsigned fake_comedi_last_chanspec(unsigned subdev, unsigned chan);

/** Make comedi_do_insnlist() fail (-1, EIO) from its n-th next call on
 *  (1 = the next one) for count calls; comedi_data_write() fails too while
 *  write_fails is set. */
void fake_comedi_fail_insnlist(unsigned long n, unsigned long count, int write_fails);

typedef struct {
    unsigned long opens, closes, insnlists, insns, data_reads, data_writes, steps;
    unsigned long softcal_lookups, hardcal_lookups, calibrations_parsed, calibrations_freed;
} fake_comedi_stats_t;

const fake_comedi_stats_t *fake_comedi_stats(void);
/** The first broken rule, or NULL. */
const char *fake_comedi_violation(void);

#endif /* FAKE_COMEDI_H */
