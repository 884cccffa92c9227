/* usb_otgfs_mmio.c - usb_otgfs.c's register access on the chip (OTG FS at 0x50000000). */
#include "board.h"
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
