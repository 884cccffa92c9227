/*
 * usb_otgfs.h - the STM32F405's USB OTG FS core in device mode (RM0090
 * chapter 34), under the USB device layer of usb_dev.h: core and device
 * initialisation (34.17.1, 34.17.3), FIFO sizes, endpoint 0 and the two bulk
 * endpoints, and the interrupt that moves packets between the FIFOs and
 * usb_dev.c (RXFLVL: SETUP and OUT packets popped from the receive FIFO;
 * IEPINT/OEPINT: transfers completed; USBRST, ENUMDNE).
 *
 * Pins: PA11 DM, PA12 DP (AF10), VBUS sensing off (self-powered board).
 * The 48 MHz clock comes from the PLL's Q output (board.c sets PLLQ = 7 for
 * 336 MHz VCO: 48 MHz).
 *
 * Registers go through piezo_otg_rd/wr (usb_otgfs_mmio.c on the chip; a fake
 * core in tests/firmware/fake_otgfs.c). QEMU models no OTG: the driver is
 * tested only against that fake; on silicon it is untested.
 */
#ifndef PIEZO_USB_OTGFS_H
#define PIEZO_USB_OTGFS_H

#include <stdint.h>

#include "usb_dev.h"

/* RM0090 34.16: register offsets from 0x50000000 */
#define OTG_GAHBCFG 0x008u
#define OTG_GUSBCFG 0x00Cu
#define OTG_GRSTCTL 0x010u
#define OTG_GINTSTS 0x014u
#define OTG_GINTMSK 0x018u
#define OTG_GRXSTSP 0x020u
#define OTG_GRXFSIZ 0x024u
#define OTG_DIEPTXF0 0x028u
#define OTG_GCCFG 0x038u
#define OTG_DIEPTXF1 0x104u
#define OTG_DCFG 0x800u
#define OTG_DCTL 0x804u
#define OTG_DIEPMSK 0x810u
#define OTG_DOEPMSK 0x814u
#define OTG_DAINT 0x818u
#define OTG_DAINTMSK 0x81Cu
#define OTG_DIEPCTL(n) (0x900u + 0x20u * (n))
#define OTG_DIEPINT(n) (0x908u + 0x20u * (n))
#define OTG_DIEPTSIZ(n) (0x910u + 0x20u * (n))
#define OTG_DOEPCTL(n) (0xB00u + 0x20u * (n))
#define OTG_DOEPINT(n) (0xB08u + 0x20u * (n))
#define OTG_DOEPTSIZ(n) (0xB10u + 0x20u * (n))
#define OTG_FIFO(n) (0x1000u + 0x1000u * (n))

#define OTG_GINT_RXFLVL (1u << 4)
#define OTG_GINT_USBRST (1u << 12)
#define OTG_GINT_ENUMDNE (1u << 13)
#define OTG_GINT_IEPINT (1u << 18)
#define OTG_GINT_OEPINT (1u << 19)

#define OTG_RXSTS_OUT_DATA 2u
#define OTG_RXSTS_OUT_DONE 3u
#define OTG_RXSTS_SETUP_DONE 4u
#define OTG_RXSTS_SETUP_DATA 6u

#define OTG_EPCTL_USBAEP (1u << 15)
#define OTG_EPCTL_STALL (1u << 21)
#define OTG_EPCTL_CNAK (1u << 26)
#define OTG_EPCTL_SNAK (1u << 27)
#define OTG_EPCTL_SD0PID (1u << 28)
#define OTG_EPCTL_EPENA (1u << 31)

uint32_t piezo_otg_rd(uint32_t off);
void piezo_otg_wr(uint32_t off, uint32_t value);

/** Core reset, device mode, full speed, FIFOs, interrupts; soft-connect. */
int piezo_otgfs_init(piezo_usbd_t *d);

/** The OTG_FS interrupt's work (call from OTG_FS_IRQHandler). */
void piezo_otgfs_irq(piezo_usbd_t *d);

#endif /* PIEZO_USB_OTGFS_H */
