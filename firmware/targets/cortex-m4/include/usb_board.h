/*
 * usb_board.h - the OTG FS device in the firmware image: the chip's side of
 * usb_otgfs.c (clock, pins, interrupt) and the path from its interrupt to
 * the background loop, where the usb_bulk/PDU code serves the register map
 * next to the RTU server (comm.c).
 *
 * Init (RM0090): GPIOA's clock (RCC_AHB1ENR.GPIOAEN, 6.3.10), PA11 (DM) and
 * PA12 (DP) in alternate function AF10 at high speed (8.4.1, 8.4.3, 8.4.10;
 * the datasheet's alternate function map), then the OTG FS clock (RCC_AHB2ENR.OTGFSEN,
 * 6.3.11; 48 MHz from the PLL's Q output, board.c), then the core
 * (piezo_otgfs_init: every wait bounded), and only when the core came up its
 * interrupt in the NVIC (OTG_FS, position 67, RM0090 table 61). QEMU 7.2
 * models no OTG (its registers read 0): the core's first wait times out, init
 * returns -1 and the image runs without USB.
 *
 * Interrupt: OTG_FS_IRQHandler only masks the OTG_FS line in the NVIC and
 * marks it pending; piezo_usb_poll() (the background loop, comm.c) runs the
 * driver's interrupt work there and unmasks the line. So a USB request runs
 * the PDU server in the same context as an RTU request, never both at once,
 * with the same masked writes, and the tick is never delayed by it. A bus
 * reset or SET_CONFIGURATION ends the USB session (usb_dev.c).
 *
 * Registers outside the OTG core go through piezo_usb_board_rd/wr
 * (usb_otgfs_mmio.c on the chip; the test records them: test_usb_board).
 */
#ifndef PIEZO_USB_BOARD_H
#define PIEZO_USB_BOARD_H

#include <stdint.h>

#include "usb_dev.h"

/* RM0090 table 61: OTG_FS global interrupt */
#define PIEZO_IRQ_OTG_FS 67u
/* below the tick, as the UART (board.h) */
#define PIEZO_PRIO_USB 0x40u

/* RM0090 6.3.10, 6.3.11 (RCC at 0x40023800), 8.4 (GPIOA at 0x40020000) */
#define PIEZO_RCC_AHB1ENR 0x40023830u
#define PIEZO_RCC_AHB2ENR 0x40023834u
#define PIEZO_RCC_AHB1ENR_GPIOAEN (1u << 0)
#define PIEZO_RCC_AHB2ENR_OTGFSEN (1u << 7)
#define PIEZO_GPIOA_MODER 0x40020000u
#define PIEZO_GPIOA_OSPEEDR 0x40020008u
#define PIEZO_GPIOA_AFRH 0x40020024u
#define PIEZO_USB_AF 10u
/* ARMv7-M B3.4: NVIC */
#define PIEZO_NVIC_ISER(n) (0xE000E100u + 4u * (n))
#define PIEZO_NVIC_ICER(n) (0xE000E180u + 4u * (n))
#define PIEZO_NVIC_IPR8(irq) (0xE000E400u + (irq))

/* piezo_usb_state() */
#define PIEZO_USB_ABSENT 0u  /* init not run, or the core did not come up */
#define PIEZO_USB_RUNNING 1u /* the core is up and its interrupt enabled */

uint32_t piezo_usb_board_rd(uint32_t addr);
void piezo_usb_board_wr(uint32_t addr, uint32_t value);
void piezo_usb_board_wr8(uint32_t addr, uint8_t value);

/** The image's USB device (for tests). */
extern piezo_usbd_t piezo_usb_dev;

/** Clocks, pins, the core, the interrupt (above), serving regs. Returns 0,
 *  or -1 when the core did not come up (no OTG peripheral: QEMU). */
int piezo_usb_init(const piezo_mb_regs_t *regs);

/** Background loop: run the core's pending interrupt work. 1 when it did. */
int piezo_usb_poll(void);

uint32_t piezo_usb_state(void);

void OTG_FS_IRQHandler(void);

#endif /* PIEZO_USB_BOARD_H */
