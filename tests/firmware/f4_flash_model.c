/* f4_flash_model.c - see f4_flash_model.h. */
#include "f4_flash_model.h"

#include <string.h>

#include "flash_f4.h"

f4_flash_model_t f4_model;

void f4_model_reset(uint32_t busy_len)
{
    memset(&f4_model, 0, sizeof f4_model);
    f4_model.cr = PIEZO_FLASH_CR_LOCK;
    f4_model.busy_len = busy_len;
    memset(f4_model.mem, 0xFF, sizeof f4_model.mem);
    memset(f4_model.pmem, 0xFF, sizeof f4_model.pmem);
}

static void start_busy(void)
{
    f4_model.busy_reads = f4_model.busy_len;
    f4_model.sr |= PIEZO_FLASH_SR_BSY;
}

int f4_model_hold_depth;
unsigned f4_model_busy_polls_unheld;

uint32_t piezo_f4_flash_rd(uint32_t off)
{
    if (off == PIEZO_FLASH_SR) {
        uint32_t v = f4_model.sr;
        if ((v & PIEZO_FLASH_SR_BSY) != 0u && f4_model_hold_depth == 0) {
            f4_model_busy_polls_unheld++; /* an interrupt from the flash could stall the tick */
        }
        if ((f4_model.sr & PIEZO_FLASH_SR_BSY) != 0u && !f4_model.stuck_busy) {
            if (f4_model.busy_reads > 0u) {
                f4_model.busy_reads--;
            }
            if (f4_model.busy_reads == 0u) {
                f4_model.sr &= ~PIEZO_FLASH_SR_BSY;
                f4_model.sr |= PIEZO_FLASH_SR_EOP | f4_model.inject_sr;
                f4_model.inject_sr = 0u;
            }
        }
        return v;
    }
    if (off == PIEZO_FLASH_CR) {
        return f4_model.cr;
    }
    return 0u;
}

void piezo_f4_flash_wr(uint32_t off, uint32_t value)
{
    if (off == PIEZO_FLASH_KEYR) {
        f4_model.key_writes++;
        if (f4_model.locked_until_reset) {
            return;
        }
        if (f4_model.key_state == 0 && value == PIEZO_FLASH_KEY1) {
            f4_model.key_state = 1;
        } else if (f4_model.key_state == 1 && value == PIEZO_FLASH_KEY2 && (f4_model.cr & PIEZO_FLASH_CR_LOCK)) {
            f4_model.cr &= ~PIEZO_FLASH_CR_LOCK;
            f4_model.key_state = 0;
        } else {
            f4_model.wrong_keys++;
            f4_model.locked_until_reset = 1; /* RM0090 3.5.1: bus error, locked until reset */
            f4_model.cr |= PIEZO_FLASH_CR_LOCK;
        }
        return;
    }
    if (off == PIEZO_FLASH_SR) {
        f4_model.sr &= ~(value & (PIEZO_FLASH_SR_ERRORS | PIEZO_FLASH_SR_EOP)); /* rc_w1 */
        return;
    }
    if (off != PIEZO_FLASH_CR) {
        return;
    }
    if ((f4_model.cr & PIEZO_FLASH_CR_LOCK) != 0u) {
        f4_model.writes_while_locked++;
        return;
    }
    if ((value & PIEZO_FLASH_CR_LOCK) != 0u) {
        f4_model.cr = PIEZO_FLASH_CR_LOCK; /* LOCK is set by software, cleared only by the keys */
        return;
    }
    if ((f4_model.sr & PIEZO_FLASH_SR_BSY) != 0u) {
        f4_model.ops_while_busy++; /* RM0090: no CR write while BSY */
    }
    f4_model.cr = value & ~PIEZO_FLASH_CR_STRT;
    if ((value & PIEZO_FLASH_CR_STRT) != 0u && (value & PIEZO_FLASH_CR_SER) != 0u) {
        uint32_t snb = (value & PIEZO_FLASH_CR_SNB_MASK) >> PIEZO_FLASH_CR_SNB_SHIFT;
        if (snb >= 8u && snb <= 11u) {
            uint32_t i = snb >= 10u ? snb - 10u : snb - 8u + 2u;
            if (i < 2u) {
                memset(f4_model.mem[i], 0xFF, F4_MODEL_BYTES);
            } else {
                memset(f4_model.pmem[i - 2u], 0xFF, F4_MODEL_PARAM_BYTES);
            }
            f4_model.erases[i]++;
        }
        start_busy();
    }
}

static uint8_t *cell(uint32_t addr)
{
    uint32_t off = addr - PIEZO_FLASH_PARAMS_A_ADDR; /* sectors 8..11, 128 KiB each */
    uint32_t s = off / PIEZO_FLASH_SLOT_BYTES, o = off % PIEZO_FLASH_SLOT_BYTES;
    if (addr < PIEZO_FLASH_PARAMS_A_ADDR || s > 3u) {
        return 0;
    }
    if (s >= 2u) { /* sectors 10, 11: tables */
        return o < F4_MODEL_BYTES ? &f4_model.mem[s - 2u][o] : 0;
    }
    return o < F4_MODEL_PARAM_BYTES ? &f4_model.pmem[s][o] : 0; /* sectors 8, 9: parameters */
}

uint8_t piezo_f4_mem_rd8(uint32_t addr)
{
    uint8_t *c = cell(addr);
    return c != 0 ? *c : 0xFFu;
}

void piezo_f4_mem_wr32(uint32_t addr, uint32_t value)
{
    if ((f4_model.sr & PIEZO_FLASH_SR_BSY) != 0u) {
        f4_model.ops_while_busy++;
    }
    if ((f4_model.cr & PIEZO_FLASH_CR_PG) == 0u || (f4_model.cr & PIEZO_FLASH_CR_LOCK) != 0u) {
        f4_model.sr |= PIEZO_FLASH_SR_PGSERR;
        return;
    }
    if ((f4_model.cr & PIEZO_FLASH_CR_PSIZE_MASK) != PIEZO_FLASH_CR_PSIZE_X32) {
        f4_model.sr |= PIEZO_FLASH_SR_PGPERR;
        return;
    }
    if ((addr & 3u) != 0u) {
        f4_model.sr |= PIEZO_FLASH_SR_PGAERR;
        return;
    }
    for (uint32_t b = 0; b < 4u; b++) {
        uint8_t *c = cell(addr + b);
        if (c != 0) {
            *c &= (uint8_t)(value >> (8u * b)); /* NOR: programming clears bits */
        }
    }
    f4_model.words_programmed++;
    start_busy();
}

/* the chip's BASEPRI hold (flash_f4_mmio.c): counted, checked balanced */
void piezo_f4_flash_hold(int on)
{
    f4_model_hold_depth += on ? 1 : -1;
}
