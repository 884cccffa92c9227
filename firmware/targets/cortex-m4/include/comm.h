/*
 * comm.h - the Modbus RTU server of the firmware image on USART1: the
 * protocol layer's RTU framer and PDU server (firmware/protocol) on the
 * controller's register map (firmware/control/regmap.c), run from the
 * background loop.
 */
#ifndef PIEZO_CM4_COMM_H
#define PIEZO_CM4_COMM_H

#include <stdint.h>

#include "modbus_rtu.h"
#include "regmap.h"

#define PIEZO_MODBUS_BAUD 115200u

/** The RTU framer's time base: one tick is this many microseconds. */
#define PIEZO_COMM_US_PER_TICK 100u

/** The image's register map and framer (for tests and the bench). */
extern piezo_regmap_t piezo_comm_map;
extern piezo_rtu_t piezo_comm_rtu;

/** Bind the register map to piezo_axis, set the identity, provision the
 *  controller (stage, axis, the image's unlock key), set up the framer (unit
 *  id from the interface, PIEZO_MODBUS_BAUD). Call after piezo_control_init()
 *  and before piezo_ctl_attach_store(). Returns 0 or -1. */
int piezo_comm_init(void);

/** The register map as both links serve it (writes masked, comm.c): the
 *  USB link's (usb_board.h) too. */
const piezo_mb_regs_t *piezo_comm_regs(void);

/** One pass of the server: the USB link's pending work (piezo_usb_poll),
 *  then received bytes into the framer, a complete request through the PDU
 *  server, its answer queued for the transmit interrupt. Returns 1 when it did something, 0 when idle. */
int piezo_comm_poll(void);

#endif /* PIEZO_CM4_COMM_H */
