#include "param_store.h"

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

/* CRC-32 over the header's seq and len (bytes 4..11) and the payload. */
static uint32_t record_crc(const uint8_t *slot, uint32_t len)
{
    uint32_t c = piezo_crc32(0u, slot + 4, 8u);
    return piezo_crc32(c, slot + PIEZO_PSTORE_HEADER_BYTES, len);
}

static int erased(const uint8_t *b, uint32_t n)
{
    for (uint32_t i = 0; i < n; i++) {
        if (b[i] != 0xFFu) {
            return 0;
        }
    }
    return 1;
}

static void scan(piezo_pstore_t *ps, int i)
{
    const piezo_storage_t *io = ps->io;
    uint8_t slot[PIEZO_PARAMS_SLOT_BYTES];
    piezo_pslot_t *s = &ps->slot[i];
    s->valid = 0u;
    s->seq = 0u;
    s->len = 0u;
    if (io->read(io->ctx, (uint32_t)i * io->slot_bytes, slot, sizeof slot) != 0) {
        s->reason = PIEZO_PARAMS_REASON_STORAGE_FAILED;
        return;
    }
    if (piezo_le32(slot) != PIEZO_PARAMS_MAGIC) {
        /* erased (never saved, or a save cut before its header) or something else */
        s->reason = erased(slot, PIEZO_PSTORE_HEADER_BYTES) ? PIEZO_PARAMS_REASON_NONE_STORED
                                                             : PIEZO_PARAMS_REASON_BAD_MAGIC;
        return;
    }
    s->seq = piezo_le32(slot + 4);
    s->len = piezo_le32(slot + 8);
    if (s->len == 0u || s->len > PIEZO_PSTORE_MAX_PAYLOAD) {
        s->reason = PIEZO_PARAMS_REASON_BAD_LENGTH;
        return;
    }
    if (record_crc(slot, s->len) != piezo_le32(slot + 12)) {
        s->reason = PIEZO_PARAMS_REASON_BAD_CRC;
        return;
    }
    s->reason = PIEZO_PARAMS_REASON_OK;
    s->valid = 1u;
}

static void choose(piezo_pstore_t *ps)
{
    ps->active = -1;
    for (int8_t i = 0; i < 2; i++) {
        if (ps->slot[i].valid && (ps->active < 0 || ps->slot[i].seq > ps->slot[ps->active].seq)) {
            ps->active = i;
        }
    }
}

int piezo_pstore_open(piezo_pstore_t *ps, const piezo_storage_t *io)
{
    if (ps == NULL || io == NULL || io->slot_bytes < PIEZO_PARAMS_SLOT_BYTES) {
        return PIEZO_EINVAL;
    }
    ps->io = io;
    scan(ps, 0);
    scan(ps, 1);
    choose(ps);
    return PIEZO_OK;
}

uint32_t piezo_pstore_load(const piezo_pstore_t *ps, uint8_t *buf, uint32_t cap)
{
    int i = ps->active;
    if (i < 0 || ps->slot[i].len > cap ||
        ps->io->read(ps->io->ctx, (uint32_t)i * ps->io->slot_bytes + PIEZO_PSTORE_HEADER_BYTES, buf,
                     ps->slot[i].len) != 0) {
        return 0u;
    }
    return ps->slot[i].len;
}

uint16_t piezo_pstore_ignored(const piezo_pstore_t *ps)
{
    for (int i = 0; i < 2; i++) {
        uint16_t r = ps->slot[i].reason;
        if (r != PIEZO_PARAMS_REASON_OK && r != PIEZO_PARAMS_REASON_NONE_STORED) {
            return r;
        }
    }
    return PIEZO_PARAMS_REASON_OK;
}

uint32_t piezo_pstore_seq(const piezo_pstore_t *ps)
{
    return ps->active >= 0 ? ps->slot[ps->active].seq : 0u;
}

uint16_t piezo_pstore_save(piezo_pstore_t *ps, const uint8_t *payload, uint32_t len)
{
    const piezo_storage_t *io = ps->io;
    uint8_t slot[PIEZO_PARAMS_SLOT_BYTES];
    int target = ps->active < 0 ? 0 : 1 - ps->active;
    uint32_t seq = ps->active < 0 ? 1u : ps->slot[ps->active].seq + 1u;
    uint32_t base = (uint32_t)target * io->slot_bytes;
    if (payload == NULL || len == 0u || len > PIEZO_PSTORE_MAX_PAYLOAD) {
        return PIEZO_PARAMS_REASON_BAD_LENGTH;
    }
    put32(slot, PIEZO_PARAMS_MAGIC);
    put32(slot + 4, seq);
    put32(slot + 8, len);
    for (uint32_t k = 0; k < len; k++) {
        slot[PIEZO_PSTORE_HEADER_BYTES + k] = payload[k];
    }
    put32(slot + 12, record_crc(slot, len));
    ps->slot[target].valid = 0u;
    /* the inactive slot only; its header last (the commit); then read it back */
    if (io->erase(io->ctx, base, io->slot_bytes) != 0 ||
        io->program(io->ctx, base + PIEZO_PSTORE_HEADER_BYTES, slot + PIEZO_PSTORE_HEADER_BYTES, len) != 0 ||
        io->program(io->ctx, base, slot, PIEZO_PSTORE_HEADER_BYTES) != 0) {
        scan(ps, target);
        choose(ps);
        return PIEZO_PARAMS_REASON_STORAGE_FAILED;
    }
    scan(ps, target);
    if (!ps->slot[target].valid || ps->slot[target].seq != seq) {
        choose(ps);
        return PIEZO_PARAMS_REASON_STORAGE_FAILED;
    }
    ps->active = (int8_t)target;
    return PIEZO_PARAMS_REASON_OK;
}
