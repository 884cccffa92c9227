/*
 * regmap.h - the Modbus register map (common/interface.toml) of one axis'
 * controller, behind the protocol layer's register-access callbacks.
 *
 * Reads return live values (status is read between ticks, so a 32-bit value
 * is never torn). A write request is checked whole before anything changes:
 * every register must exist and be writable, configuration registers need the
 * unlock key and a disarmed unit, every new value must be legal; then the
 * values are stored and their actions run in address order. A refused write
 * changes nothing and answers ILLEGAL DATA ADDRESS (no such register, or
 * read-only) or ILLEGAL DATA VALUE (value, lock or state).
 *
 * Sessions (docs/protocol.md): the transport says whose request it is
 * (piezo_mb_regs_t.session); the unlock, configuration writes and the staged
 * upload are per session. unlock_key takes the provisioned key in one
 * request: a wrong key is ILLEGAL DATA VALUE, an unlock during the backoff or
 * lockout SERVER DEVICE BUSY (both counted in bad_unlocks).
 *
 * Parameters: params_command save writes the configuration registers to
 * the parameter store (param_store.h), load reads them back, defaults
 * restores the target's own; the reason in params_result.
 *
 * Table upload: table_offset and table_window are adjacent, so one FC 16
 * request writes a chunk at its offset, and one FC 23 request reads a chunk
 * back. Recorder readout: rec_read_index and rec_window likewise, with FC 23.
 */
#ifndef PIEZO_REGMAP_H
#define PIEZO_REGMAP_H

#include <stdint.h>

#include "controller.h"
#include "modbus_pdu.h"
#include "param_store.h"

typedef struct {
    piezo_ctl_t *ctl;
    uint16_t axis;
    uint16_t n_axes;
    uint32_t tick_hz;
    uint32_t fw_version;
    int32_t drive_min_mv, drive_max_mv;       /* physical value of q15 -32768 / +32768 */
    int32_t position_min_nm, position_max_nm;
    uint32_t tick_time_ns;                    /* the target keeps these two current */
    uint32_t tick_time_max_ns;
    uint32_t table_offset;
    uint32_t rec_read_index;
    uint16_t wave_ff_n;         /* learned feedforward: entries of the next commit */
    uint32_t wave_ff_freq_word; /* and its periods per tick * 2^32 */
    piezo_rec_cfg_t rec_cfg;                  /* applied when the recorder is armed */
    uint8_t session;                          /* whose request runs (PIEZO_MB_SESSION_*) */
    /* controller parameters = the configuration registers (docs/operate.md) */
    piezo_ctl_cfg_t params_defaults;          /* the target's built-in ones (the cfg at init) */
    piezo_pstore_t pstore;
    uint8_t have_pstore;
    uint8_t params_source;                    /* enum piezo_enum_params_source */
    uint16_t params_result;                   /* PIEZO_PARAMS_REASON_* of the last command or boot */
    uint16_t params_ignored;                  /* why a stored record was ignored at boot */
    uint16_t params_wave;                     /* PIEZO_PARAMS_WAVE_*: the active record's wave */
} piezo_regmap_t;

/** Bind a map to a controller; identity fields are set by the caller after. */
void piezo_regmap_init(piezo_regmap_t *m, piezo_ctl_t *ctl);

/** Provision the controller: the stage and axis of the identity fields
 *  (set them first) and the unlock key (>= 32 bits, 0 = unlock disabled).
 *  Call before piezo_ctl_attach_store(), so a stored table is checked too. */
void piezo_regmap_provision(piezo_regmap_t *m, uint32_t key);

/** Attach the parameter storage (two slots of PIEZO_PARAMS_MIN_SLOT_BYTES or
 *  more; PIEZO_PARAMS_SLOT_BYTES hold the wave too) and load the active
 *  record, at boot, after provisioning: the parameters, and the wave and its
 *  learned feedforward if the record holds them (not started). A record
 *  is used only if its CRC holds, it was written by this interface
 *  definition (its interface CRC) and every value passes the checks a
 *  register write makes; else the defaults run and the reason is reported
 *  (params_result; a corrupt slot beside a good one: params_ignored).
 *  Returns the reason (PIEZO_PARAMS_REASON_OK: parameters from flash). */
uint16_t piezo_regmap_attach_params(piezo_regmap_t *m, const piezo_storage_t *io);

/** The callbacks for piezo_mb_pdu_process() and the transports. */
piezo_mb_regs_t piezo_regmap_regs(piezo_regmap_t *m);

#endif /* PIEZO_REGMAP_H */
