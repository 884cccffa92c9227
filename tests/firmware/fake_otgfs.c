/* fake_otgfs.c - see fake_otgfs.h. */
#include "fake_otgfs.h"

#include <string.h>

#include "usb_otgfs.h"

fake_otg_t fotg;

void fake_otg_reset(void)
{
    memset(&fotg, 0, sizeof fotg);
}

static void push(uint32_t w)
{
    fotg.rxq[fotg.rx_tail++ % 256u] = w;
}

void fake_otg_rx(uint32_t ep, uint32_t kind, const uint8_t *data, uint32_t n)
{
    push(ep | (n << 4) | (kind << 17));
    for (uint32_t i = 0; i < n; i += 4u) {
        uint32_t w = 0u;
        for (uint32_t b = 0; b < 4u && i + b < n; b++) {
            w |= (uint32_t)data[i + b] << (8u * b);
        }
        push(w);
    }
}

uint32_t piezo_otg_rd(uint32_t off)
{
    fotg.accesses++;
    if (fotg.absent) {
        return 0u;
    }
    if (off == OTG_GRSTCTL) {
        return 1u << 31; /* AHB idle; resets and flushes done */
    }
    if (off == OTG_GINTSTS) {
        uint32_t v = fotg.reg[off / 4u] & ~OTG_GINT_RXFLVL;
        return v | (fotg.rx_head != fotg.rx_tail ? OTG_GINT_RXFLVL : 0u);
    }
    if (off == OTG_GRXSTSP || off == OTG_FIFO(0)) {
        return fotg.rx_head != fotg.rx_tail ? fotg.rxq[fotg.rx_head++ % 256u] : 0u;
    }
    return off < sizeof fotg.reg ? fotg.reg[off / 4u] : 0u;
}

void piezo_otg_wr(uint32_t off, uint32_t value)
{
    fotg.accesses++;
    if (fotg.absent) {
        return;
    }
    if (off == OTG_FIFO(0) || off == OTG_FIFO(1)) {
        unsigned ep = off == OTG_FIFO(0) ? 0u : 1u;
        for (unsigned b = 0; b < 4u && fotg.tx_len[ep] < sizeof fotg.tx[ep]; b++) {
            fotg.tx[ep][fotg.tx_len[ep]++] = (uint8_t)(value >> (8u * b));
        }
        return;
    }
    if (off == OTG_GINTSTS) {
        fotg.reg[off / 4u] &= ~value; /* rc_w1 */
        return;
    }
    if (off == OTG_DIEPTSIZ(0) || off == OTG_DIEPTSIZ(1)) {
        fotg.tx_packets[off == OTG_DIEPTSIZ(0) ? 0 : 1]++;
    }
    if (off < sizeof fotg.reg) {
        fotg.reg[off / 4u] = value;
    }
}
