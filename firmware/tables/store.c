#include "store.h"

#include <stddef.h>

#include "crc32.h"
#include "piezo_err.h"
#include "table_image.h"

static void put32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
    p[2] = (uint8_t)(v >> 16);
    p[3] = (uint8_t)(v >> 24);
}

/* A slot is valid when its record is complete and the image it names is a
 * table this firmware accepts. */
static void scan_slot(piezo_store_t *st, int i, uint8_t *scratch)
{
    const piezo_storage_t *io = st->io;
    uint32_t base = (uint32_t)i * io->slot_bytes;
    uint8_t rec[PIEZO_STORE_RECORD_BYTES];
    piezo_table_info_t info;
    piezo_slot_info_t *s = &st->slot[i];
    s->valid = 0u;
    if (io->read(io->ctx, base, rec, sizeof rec) != 0 || piezo_le32(rec) != PIEZO_STORE_MAGIC) {
        return;
    }
    s->seq = piezo_le32(rec + 4);
    s->len = piezo_le32(rec + 8);
    s->crc = piezo_le32(rec + 12);
    if (s->len < 4u || s->len > PIEZO_TABLE_MAX_BYTES ||
        io->read(io->ctx, base + PIEZO_STORE_RECORD_BYTES, scratch, s->len) != 0) {
        return;
    }
    if (piezo_table_check(scratch, s->len, &info) != PIEZO_TABLE_REASON_OK || info.crc != s->crc) {
        return;
    }
    s->valid = 1u;
}

static void choose(piezo_store_t *st)
{
    st->active = -1;
    st->previous = -1;
    for (int8_t i = 0; i < 2; i++) {
        if (st->slot[i].valid && (st->active < 0 || st->slot[i].seq > st->slot[st->active].seq)) {
            st->active = i;
        }
    }
    if (st->active >= 0 && st->slot[1 - st->active].valid) {
        st->previous = (int8_t)(1 - st->active);
    }
}

int piezo_store_open(piezo_store_t *st, const piezo_storage_t *io, uint8_t *scratch)
{
    if (st == NULL || io == NULL || scratch == NULL ||
        io->slot_bytes < PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES) {
        return PIEZO_EINVAL;
    }
    st->io = io;
    scan_slot(st, 0, scratch);
    scan_slot(st, 1, scratch);
    choose(st);
    return PIEZO_OK;
}

uint32_t piezo_store_load(const piezo_store_t *st, int which, uint8_t *buf, uint32_t cap)
{
    int i = which == 0 ? st->active : st->previous;
    if (i < 0 || st->slot[i].len > cap ||
        st->io->read(st->io->ctx, (uint32_t)i * st->io->slot_bytes + PIEZO_STORE_RECORD_BYTES, buf,
                     st->slot[i].len) != 0) {
        return 0u;
    }
    return st->slot[i].len;
}

/* Erase, program the image, program the record last. */
static uint16_t write_slot(piezo_store_t *st, int i, const uint8_t *img, uint32_t len, uint32_t seq)
{
    const piezo_storage_t *io = st->io;
    uint32_t base = (uint32_t)i * io->slot_bytes;
    uint8_t rec[PIEZO_STORE_RECORD_BYTES];
    put32(rec, PIEZO_STORE_MAGIC);
    put32(rec + 4, seq);
    put32(rec + 8, len);
    put32(rec + 12, piezo_le32(img + len - 4u));
    st->slot[i].valid = 0u;
    if (io->erase(io->ctx, base, io->slot_bytes) != 0 ||
        io->program(io->ctx, base + PIEZO_STORE_RECORD_BYTES, img, len) != 0 ||
        io->program(io->ctx, base, rec, sizeof rec) != 0) {
        choose(st);
        return PIEZO_TABLE_REASON_STORAGE_FAILED;
    }
    st->slot[i].valid = 1u;
    st->slot[i].seq = seq;
    st->slot[i].len = len;
    st->slot[i].crc = piezo_le32(img + len - 4u);
    choose(st);
    return PIEZO_TABLE_REASON_OK;
}

uint16_t piezo_store_save(piezo_store_t *st, const uint8_t *img, uint32_t len)
{
    int target = st->active < 0 ? 0 : 1 - st->active;
    uint32_t seq = st->active < 0 ? 1u : st->slot[st->active].seq + 1u;
    if (img == NULL || len < 4u || len > PIEZO_TABLE_MAX_BYTES) {
        return PIEZO_TABLE_REASON_BAD_LENGTH;
    }
    return write_slot(st, target, img, len, seq);
}

uint16_t piezo_store_rollback(piezo_store_t *st, uint8_t *scratch)
{
    uint32_t len;
    if (st->previous < 0) {
        return PIEZO_TABLE_REASON_NO_PREVIOUS;
    }
    len = piezo_store_load(st, 1, scratch, PIEZO_TABLE_MAX_BYTES);
    if (len == 0u) {
        return PIEZO_TABLE_REASON_STORAGE_FAILED;
    }
    /* the active slot's place: the previous slot keeps its copy until then */
    return write_slot(st, st->active, scratch, len, st->slot[st->active].seq + 1u);
}
