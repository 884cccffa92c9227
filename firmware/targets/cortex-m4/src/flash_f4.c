/* flash_f4.c - table storage in the STM32F405's flash (see flash_f4.h). */
#include "flash_f4.h"

#include <stddef.h>

static int wait_not_busy(void)
{
    for (uint32_t i = 0; i < PIEZO_FLASH_BSY_POLLS; i++) {
        if ((piezo_f4_flash_rd(PIEZO_FLASH_SR) & PIEZO_FLASH_SR_BSY) == 0u) {
            return 0;
        }
    }
    return -1;
}

/* RM0090 3.5.1: KEY1 then KEY2 into KEYR; a wrong sequence locks CR until
 * reset (and a bus error), so never write KEYR when CR is already unlocked. */
static int unlock(void)
{
    if ((piezo_f4_flash_rd(PIEZO_FLASH_CR) & PIEZO_FLASH_CR_LOCK) != 0u) {
        piezo_f4_flash_wr(PIEZO_FLASH_KEYR, PIEZO_FLASH_KEY1);
        piezo_f4_flash_wr(PIEZO_FLASH_KEYR, PIEZO_FLASH_KEY2);
    }
    return (piezo_f4_flash_rd(PIEZO_FLASH_CR) & PIEZO_FLASH_CR_LOCK) == 0u ? 0 : -1;
}

static void lock(void)
{
    piezo_f4_flash_wr(PIEZO_FLASH_CR, PIEZO_FLASH_CR_LOCK);
}

/* Errors of the last operation: cleared by writing 1 (rc_w1); -1 if any. */
static int take_errors(void)
{
    uint32_t sr = piezo_f4_flash_rd(PIEZO_FLASH_SR);
    piezo_f4_flash_wr(PIEZO_FLASH_SR, sr & (PIEZO_FLASH_SR_ERRORS | PIEZO_FLASH_SR_EOP));
    return (sr & PIEZO_FLASH_SR_ERRORS) != 0u ? -1 : 0;
}

/* Before an operation: not busy, no error left from an earlier one, unlocked. */
static int begin(void)
{
    if (wait_not_busy() != 0) {
        return -1;
    }
    (void)take_errors();
    return unlock();
}

int piezo_f4_flash_erase_sector(uint32_t sector)
{
    int rc;
    if (sector < PIEZO_FLASH_PARAMS_A_SECTOR || sector > PIEZO_FLASH_SLOT_A_SECTOR + 1u) {
        return -1; /* never the code's sectors (0-7) */
    }
    if (begin() != 0) {
        return -1;
    }
    /* RM0090 3.6.3: SER and SNB (with PSIZE), then STRT, then wait BSY */
    piezo_f4_flash_wr(PIEZO_FLASH_CR, PIEZO_FLASH_CR_PSIZE_X32 | PIEZO_FLASH_CR_SER |
                                          (sector << PIEZO_FLASH_CR_SNB_SHIFT));
    piezo_f4_flash_hold(1);
    piezo_f4_flash_wr(PIEZO_FLASH_CR, piezo_f4_flash_rd(PIEZO_FLASH_CR) | PIEZO_FLASH_CR_STRT);
    rc = wait_not_busy();
    piezo_f4_flash_hold(0);
    rc |= take_errors();
    lock();
    return rc != 0 ? -1 : 0;
}

int piezo_f4_flash_program(uint32_t addr, const uint8_t *data, uint32_t n)
{
    int rc = 0;
    /* sectors 8-11 are contiguous: the parameters' and the tables' slots */
    if ((addr & 3u) != 0u || addr < PIEZO_FLASH_PARAMS_A_ADDR ||
        addr + n > PIEZO_FLASH_SLOT_A_ADDR + 2u * PIEZO_FLASH_SLOT_BYTES || addr + n < addr) {
        return -1;
    }
    if (begin() != 0) {
        return -1;
    }
    /* RM0090 3.6.4: PSIZE x32 and PG, then one word per write, BSY after each */
    piezo_f4_flash_wr(PIEZO_FLASH_CR, PIEZO_FLASH_CR_PSIZE_X32 | PIEZO_FLASH_CR_PG);
    piezo_f4_flash_hold(1);
    for (uint32_t i = 0; i < n && rc == 0; i += 4u) {
        uint32_t w = 0u;
        for (uint32_t b = 0; b < 4u; b++) {
            uint32_t v = i + b < n ? data[i + b] : 0xFFu;
            w |= v << (8u * b);
        }
        piezo_f4_mem_wr32(addr + i, w);
        rc = wait_not_busy();
        if (rc == 0) {
            rc = take_errors();
        }
    }
    piezo_f4_flash_hold(0);
    piezo_f4_flash_wr(PIEZO_FLASH_CR, piezo_f4_flash_rd(PIEZO_FLASH_CR) & ~PIEZO_FLASH_CR_PG);
    lock();
    return rc;
}

/* store.h callbacks: addresses are offsets into two slots of one sector
 * each; ctx is the region (the tables' sectors 10/11 or the parameters' 8/9). */
typedef struct {
    uint32_t base;         /* address of slot A */
    uint32_t first_sector; /* slot A's sector; slot B is the next one */
} f4_region_t;

static f4_region_t tables_region = {PIEZO_FLASH_SLOT_A_ADDR, PIEZO_FLASH_SLOT_A_SECTOR};
static f4_region_t params_region = {PIEZO_FLASH_PARAMS_A_ADDR, PIEZO_FLASH_PARAMS_A_SECTOR};

static int st_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    const f4_region_t *r = ctx;
    if (addr + len > 2u * PIEZO_FLASH_SLOT_BYTES || addr + len < addr) {
        return -1;
    }
    for (uint32_t i = 0; i < len; i++) {
        buf[i] = piezo_f4_mem_rd8(r->base + addr + i);
    }
    return 0;
}

static int st_program(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    const f4_region_t *r = ctx;
    if ((addr & 3u) != 0u) {
        /* the stores program at record and image offsets, all multiples of 4;
         * an unaligned start would need a read-modify-write of a word */
        return -1;
    }
    if (addr + len > 2u * PIEZO_FLASH_SLOT_BYTES || addr + len < addr) {
        return -1;
    }
    return piezo_f4_flash_program(r->base + addr, buf, len);
}

static int st_erase(void *ctx, uint32_t addr, uint32_t len)
{
    const f4_region_t *r = ctx;
    if (len == 0u) {
        return 0;
    }
    if (addr + len > 2u * PIEZO_FLASH_SLOT_BYTES || addr + len < addr) {
        return -1;
    }
    uint32_t first = addr >= PIEZO_FLASH_SLOT_BYTES ? 1u : 0u;
    uint32_t last = addr + len - 1u >= PIEZO_FLASH_SLOT_BYTES ? 1u : 0u;
    for (uint32_t s = first; s <= last; s++) {
        if (piezo_f4_flash_erase_sector(r->first_sector + s) != 0) {
            return -1;
        }
    }
    return 0;
}

piezo_storage_t piezo_f4_flash_storage(void)
{
    piezo_storage_t s = {st_read, st_program, st_erase, &tables_region, PIEZO_FLASH_SLOT_BYTES};
    return s;
}

piezo_storage_t piezo_f4_params_storage(void)
{
    piezo_storage_t s = {st_read, st_program, st_erase, &params_region, PIEZO_FLASH_SLOT_BYTES};
    return s;
}

/* RAM storage: ctx is the buffer of 2 x slot_bytes; slot_bytes is in the
 * storage itself, so the callbacks find the size through a small header. */
typedef piezo_ram_store_t ram_store_t;

static ram_store_t ram_store;

static int ram_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    ram_store_t *r = ctx;
    if (addr + len > r->size || addr + len < addr) {
        return -1;
    }
    for (uint32_t i = 0; i < len; i++) {
        buf[i] = r->mem[addr + i];
    }
    return 0;
}

static int ram_program(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    ram_store_t *r = ctx;
    if (addr + len > r->size || addr + len < addr) {
        return -1;
    }
    for (uint32_t i = 0; i < len; i++) {
        r->mem[addr + i] &= buf[i]; /* NOR: programming only clears bits */
    }
    return 0;
}

static int ram_erase(void *ctx, uint32_t addr, uint32_t len)
{
    ram_store_t *r = ctx;
    if (addr + len > r->size || addr + len < addr) {
        return -1;
    }
    for (uint32_t i = 0; i < len; i++) {
        r->mem[addr + i] = 0xFFu;
    }
    return 0;
}

piezo_storage_t piezo_ram_storage_in(piezo_ram_store_t *r, uint8_t *mem, uint32_t slot_bytes)
{
    r->mem = mem;
    r->size = 2u * slot_bytes;
    for (uint32_t i = 0; i < r->size; i++) {
        mem[i] = 0xFFu; /* erased */
    }
    piezo_storage_t s = {ram_read, ram_program, ram_erase, r, slot_bytes};
    return s;
}

piezo_storage_t piezo_ram_storage(uint8_t *mem, uint32_t slot_bytes)
{
    return piezo_ram_storage_in(&ram_store, mem, slot_bytes);
}
