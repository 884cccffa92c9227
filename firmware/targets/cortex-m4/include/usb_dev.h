/*
 * usb_dev.h - the device side of the USB link, HAL-free: descriptors of a
 * vendor-class device (one interface, class 0xFF, a bulk OUT endpoint 0x01
 * and a bulk IN endpoint 0x81 of 64 bytes, full speed), the standard control
 * requests on endpoint 0 (USB 2.0 chapter 9), and the bulk endpoints carrying
 * the usb_bulk framing (firmware/protocol/usb_bulk.h: requests reassembled
 * from OUT packets, the answer cut into IN packets, a zero-length packet
 * after an answer that fills its last packet).
 *
 * The OTG FS driver (usb_otgfs.c, run from the background loop by
 * usb_board.c) calls these from its interrupt work: on a SETUP packet
 * piezo_usbd_setup(), then piezo_usbd_ep0_in() for each IN packet of the
 * data stage and piezo_usbd_status_done() after the status stage; on a
 * bulk OUT packet piezo_usbd_bulk_out(), then piezo_usbd_bulk_in() for each
 * IN packet of the answer. QEMU models no OTG:
 * tests/firmware/test_usb_dev.c drives this layer as a host would.
 *
 * Ids: VID 0x1209 (pid.codes), PID 0x0001 (its test PID), as the host's
 * transport (host/piezoctl/transport/usb.py) expects.
 */
#ifndef PIEZO_USB_DEV_H
#define PIEZO_USB_DEV_H

#include <stddef.h>
#include <stdint.h>

#include "usb_bulk.h"

#define PIEZO_USBD_VID 0x1209u
#define PIEZO_USBD_PID 0x0001u
#define PIEZO_USBD_EP0_SIZE 64u
#define PIEZO_USBD_BULK_SIZE 64u
#define PIEZO_USBD_EP_OUT 0x01u
#define PIEZO_USBD_EP_IN 0x81u
#define PIEZO_USBD_STALL (-1)

typedef struct {
    const piezo_mb_regs_t *regs;
    uint8_t address;         /* in effect */
    uint8_t pending_address; /* SET_ADDRESS: applied after its status stage */
    uint8_t configuration;   /* 0: addressed, 1: configured */
    /* endpoint 0 IN data stage */
    const uint8_t *ep0_data;
    uint16_t ep0_left;
    uint8_t ep0_zlp;
    uint8_t ep0_buf[4];
    /* bulk */
    piezo_usb_rx_t rx;
    uint8_t rsp[PIEZO_USB_FRAME_MAX];
    uint16_t rsp_len, rsp_pos;
    uint8_t rsp_zlp;
} piezo_usbd_t;

/** Bind to a register map; the state of a bus reset (address 0, not configured). */
void piezo_usbd_init(piezo_usbd_t *d, const piezo_mb_regs_t *regs);

/** Bus reset: address 0, not configured, transfers dropped; the USB link's
 *  Modbus session (PIEZO_MB_SESSION_USB) ends, as at SET_CONFIGURATION. */
void piezo_usbd_reset(piezo_usbd_t *d);

/** A SETUP packet. Returns PIEZO_USBD_STALL (the request is not supported:
 *  stall endpoint 0), or the length of the data stage (0: status only). */
int piezo_usbd_setup(piezo_usbd_t *d, const uint8_t setup[8]);

/** The next IN packet of the data stage into pkt (64 bytes); its length, or
 *  -1 when the data stage is over (a short or zero-length packet ended it). */
int piezo_usbd_ep0_in(piezo_usbd_t *d, uint8_t *pkt);

/** The status stage completed: a pending SET_ADDRESS takes effect. */
void piezo_usbd_status_done(piezo_usbd_t *d);

/** A bulk OUT packet. Returns 1 when it completed a request whose answer is
 *  now waiting for piezo_usbd_bulk_in(), else 0 (incomplete, dropped, or
 *  not configured). */
int piezo_usbd_bulk_out(piezo_usbd_t *d, const uint8_t *pkt, size_t n);

/** The next bulk IN packet of the answer; its length, or -1 when none. */
int piezo_usbd_bulk_in(piezo_usbd_t *d, uint8_t *pkt);

/** The descriptors (for tests and the driver). */
extern const uint8_t piezo_usbd_device_desc[18];
extern const uint8_t piezo_usbd_config_desc[32];

#endif /* PIEZO_USB_DEV_H */
