/*
 * param_store.h - the controller parameters in two flash slots (A/B), each a
 * small record with a CRC-32, saved the way the table store saves a table.
 *
 * A slot (the target's io->slot_bytes: PIEZO_PARAMS_SLOT_BYTES on the
 * flash-file targets and the board, at least PIEZO_PARAMS_MIN_SLOT_BYTES;
 * common/interface.toml [params]) holds a 16-byte header and the payload
 * right after it, little-endian:
 *
 *   offset 0  magic   PIEZO_PARAMS_MAGIC ("ZPPR")
 *          4  seq     sequence number, 1 for the first save, +1 every save
 *          8  len     payload bytes
 *         12  crc     CRC-32 (IEEE, zlib's) over bytes 4..11 and the payload
 *         16  payload len bytes (the caller's: regmap.c puts the interface
 *             CRC, the word count and the configuration registers' words)
 *
 * Saving erases the slot that is not active, programs the payload, and
 * programs the header LAST: the header is the commit. A power cut at any
 * point leaves the active slot untouched, and the half-written slot fails
 * its magic or CRC at the next boot. Boot takes the valid slot with the
 * highest sequence number; a slot that is neither erased nor valid is
 * ignored, and the reason (bad_magic, bad_length, bad_crc) is kept so the
 * controller can report it.
 *
 * Storage is the table store's piezo_storage_t (store.h): NOR semantics,
 * two slots of io->slot_bytes >= PIEZO_PARAMS_MIN_SLOT_BYTES. The payload
 * is streamed in 64-byte chunks (scan, save and read): no slot-sized buffer.
 */
#ifndef PIEZO_PARAM_STORE_H
#define PIEZO_PARAM_STORE_H

#include <stdint.h>

#include "piezo_interface.h"
#include "store.h"

#define PIEZO_PSTORE_HEADER_BYTES 16u

/** Produces payload bytes [off, off + n) of a record being saved; called in
 *  order, once per chunk. Returns 0, or nonzero to abandon the save. */
typedef int (*piezo_pstore_fill_fn)(void *ctx, uint32_t off, uint8_t *buf, uint32_t n);

typedef struct {
    uint8_t valid;
    uint16_t reason; /* PIEZO_PARAMS_REASON_*: ok (valid), none_stored (erased) or why it is not valid */
    uint32_t seq;
    uint32_t len;
} piezo_pslot_t;

typedef struct {
    const piezo_storage_t *io;
    uint32_t magic; /* PIEZO_PARAMS_MAGIC */
    piezo_pslot_t slot[2];
    int8_t active; /* slot index, -1 = none valid */
} piezo_pstore_t;

/** Scan both slots (boot): each record's header, then its payload for the
 *  CRC. Returns a piezo_err code (EINVAL: bad arguments or slots smaller
 *  than PIEZO_PARAMS_MIN_SLOT_BYTES). */
int piezo_pstore_open(piezo_pstore_t *ps, const piezo_storage_t *io);

/** Copy the active record's payload to buf (cap bytes). Returns its length,
 *  0 when none is valid or it does not fit. */
uint32_t piezo_pstore_load(const piezo_pstore_t *ps, uint8_t *buf, uint32_t cap);

/** Payload bytes of the active record, 0 = none. */
uint32_t piezo_pstore_len(const piezo_pstore_t *ps);

/** The largest payload a slot of this storage holds (slot_bytes - 16). */
uint32_t piezo_pstore_capacity(const piezo_pstore_t *ps);

/** Read payload bytes [off, off + len) of the active record. Returns
 *  PIEZO_OK, EINVAL (none active, or past its end) or EIO. */
int piezo_pstore_read(const piezo_pstore_t *ps, uint32_t off, uint8_t *buf, uint32_t len);

/** The worst reason among the slots at open: why a stored record was
 *  ignored (PIEZO_PARAMS_REASON_OK when none was). */
uint16_t piezo_pstore_ignored(const piezo_pstore_t *ps);

/** Save a payload of len bytes (1..piezo_pstore_capacity) into the
 *  inactive slot and make it active. Returns PIEZO_PARAMS_REASON_OK,
 *  BAD_LENGTH, or STORAGE_FAILED (the active record is then unchanged). */
uint16_t piezo_pstore_save(piezo_pstore_t *ps, const uint8_t *payload, uint32_t len);

/** The same with the payload produced chunk by chunk by fill (a fill that
 *  fails abandons the save: STORAGE_FAILED, the active record unchanged). */
uint16_t piezo_pstore_save_stream(piezo_pstore_t *ps, uint32_t len, piezo_pstore_fill_fn fill, void *ctx);

/** Sequence number of the active record, 0 = none. */
uint32_t piezo_pstore_seq(const piezo_pstore_t *ps);

#endif /* PIEZO_PARAM_STORE_H */
