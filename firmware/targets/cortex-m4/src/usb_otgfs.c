/* usb_otgfs.c - OTG FS device driver (see usb_otgfs.h; RM0090 chapter 34). */
#include "usb_otgfs.h"

/* FIFO RAM (1.25 KiB = 320 words): RX 128 words, EP0 TX 32 (64 bytes), EP1 TX 64 */
#define RXFIFO_WORDS 128u
#define TX0_WORDS 32u
#define TX1_WORDS 64u
#define WAIT_POLLS 100000u

static uint8_t setup_pkt[8];
static uint8_t out_pkt[PIEZO_USBD_BULK_SIZE];
static uint8_t in_pkt[PIEZO_USBD_BULK_SIZE];

static int wait_set(uint32_t off, uint32_t bit, int set)
{
    for (uint32_t i = 0; i < WAIT_POLLS; i++) {
        if (((piezo_otg_rd(off) & bit) != 0u) == (set != 0)) {
            return 0;
        }
    }
    return -1;
}

int piezo_otgfs_init(piezo_usbd_t *d)
{
    piezo_usbd_reset(d);
    /* 34.17.1: wait AHB idle, core soft reset */
    if (wait_set(OTG_GRSTCTL, 1u << 31, 1) != 0) {
        return -1;
    }
    piezo_otg_wr(OTG_GRSTCTL, 1u << 0); /* CSRST */
    if (wait_set(OTG_GRSTCTL, 1u << 0, 0) != 0) {
        return -1;
    }
    /* force device mode, turnaround 6 (AHB >= 32 MHz), embedded FS PHY */
    piezo_otg_wr(OTG_GUSBCFG, (1u << 30) | (6u << 10) | (1u << 6));
    /* transceiver on, no VBUS sensing (self-powered) */
    piezo_otg_wr(OTG_GCCFG, (1u << 16) | (1u << 21));
    /* 34.17.3: device full speed, address 0 */
    piezo_otg_wr(OTG_DCFG, 3u);
    piezo_otg_wr(OTG_GRXFSIZ, RXFIFO_WORDS);
    piezo_otg_wr(OTG_DIEPTXF0, (TX0_WORDS << 16) | RXFIFO_WORDS);
    piezo_otg_wr(OTG_DIEPTXF1, (TX1_WORDS << 16) | (RXFIFO_WORDS + TX0_WORDS));
    piezo_otg_wr(OTG_GRSTCTL, (0x10u << 6) | (1u << 5)); /* flush all TX FIFOs */
    (void)wait_set(OTG_GRSTCTL, 1u << 5, 0);
    piezo_otg_wr(OTG_GRSTCTL, 1u << 4); /* flush RX FIFO */
    (void)wait_set(OTG_GRSTCTL, 1u << 4, 0);
    piezo_otg_wr(OTG_DIEPMSK, 1u << 0); /* XFRC */
    piezo_otg_wr(OTG_DOEPMSK, (1u << 0) | (1u << 3)); /* XFRC, STUP */
    piezo_otg_wr(OTG_GINTSTS, 0xFFFFFFFFu);
    piezo_otg_wr(OTG_GINTMSK, OTG_GINT_RXFLVL | OTG_GINT_USBRST | OTG_GINT_ENUMDNE | OTG_GINT_IEPINT |
                                  OTG_GINT_OEPINT);
    piezo_otg_wr(OTG_GAHBCFG, 1u << 0); /* GINTMSK: global interrupt on */
    piezo_otg_wr(OTG_DCTL, 0u);          /* SDIS cleared: connect */
    return 0;
}

static void ep0_out_arm(void)
{
    /* three back-to-back SETUPs, one 64-byte packet */
    piezo_otg_wr(OTG_DOEPTSIZ(0), (3u << 29) | (1u << 19) | 64u);
    piezo_otg_wr(OTG_DOEPCTL(0), OTG_EPCTL_EPENA | OTG_EPCTL_CNAK);
}

static void bulk_out_arm(void)
{
    piezo_otg_wr(OTG_DOEPTSIZ(1), (1u << 19) | PIEZO_USBD_BULK_SIZE);
    piezo_otg_wr(OTG_DOEPCTL(1), piezo_otg_rd(OTG_DOEPCTL(1)) | OTG_EPCTL_EPENA | OTG_EPCTL_CNAK);
}

/* One IN packet of n bytes (0..64) on endpoint ep: size, enable, then the FIFO words. */
static void in_packet(uint32_t ep, const uint8_t *p, uint32_t n)
{
    piezo_otg_wr(OTG_DIEPTSIZ(ep), (1u << 19) | n);
    piezo_otg_wr(OTG_DIEPCTL(ep), piezo_otg_rd(OTG_DIEPCTL(ep)) | OTG_EPCTL_EPENA | OTG_EPCTL_CNAK);
    for (uint32_t i = 0; i < n; i += 4u) {
        uint32_t w = 0u;
        for (uint32_t b = 0; b < 4u && i + b < n; b++) {
            w |= (uint32_t)p[i + b] << (8u * b);
        }
        piezo_otg_wr(OTG_FIFO(ep), w);
    }
}

static void read_fifo(uint8_t *p, uint32_t n)
{
    for (uint32_t i = 0; i < n; i += 4u) {
        uint32_t w = piezo_otg_rd(OTG_FIFO(0));
        for (uint32_t b = 0; b < 4u && i + b < n; b++) {
            p[i + b] = (uint8_t)(w >> (8u * b));
        }
    }
}

static void ep0_next_in(piezo_usbd_t *d)
{
    int n = piezo_usbd_ep0_in(d, in_pkt);
    if (n >= 0) {
        in_packet(0u, in_pkt, (uint32_t)n);
    } else {
        in_packet(0u, in_pkt, 0u); /* status stage of a control write, or after data: ZLP */
    }
}

static void on_setup(piezo_usbd_t *d)
{
    int n = piezo_usbd_setup(d, setup_pkt);
    if (n < 0) {
        piezo_otg_wr(OTG_DIEPCTL(0), piezo_otg_rd(OTG_DIEPCTL(0)) | OTG_EPCTL_STALL);
        piezo_otg_wr(OTG_DOEPCTL(0), piezo_otg_rd(OTG_DOEPCTL(0)) | OTG_EPCTL_STALL);
        return;
    }
    if ((setup_pkt[0] & 0x80u) != 0u && n > 0) {
        ep0_next_in(d); /* data stage IN; status OUT follows */
    } else {
        /* status stage IN (zero length); SET_ADDRESS: the core takes the
         * address at once (DCFG.DAD) and answers the status stage at 0 */
        if (setup_pkt[1] == 5u) {
            piezo_usbd_status_done(d);
            piezo_otg_wr(OTG_DCFG, (piezo_otg_rd(OTG_DCFG) & ~(0x7Fu << 4)) | ((uint32_t)d->address << 4));
        }
        in_packet(0u, in_pkt, 0u);
        if (setup_pkt[1] == 9u && d->configuration != 0u) {
            /* SET_CONFIGURATION: activate the bulk endpoints */
            piezo_otg_wr(OTG_DOEPCTL(1), OTG_EPCTL_USBAEP | (2u << 18) | OTG_EPCTL_SD0PID | PIEZO_USBD_BULK_SIZE);
            piezo_otg_wr(OTG_DIEPCTL(1), OTG_EPCTL_USBAEP | (2u << 18) | (1u << 22) | OTG_EPCTL_SD0PID |
                                             PIEZO_USBD_BULK_SIZE);
            piezo_otg_wr(OTG_DAINTMSK, (1u << 0) | (1u << 1) | (1u << 16) | (1u << 17));
            bulk_out_arm();
        }
    }
}

void piezo_otgfs_irq(piezo_usbd_t *d)
{
    uint32_t st = piezo_otg_rd(OTG_GINTSTS) & piezo_otg_rd(OTG_GINTMSK);
    if ((st & OTG_GINT_USBRST) != 0u) {
        piezo_otg_wr(OTG_GINTSTS, OTG_GINT_USBRST);
        piezo_usbd_reset(d);
        piezo_otg_wr(OTG_DCFG, piezo_otg_rd(OTG_DCFG) & ~(0x7Fu << 4));
        piezo_otg_wr(OTG_DAINTMSK, (1u << 0) | (1u << 16));
        ep0_out_arm();
    }
    if ((st & OTG_GINT_ENUMDNE) != 0u) {
        piezo_otg_wr(OTG_GINTSTS, OTG_GINT_ENUMDNE);
        piezo_otg_wr(OTG_DIEPCTL(0), 0u); /* MPSIZ 0: 64 bytes */
    }
    while ((piezo_otg_rd(OTG_GINTSTS) & OTG_GINT_RXFLVL) != 0u) {
        uint32_t rx = piezo_otg_rd(OTG_GRXSTSP);
        uint32_t ep = rx & 0xFu, n = (rx >> 4) & 0x7FFu, kind = (rx >> 17) & 0xFu;
        if (kind == OTG_RXSTS_SETUP_DATA && ep == 0u && n == 8u) {
            read_fifo(setup_pkt, 8u);
        } else if (kind == OTG_RXSTS_SETUP_DONE && ep == 0u) {
            on_setup(d);
        } else if (kind == OTG_RXSTS_OUT_DATA && n > 0u) {
            uint32_t take = n > sizeof out_pkt ? sizeof out_pkt : n;
            read_fifo(out_pkt, take);
            for (uint32_t i = take; i < n; i += 4u) {
                (void)piezo_otg_rd(OTG_FIFO(0));
            }
            if (ep == 1u && piezo_usbd_bulk_out(d, out_pkt, take)) {
                int k = piezo_usbd_bulk_in(d, in_pkt);
                if (k >= 0) {
                    in_packet(1u, in_pkt, (uint32_t)k);
                }
            }
        } else if (kind == OTG_RXSTS_OUT_DONE) {
            if (ep == 1u) {
                bulk_out_arm();
            } else {
                ep0_out_arm();
            }
        }
    }
    if ((st & OTG_GINT_IEPINT) != 0u) {
        uint32_t daint = piezo_otg_rd(OTG_DAINT);
        if ((daint & (1u << 0)) != 0u) {
            uint32_t f = piezo_otg_rd(OTG_DIEPINT(0));
            piezo_otg_wr(OTG_DIEPINT(0), f);
            if ((f & 1u) != 0u && d->ep0_data != 0) {
                ep0_next_in(d); /* next packet of the data stage */
            }
        }
        if ((daint & (1u << 1)) != 0u) {
            uint32_t f = piezo_otg_rd(OTG_DIEPINT(1));
            piezo_otg_wr(OTG_DIEPINT(1), f);
            if ((f & 1u) != 0u) {
                int k = piezo_usbd_bulk_in(d, in_pkt);
                if (k >= 0) {
                    in_packet(1u, in_pkt, (uint32_t)k);
                }
            }
        }
    }
    if ((st & OTG_GINT_OEPINT) != 0u) {
        uint32_t daint = piezo_otg_rd(OTG_DAINT);
        for (uint32_t ep = 0; ep < 2u; ep++) {
            if ((daint & (1u << (16u + ep))) != 0u) {
                uint32_t f = piezo_otg_rd(OTG_DOEPINT(ep));
                piezo_otg_wr(OTG_DOEPINT(ep), f);
                if (ep == 0u && (f & (1u << 3)) != 0u) {
                    ep0_out_arm(); /* after a SETUP phase: ready for the next */
                }
            }
        }
    }
}
