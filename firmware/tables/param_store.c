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

/* Payload bytes moved per storage call: the record is streamed, so no
 * slot-sized buffer lives on the stack (a slot holds up to 4 KiB). */
#define CHUNK_BYTES 64u

static uint32_t capacity(const piezo_storage_t *io)
{
    return io->slot_bytes - PIEZO_PSTORE_HEADER_BYTES;
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
    uint8_t hdr[PIEZO_PSTORE_HEADER_BYTES], chunk[CHUNK_BYTES];
    uint32_t base = (uint32_t)i * io->slot_bytes, crc;
    piezo_pslot_t *s = &ps->slot[i];
    s->valid = 0u;
    s->seq = 0u;
    s->len = 0u;
    if (io->read(io->ctx, base, hdr, sizeof hdr) != 0) {
        s->reason = PIEZO_PARAMS_REASON_STORAGE_FAILED;
        return;
    }
    if (piezo_le32(hdr) != ps->magic) {
        /* erased (never saved, or a save cut before its header) or something else */
        s->reason = erased(hdr, sizeof hdr) ? PIEZO_PARAMS_REASON_NONE_STORED : PIEZO_PARAMS_REASON_BAD_MAGIC;
        return;
    }
    s->seq = piezo_le32(hdr + 4);
    s->len = piezo_le32(hdr + 8);
    if (s->len == 0u || s->len > capacity(io)) {
        s->reason = PIEZO_PARAMS_REASON_BAD_LENGTH;
        return;
    }
    /* CRC-32 over the header's seq and len (bytes 4..11) and the payload */
    crc = piezo_crc32(0u, hdr + 4, 8u);
    for (uint32_t off = 0; off < s->len; off += CHUNK_BYTES) {
        uint32_t n = s->len - off < CHUNK_BYTES ? s->len - off : CHUNK_BYTES;
        if (io->read(io->ctx, base + PIEZO_PSTORE_HEADER_BYTES + off, chunk, n) != 0) {
            s->reason = PIEZO_PARAMS_REASON_STORAGE_FAILED;
            return;
        }
        crc = piezo_crc32(crc, chunk, n);
    }
    if (crc != piezo_le32(hdr + 12)) {
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
    if (ps == NULL || io == NULL || io->slot_bytes < PIEZO_PARAMS_MIN_SLOT_BYTES) {
        return PIEZO_EINVAL;
    }
    ps->io = io;
    ps->magic = PIEZO_PARAMS_MAGIC;
    scan(ps, 0);
    scan(ps, 1);
    choose(ps);
    return PIEZO_OK;
}

uint32_t piezo_pstore_len(const piezo_pstore_t *ps)
{
    return ps->active >= 0 ? ps->slot[ps->active].len : 0u;
}

uint32_t piezo_pstore_capacity(const piezo_pstore_t *ps)
{
    return capacity(ps->io);
}

int piezo_pstore_read(const piezo_pstore_t *ps, uint32_t off, uint8_t *buf, uint32_t len)
{
    int i = ps->active;
    if (i < 0 || off > ps->slot[i].len || len > ps->slot[i].len - off) {
        return PIEZO_EINVAL;
    }
    if (ps->io->read(ps->io->ctx, (uint32_t)i * ps->io->slot_bytes + PIEZO_PSTORE_HEADER_BYTES + off, buf, len) !=
        0) {
        return PIEZO_EIO;
    }
    return PIEZO_OK;
}

uint32_t piezo_pstore_load(const piezo_pstore_t *ps, uint8_t *buf, uint32_t cap)
{
    uint32_t len = piezo_pstore_len(ps);
    if (len == 0u || len > cap || piezo_pstore_read(ps, 0u, buf, len) != PIEZO_OK) {
        return 0u;
    }
    return len;
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

uint16_t piezo_pstore_save_stream(piezo_pstore_t *ps, uint32_t len, piezo_pstore_fill_fn fill, void *ctx)
{
    const piezo_storage_t *io = ps->io;
    uint8_t hdr[PIEZO_PSTORE_HEADER_BYTES], chunk[CHUNK_BYTES];
    int target = ps->active < 0 ? 0 : 1 - ps->active;
    uint32_t seq = ps->active < 0 ? 1u : ps->slot[ps->active].seq + 1u;
    uint32_t base = (uint32_t)target * io->slot_bytes, crc;
    if (fill == NULL || len == 0u || len > capacity(io)) {
        return PIEZO_PARAMS_REASON_BAD_LENGTH;
    }
    put32(hdr, ps->magic);
    put32(hdr + 4, seq);
    put32(hdr + 8, len);
    crc = piezo_crc32(0u, hdr + 4, 8u);
    ps->slot[target].valid = 0u;
    /* the inactive slot only; the payload chunk by chunk, its header last
     * (the commit); then read it back */
    if (io->erase(io->ctx, base, io->slot_bytes) != 0) {
        goto failed;
    }
    for (uint32_t off = 0; off < len; off += CHUNK_BYTES) {
        uint32_t n = len - off < CHUNK_BYTES ? len - off : CHUNK_BYTES;
        if (fill(ctx, off, chunk, n) != 0) {
            goto failed;
        }
        crc = piezo_crc32(crc, chunk, n);
        if (io->program(io->ctx, base + PIEZO_PSTORE_HEADER_BYTES + off, chunk, n) != 0) {
            goto failed;
        }
    }
    put32(hdr + 12, crc);
    if (io->program(io->ctx, base, hdr, PIEZO_PSTORE_HEADER_BYTES) != 0) {
        goto failed;
    }
    scan(ps, target);
    if (!ps->slot[target].valid || ps->slot[target].seq != seq) {
        choose(ps);
        return PIEZO_PARAMS_REASON_STORAGE_FAILED;
    }
    ps->active = (int8_t)target;
    return PIEZO_PARAMS_REASON_OK;
failed:
    scan(ps, target);
    choose(ps);
    return PIEZO_PARAMS_REASON_STORAGE_FAILED;
}

static int fill_copy(void *ctx, uint32_t off, uint8_t *buf, uint32_t n)
{
    const uint8_t *payload = ctx;
    for (uint32_t k = 0; k < n; k++) {
        buf[k] = payload[off + k];
    }
    return 0;
}

uint16_t piezo_pstore_save(piezo_pstore_t *ps, const uint8_t *payload, uint32_t len)
{
    if (payload == NULL) {
        return PIEZO_PARAMS_REASON_BAD_LENGTH;
    }
    return piezo_pstore_save_stream(ps, len, fill_copy, (void *)(uintptr_t)payload);
}
