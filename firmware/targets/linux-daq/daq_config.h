/*
 * daq_config.h - the configuration file of the Linux DAQ target
 * (docs/target-linux-daq.md): which comedi device, which analog output and
 * input channel drive and read each axis, the physical scale of the drive
 * and the sensor, and where the tables persist.
 *
 * The format is line-based "key = value"; '#' starts a comment (at the start
 * of a line or after a blank); "[axis N]" (N = 0, then 1) starts the keys of
 * one axis. Every error names the file and the line:
 *
 *     device = /dev/comedi0
 *     flash = /var/lib/piezoctl/stage.flash
 *     calibration = auto            # auto | none | PATH of a comedi_soft_calibrate file
 *     [axis 0]
 *     ao.subdevice = auto           # auto: the first analog output subdevice
 *     ao.channel = 0
 *     ao.range = 0                  # index into the subdevice's range table
 *     ao.aref = ground              # ground | common | diff | other
 *     ai.channel = 0
 *     ai.range = 0
 *     ai.aref = diff
 *     amplifier.gain = 15           # [V/V] drive volts per AO volt
 *     sensor.um_per_v = 2.4         # [um/V] position per volt of sensor output
 *
 * Units are in the key: _v volts, _um micrometres, _hz hertz.
 */
#ifndef PIEZO_DAQ_CONFIG_H
#define PIEZO_DAQ_CONFIG_H

#include <stddef.h>
#include <stdint.h>

#define PIEZO_DAQ_MAX_AXES 2
#define PIEZO_DAQ_PATH_MAX 512

enum piezo_daq_cal_mode {
    PIEZO_DAQ_CAL_AUTO = 0, /* soft-calibrated subdevices: comedi's default calibration file, if any */
    PIEZO_DAQ_CAL_NONE = 1, /* ideal conversion (comedi_to_phys / comedi_from_phys) */
    PIEZO_DAQ_CAL_FILE = 2  /* this comedi_soft_calibrate file; it must parse */
};

typedef struct {
    int subdevice;      /* -1: auto (the first subdevice of the type) */
    unsigned channel;
    unsigned range;     /* index into the channel's range table */
    unsigned aref;      /* AREF_GROUND, AREF_COMMON, AREF_DIFF, AREF_OTHER (comedi.h) */
} piezo_daq_chan_cfg_t;

typedef struct {
    piezo_daq_chan_cfg_t ao;        /* drive: analog output into the amplifier */
    piezo_daq_chan_cfg_t ai;        /* position sensor: analog input */
    double amp_gain;                /* [V/V] amplifier: drive = gain * AO volts + offset */
    double amp_offset_v;            /* [V] = 0 */
    double sensor_um_per_v;         /* [um/V] position = offset + um_per_v * AI volts */
    double sensor_offset_um;        /* [um] = 0 */
    double safe_v;                  /* [V] drive while disarmed, on exit, on an I/O error = 0 */
    double drive_min_v, drive_max_v; /* [V] output clamp, when given */
    int has_drive_min, has_drive_max;
} piezo_daq_axis_cfg_t;

typedef struct {
    char device[PIEZO_DAQ_PATH_MAX];          /* comedi device file, e.g. /dev/comedi0 */
    char flash[PIEZO_DAQ_PATH_MAX];           /* table storage file (axis 1: FILE.axis2) */
    int calibration;                          /* enum piezo_daq_cal_mode = AUTO */
    char calibration_path[PIEZO_DAQ_PATH_MAX];
    uint32_t tick_hz;                         /* [Hz] = 10000 */
    int priority;                             /* SCHED_FIFO priority, 0 = leave the scheduler = 80 */
    int n_axes;
    piezo_daq_axis_cfg_t axis[PIEZO_DAQ_MAX_AXES];
} piezo_daq_config_t;

/** Parses the configuration text; name is the file name used in messages.
 *  Returns 0, or -1 with "name:line: message" in errbuf. */
int piezo_daq_config_parse(const char *text, const char *name, piezo_daq_config_t *cfg,
                           char *errbuf, size_t errlen);

/** Reads and parses a configuration file. Returns 0, or -1 with the message
 *  ("path: cannot read: reason" or "path:line: message") in errbuf. */
int piezo_daq_config_load(const char *path, piezo_daq_config_t *cfg, char *errbuf, size_t errlen);

#endif /* PIEZO_DAQ_CONFIG_H */
