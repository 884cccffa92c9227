/* flash_f4_mmio.c - flash_f4.c's access functions on the chip: the flash
 * interface registers at 0x40023C00 (RM0090 3.9) and the flash array. */
#include "board.h"
#include "flash_f4.h"

#define FLASH_R_BASE 0x40023C00u

uint32_t piezo_f4_flash_rd(uint32_t off)
{
    return PIEZO_REG(FLASH_R_BASE + off);
}

void piezo_f4_flash_wr(uint32_t off, uint32_t value)
{
    PIEZO_REG(FLASH_R_BASE + off) = value;
}

uint8_t piezo_f4_mem_rd8(uint32_t addr)
{
    return *(volatile const uint8_t *)addr;
}

void piezo_f4_mem_wr32(uint32_t addr, uint32_t value)
{
    *(volatile uint32_t *)addr = value;
    __asm volatile("dsb" ::: "memory");
}

/* BASEPRI 0x10: only priority 0x00 (the tick, board.h) preempts. */
void piezo_f4_flash_hold(int on)
{
    uint32_t v = on ? 0x10u : 0u;
    __asm volatile("msr basepri, %0\n\tisb" ::"r"(v) : "memory");
}
