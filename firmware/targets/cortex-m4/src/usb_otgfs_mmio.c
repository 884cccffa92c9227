/* usb_otgfs_mmio.c - usb_otgfs.c's and usb_board.c's register access on the
 * chip (OTG FS at 0x50000000; RCC, GPIOA, NVIC at their addresses). */
#include "board.h"
#include "usb_board.h"
#include "usb_otgfs.h"

#define OTG_FS_BASE 0x50000000u

uint32_t piezo_otg_rd(uint32_t off)
{
    return PIEZO_REG(OTG_FS_BASE + off);
}

void piezo_otg_wr(uint32_t off, uint32_t value)
{
    PIEZO_REG(OTG_FS_BASE + off) = value;
}

uint32_t piezo_usb_board_rd(uint32_t addr)
{
    return PIEZO_REG(addr);
}

void piezo_usb_board_wr(uint32_t addr, uint32_t value)
{
    PIEZO_REG(addr) = value;
}

void piezo_usb_board_wr8(uint32_t addr, uint8_t value)
{
    *(volatile uint8_t *)addr = value;
}
