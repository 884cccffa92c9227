#define _POSIX_C_SOURCE 200809L
#include "flash_file.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static int in_range(const piezo_flash_file_t *f, uint32_t addr, uint32_t len)
{
    return addr <= f->size && len <= f->size - addr;
}

static int ff_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    piezo_flash_file_t *f = ctx;
    if (!in_range(f, addr, len)) {
        return -1;
    }
    return pread(f->fd, buf, len, (off_t)addr) == (ssize_t)len ? 0 : -1;
}

static int ff_program(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    piezo_flash_file_t *f = ctx;
    uint8_t cur[256];
    if (!in_range(f, addr, len)) {
        return -1;
    }
    for (uint32_t done = 0; done < len;) {
        uint32_t n = len - done < sizeof cur ? len - done : (uint32_t)sizeof cur;
        if (pread(f->fd, cur, n, (off_t)(addr + done)) != (ssize_t)n) {
            return -1;
        }
        for (uint32_t i = 0; i < n; i++) {
            cur[i] &= buf[done + i]; /* NOR: bits only go from 1 to 0 */
        }
        if (pwrite(f->fd, cur, n, (off_t)(addr + done)) != (ssize_t)n) {
            return -1;
        }
        done += n;
    }
    return fsync(f->fd) == 0 ? 0 : -1;
}

static int ff_erase(void *ctx, uint32_t addr, uint32_t len)
{
    piezo_flash_file_t *f = ctx;
    uint8_t ones[256];
    if (!in_range(f, addr, len)) {
        return -1;
    }
    memset(ones, 0xFF, sizeof ones);
    for (uint32_t done = 0; done < len;) {
        uint32_t n = len - done < sizeof ones ? len - done : (uint32_t)sizeof ones;
        if (pwrite(f->fd, ones, n, (off_t)(addr + done)) != (ssize_t)n) {
            return -1;
        }
        done += n;
    }
    return fsync(f->fd) == 0 ? 0 : -1;
}

static uint32_t le32(const uint8_t *b)
{
    return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}

/* What a slot record's first word says: 1 erased, 2 committed (the store's magic), 0 neither. */
static int record_kind(const uint8_t *rec, uint32_t magic)
{
    uint32_t w = le32(rec);
    return w == 0xFFFFFFFFu ? 1 : w == magic ? 2 : 0;
}

static int refuse(piezo_flash_file_t *f, const char *fmt, unsigned long long a, unsigned long long b,
                  const uint8_t *head, size_t nhead)
{
    char hex[3 * 8 + 1] = "";
    for (size_t i = 0; i < nhead && i < 8; i++) {
        snprintf(hex + 3 * i, sizeof hex - 3 * i, "%02x ", head[i]);
    }
    int n = snprintf(f->why, sizeof f->why, fmt, a, b);
    if (nhead > 0 && n > 0 && (size_t)n < sizeof f->why) {
        snprintf(f->why + n, sizeof f->why - (size_t)n, "; it begins %s", hex);
    }
    close(f->fd);
    f->fd = -1;
    errno = EINVAL;
    return -1;
}

int piezo_flash_file_open(piezo_flash_file_t *f, const char *path, uint32_t size)
{
    return piezo_flash_file_open_magic(f, path, size, PIEZO_STORE_MAGIC);
}

int piezo_flash_file_open_magic(piezo_flash_file_t *f, const char *path, uint32_t size, uint32_t magic)
{
    struct stat st;
    uint32_t slot = size / 2u;
    uint8_t rec[2][PIEZO_STORE_RECORD_BYTES];
    f->why[0] = '\0';
    f->size = size;
    f->fd = open(path, O_RDWR | O_CREAT, 0644);
    if (f->fd < 0) {
        return -1;
    }
    if (fstat(f->fd, &st) != 0) {
        int e = errno;
        close(f->fd);
        f->fd = -1;
        errno = e;
        return -1;
    }
    if (!S_ISREG(st.st_mode)) {
        return refuse(f, "not a regular file (mode %llo)%.0llu", (unsigned long long)(st.st_mode & 0170000u), 0,
                      NULL, 0);
    }
    if (st.st_size == 0) {
        /* new (or empty): a fresh, erased part */
        if (ff_erase(f, 0, size) != 0) {
            int e = errno;
            close(f->fd);
            f->fd = -1;
            errno = e;
            return -1;
        }
        return 0;
    }
    /* an existing file: read what is there, change nothing unless it is a flash image of this layout */
    uint8_t head[8];
    ssize_t got = pread(f->fd, head, sizeof head, 0);
    size_t nhead = got > 0 ? (size_t)got : 0u;
    int k0 = -1, k1 = -1;
    if ((uint64_t)st.st_size >= PIEZO_STORE_RECORD_BYTES &&
        pread(f->fd, rec[0], sizeof rec[0], 0) == (ssize_t)sizeof rec[0]) {
        k0 = record_kind(rec[0], magic);
    }
    if ((uint64_t)st.st_size >= (uint64_t)slot + PIEZO_STORE_RECORD_BYTES &&
        pread(f->fd, rec[1], sizeof rec[1], (off_t)slot) == (ssize_t)sizeof rec[1]) {
        k1 = record_kind(rec[1], magic);
    }
    if ((uint64_t)st.st_size == size) {
        if (k0 > 0 && k1 > 0) {
            return 0;
        }
        return refuse(f, "not a flash image: %llu bytes as expected, but slot records hold no store magic "
                         "(slot A %llu); file left untouched",
                      (unsigned long long)st.st_size, (unsigned long long)(k0 > 0), head, nhead);
    }
    if ((uint64_t)st.st_size < size && k0 > 0) {
        return refuse(f, "truncated flash image: %llu of %llu bytes (a table in it would be lost); "
                         "file left untouched, restore it or remove it to start erased",
                      (unsigned long long)st.st_size, (unsigned long long)size, head, nhead);
    }
    if ((uint64_t)st.st_size > size && k0 > 0) {
        return refuse(f, "a flash image of another layout: %llu bytes, this build uses %llu; file left untouched",
                      (unsigned long long)st.st_size, (unsigned long long)size, head, nhead);
    }
    return refuse(f, "not a flash image: %llu bytes (a flash file is %llu) with no store record; "
                     "file left untouched",
                  (unsigned long long)st.st_size, (unsigned long long)size, head, nhead);
}

void piezo_flash_file_close(piezo_flash_file_t *f)
{
    if (f->fd >= 0) {
        close(f->fd);
        f->fd = -1;
    }
}

piezo_storage_t piezo_flash_file_storage(piezo_flash_file_t *f, uint32_t slot_bytes)
{
    piezo_storage_t s = {ff_read, ff_program, ff_erase, f, slot_bytes};
    return s;
}
