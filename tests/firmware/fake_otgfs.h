/*
 * fake_otgfs.h - a fake of the OTG FS core's registers for the driver's host
 * test: GRSTCTL (AHB idle, resets and flushes that complete at once), the
 * receive FIFO as a queue of status words (GRXSTSP, RXFLVL while not empty)
 * and data words (FIFO reads), the transmit FIFOs recorded per endpoint, and
 * every other register as plain storage.
 */
#ifndef FAKE_OTGFS_H
#define FAKE_OTGFS_H

#include <stdint.h>

typedef struct {
    uint32_t reg[0x1000 / 4];  /* 0x000..0xFFF */
    uint32_t rxq[256];
    unsigned rx_head, rx_tail;
    uint8_t tx[2][512];
    unsigned tx_len[2];
    unsigned tx_packets[2];
    unsigned accesses; /* reads and writes so far (for ordering checks) */
    int absent;        /* no core: every register reads 0, writes are lost (QEMU) */
} fake_otg_t;

extern fake_otg_t fotg;

void fake_otg_reset(void);
/** Queue a packet as the core would: a status word (GRXSTSP) then its data words. */
void fake_otg_rx(uint32_t ep, uint32_t kind, const uint8_t *data, uint32_t n);

#endif /* FAKE_OTGFS_H */
