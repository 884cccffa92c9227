/*
 * store.h - persistent coefficient tables in two flash slots (A/B).
 *
 * Each slot holds a 16-byte record (magic, sequence number, image length,
 * image CRC-32) followed by the image. Saving erases the slot that does not
 * hold the active table, programs the image, and programs the record LAST: the
 * record is the commit. A power cut between any two storage operations leaves
 * at least the old active slot intact, so boot always finds a valid table (or
 * none, if none was ever saved) and never half of one.
 *
 * Boot picks the valid slot with the highest sequence number as active and the
 * other valid slot, if any, as previous (the rollback target). Rollback copies
 * the previous image into the active slot's place with a new sequence number,
 * the same commit-last order.
 *
 * Storage is behind three callbacks so targets bring their own flash: the SIL
 * build uses a file, tests an in-memory NOR emulation with injectable power cuts.
 * Programming may only clear bits (NOR semantics); erase sets a range to 0xFF.
 */
#ifndef PIEZO_STORE_H
#define PIEZO_STORE_H

#include <stdint.h>

#define PIEZO_STORE_RECORD_BYTES 16u
#define PIEZO_STORE_MAGIC 0x4C53505Au /* "ZPSL" */

typedef struct {
    int (*read)(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len);
    int (*program)(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len);
    int (*erase)(void *ctx, uint32_t addr, uint32_t len);
    void *ctx;
    uint32_t slot_bytes; /* >= PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES */
} piezo_storage_t;

typedef struct {
    uint8_t valid;
    uint32_t seq;
    uint32_t len;
    uint32_t crc;
} piezo_slot_info_t;

typedef struct {
    const piezo_storage_t *io;
    piezo_slot_info_t slot[2];
    int8_t active;   /* slot index, -1 = none */
    int8_t previous; /* slot index, -1 = none */
} piezo_store_t;

/** Scan both slots (boot). scratch must hold PIEZO_TABLE_MAX_BYTES. Returns a piezo_err code. */
int piezo_store_open(piezo_store_t *st, const piezo_storage_t *io, uint8_t *scratch);
/** Read the active (which = 0) or previous (which = 1) image; returns its length or 0. */
uint32_t piezo_store_load(const piezo_store_t *st, int which, uint8_t *buf, uint32_t cap);
/** Save a validated image as the new active table; the old active becomes previous.
 *  Returns PIEZO_TABLE_REASON_OK or PIEZO_TABLE_REASON_STORAGE_FAILED. */
uint16_t piezo_store_save(piezo_store_t *st, const uint8_t *img, uint32_t len);
/** Make the previous image active again (scratch as in open). */
uint16_t piezo_store_rollback(piezo_store_t *st, uint8_t *scratch);

#endif /* PIEZO_STORE_H */
