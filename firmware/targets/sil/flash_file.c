#define _POSIX_C_SOURCE 200809L
#include "flash_file.h"

#include <errno.h>
#include <fcntl.h>
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

int piezo_flash_file_open(piezo_flash_file_t *f, const char *path, uint32_t size)
{
    struct stat st;
    f->fd = open(path, O_RDWR | O_CREAT, 0644);
    f->size = size;
    if (f->fd < 0) {
        return -1;
    }
    if (fstat(f->fd, &st) != 0) {
        close(f->fd);
        return -1;
    }
    if ((uint64_t)st.st_size != size) {
        /* new (or of another layout): a fresh, erased part */
        if (ftruncate(f->fd, 0) != 0 || ff_erase(f, 0, size) != 0) {
            int e = errno;
            close(f->fd);
            errno = e;
            return -1;
        }
    }
    return 0;
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
