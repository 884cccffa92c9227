#include "nor_flash.h"

#include <string.h>

void nor_flash_init(nor_flash_t *f, uint8_t *mem, uint32_t size)
{
    f->mem = mem;
    f->size = size;
    f->ops_left = -1;
    f->dead = 0;
    memset(mem, 0xFF, size);
}

/* Returns how many bytes of an operation of len bytes are carried out. */
static uint32_t power(nor_flash_t *f, uint32_t len)
{
    if (f->dead) {
        return 0;
    }
    if (f->ops_left == 0) {
        f->dead = 1;
        return len / 2u;
    }
    if (f->ops_left > 0) {
        f->ops_left--;
    }
    return len;
}

static int nor_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    nor_flash_t *f = ctx;
    if (addr > f->size || len > f->size - addr) {
        return -1;
    }
    memcpy(buf, f->mem + addr, len);
    return 0;
}

static int nor_program(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    nor_flash_t *f = ctx;
    uint32_t n;
    if (addr > f->size || len > f->size - addr) {
        return -1;
    }
    n = power(f, len);
    for (uint32_t i = 0; i < n; i++) {
        f->mem[addr + i] &= buf[i];
    }
    return n == len ? 0 : -1;
}

static int nor_erase(void *ctx, uint32_t addr, uint32_t len)
{
    nor_flash_t *f = ctx;
    uint32_t n;
    if (addr > f->size || len > f->size - addr) {
        return -1;
    }
    n = power(f, len);
    memset(f->mem + addr, 0xFF, n);
    return n == len ? 0 : -1;
}

piezo_storage_t nor_flash_storage(nor_flash_t *f, uint32_t slot_bytes)
{
    piezo_storage_t s = {nor_read, nor_program, nor_erase, f, slot_bytes};
    return s;
}
