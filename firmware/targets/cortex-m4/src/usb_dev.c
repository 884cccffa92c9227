/* usb_dev.c - USB device: descriptors, chapter 9 requests, bulk endpoints (see usb_dev.h). */
#include "usb_dev.h"

#include <string.h>

/* USB 2.0 table 9-4 (request codes) and 9-5 (descriptor types) */
#define REQ_GET_STATUS 0u
#define REQ_CLEAR_FEATURE 1u
#define REQ_SET_FEATURE 3u
#define REQ_SET_ADDRESS 5u
#define REQ_GET_DESCRIPTOR 6u
#define REQ_GET_CONFIGURATION 8u
#define REQ_SET_CONFIGURATION 9u
#define REQ_GET_INTERFACE 10u
#define REQ_SET_INTERFACE 11u
#define DESC_DEVICE 1u
#define DESC_CONFIG 2u
#define DESC_STRING 3u

const uint8_t piezo_usbd_device_desc[18] = {
    18, DESC_DEVICE, 0x00, 0x02, /* USB 2.0 */
    0x00, 0x00, 0x00,            /* class per interface */
    PIEZO_USBD_EP0_SIZE,
    PIEZO_USBD_VID & 0xFFu, PIEZO_USBD_VID >> 8, PIEZO_USBD_PID & 0xFFu, PIEZO_USBD_PID >> 8,
    0x00, 0x01, /* bcdDevice 1.00 */
    1, 2, 3,    /* manufacturer, product, serial strings */
    1,          /* one configuration */
};

const uint8_t piezo_usbd_config_desc[32] = {
    /* configuration (9.6.3): total 32 bytes, one interface, value 1, self-powered, 100 mA */
    9, DESC_CONFIG, 32, 0, 1, 1, 0, 0xC0, 50,
    /* interface (9.6.5): 0, alt 0, two endpoints, vendor class 0xFF */
    9, 4, 0, 0, 2, 0xFF, 0x00, 0x00, 0,
    /* endpoints (9.6.6): bulk OUT 0x01 and bulk IN 0x81, 64 bytes */
    7, 5, PIEZO_USBD_EP_OUT, 0x02, PIEZO_USBD_BULK_SIZE, 0, 0,
    7, 5, PIEZO_USBD_EP_IN, 0x02, PIEZO_USBD_BULK_SIZE, 0, 0,
};

static const uint8_t str_lang[4] = {4, DESC_STRING, 0x09, 0x04}; /* en-US */
static const uint8_t str_manufacturer[18] = {18, DESC_STRING, 'p', 0, 'i', 0, 'e', 0, 'z', 0, 'o', 0,
                                             'c', 0, 't', 0, 'l', 0};
static const uint8_t str_product[24] = {24, DESC_STRING, 'p', 0, 'i', 0, 'e', 0, 'z', 0, 'o', 0, 'c', 0,
                                        't', 0, 'l', 0, '-', 0, 'f', 0, 'w', 0};
static const uint8_t str_serial[10] = {10, DESC_STRING, '0', 0, '0', 0, '0', 0, '1', 0};

/* The USB link's session (modbus_pdu.h) ends with the host that had it: at a
 * bus reset (a replug, a host that re-enumerates) and at SET_CONFIGURATION
 * (a new configuration starts a new link). What it unlocked and staged goes
 * with it, as with a closed TCP connection. */
static void end_session(piezo_usbd_t *d)
{
    if (d->regs != NULL && d->regs->session != NULL) {
        d->regs->session(d->regs->ctx, PIEZO_MB_SESSION_USB, PIEZO_MB_SESSION_END);
    }
}

void piezo_usbd_reset(piezo_usbd_t *d)
{
    end_session(d);
    d->address = 0u;
    d->pending_address = 0u;
    d->configuration = 0u;
    d->ep0_data = NULL;
    d->ep0_left = 0u;
    d->ep0_zlp = 0u;
    piezo_usb_rx_init(&d->rx);
    d->rsp_len = 0u;
    d->rsp_pos = 0u;
    d->rsp_zlp = 0u;
}

void piezo_usbd_init(piezo_usbd_t *d, const piezo_mb_regs_t *regs)
{
    d->regs = regs;
    piezo_usbd_reset(d);
}

static int send(piezo_usbd_t *d, const uint8_t *data, uint16_t len, uint16_t wlength)
{
    uint16_t n = len < wlength ? len : wlength;
    d->ep0_data = data;
    d->ep0_left = n;
    /* a data stage shorter than asked for that ends on a full packet needs a ZLP */
    d->ep0_zlp = (uint8_t)(n < wlength && n > 0u && (n % PIEZO_USBD_EP0_SIZE) == 0u);
    return (int)n;
}

static int get_descriptor(piezo_usbd_t *d, uint8_t type, uint8_t index, uint16_t wlength)
{
    switch (type) {
    case DESC_DEVICE:
        return send(d, piezo_usbd_device_desc, sizeof piezo_usbd_device_desc, wlength);
    case DESC_CONFIG:
        return index == 0u ? send(d, piezo_usbd_config_desc, sizeof piezo_usbd_config_desc, wlength)
                           : PIEZO_USBD_STALL;
    case DESC_STRING:
        switch (index) {
        case 0: return send(d, str_lang, sizeof str_lang, wlength);
        case 1: return send(d, str_manufacturer, sizeof str_manufacturer, wlength);
        case 2: return send(d, str_product, sizeof str_product, wlength);
        case 3: return send(d, str_serial, sizeof str_serial, wlength);
        default: return PIEZO_USBD_STALL;
        }
    default:
        return PIEZO_USBD_STALL; /* no qualifier: a full-speed-only device stalls it (9.6.2) */
    }
}

int piezo_usbd_setup(piezo_usbd_t *d, const uint8_t s[8])
{
    uint8_t bm = s[0], req = s[1];
    uint16_t wvalue = (uint16_t)(s[2] | (s[3] << 8));
    uint16_t windex = (uint16_t)(s[4] | (s[5] << 8));
    uint16_t wlength = (uint16_t)(s[6] | (s[7] << 8));
    uint8_t recipient = bm & 0x1Fu;
    d->ep0_data = NULL;
    d->ep0_left = 0u;
    d->ep0_zlp = 0u;
    if ((bm & 0x60u) != 0u) {
        return PIEZO_USBD_STALL; /* class and vendor requests: none on endpoint 0 */
    }
    switch (req) {
    case REQ_GET_DESCRIPTOR:
        if (bm != 0x80u) {
            return PIEZO_USBD_STALL;
        }
        return get_descriptor(d, (uint8_t)(wvalue >> 8), (uint8_t)wvalue, wlength);
    case REQ_SET_ADDRESS:
        if (bm != 0x00u || wvalue > 127u || wlength != 0u || d->configuration != 0u) {
            return PIEZO_USBD_STALL;
        }
        d->pending_address = (uint8_t)wvalue;
        return 0;
    case REQ_SET_CONFIGURATION:
        if (bm != 0x00u || wvalue > 1u || d->address == 0u) {
            return PIEZO_USBD_STALL; /* 9.4.7: only in the addressed or configured state */
        }
        d->configuration = (uint8_t)wvalue;
        end_session(d);
        piezo_usb_rx_init(&d->rx);
        d->rsp_len = 0u;
        d->rsp_pos = 0u;
        d->rsp_zlp = 0u;
        return 0;
    case REQ_GET_CONFIGURATION:
        if (bm != 0x80u || wlength != 1u) {
            return PIEZO_USBD_STALL;
        }
        d->ep0_buf[0] = d->configuration;
        return send(d, d->ep0_buf, 1u, wlength);
    case REQ_GET_STATUS:
        if ((bm & 0x80u) == 0u || wlength != 2u) {
            return PIEZO_USBD_STALL;
        }
        if (recipient == 0u) {
            d->ep0_buf[0] = 0x01u; /* self-powered, no remote wake-up */
        } else if (recipient == 1u && windex == 0u && d->configuration != 0u) {
            d->ep0_buf[0] = 0x00u;
        } else if (recipient == 2u && ((windex & 0x7Fu) <= 1u)) {
            d->ep0_buf[0] = 0x00u; /* not halted */
        } else {
            return PIEZO_USBD_STALL;
        }
        d->ep0_buf[1] = 0x00u;
        return send(d, d->ep0_buf, 2u, wlength);
    case REQ_GET_INTERFACE:
        if (bm != 0x81u || windex != 0u || d->configuration == 0u || wlength != 1u) {
            return PIEZO_USBD_STALL;
        }
        d->ep0_buf[0] = 0u;
        return send(d, d->ep0_buf, 1u, wlength);
    case REQ_SET_INTERFACE:
        return (bm == 0x01u && windex == 0u && wvalue == 0u && d->configuration != 0u) ? 0 : PIEZO_USBD_STALL;
    case REQ_CLEAR_FEATURE:
    case REQ_SET_FEATURE:
        /* ENDPOINT_HALT on the bulk endpoints: accepted; CLEAR drops a half request */
        if (bm == 0x02u && wvalue == 0u && (windex == PIEZO_USBD_EP_OUT || windex == PIEZO_USBD_EP_IN)) {
            if (req == REQ_CLEAR_FEATURE) {
                piezo_usb_rx_init(&d->rx);
            }
            return 0;
        }
        return PIEZO_USBD_STALL;
    default:
        return PIEZO_USBD_STALL;
    }
}

int piezo_usbd_ep0_in(piezo_usbd_t *d, uint8_t *pkt)
{
    if (d->ep0_data == NULL) {
        return -1;
    }
    if (d->ep0_left == 0u) {
        if (d->ep0_zlp) {
            d->ep0_zlp = 0u;
            d->ep0_data = NULL;
            return 0;
        }
        d->ep0_data = NULL;
        return -1;
    }
    uint16_t n = d->ep0_left < PIEZO_USBD_EP0_SIZE ? d->ep0_left : PIEZO_USBD_EP0_SIZE;
    memcpy(pkt, d->ep0_data, n);
    d->ep0_data += n;
    d->ep0_left = (uint16_t)(d->ep0_left - n);
    if (d->ep0_left == 0u && !d->ep0_zlp) {
        d->ep0_data = NULL; /* a short packet, or exactly what was asked: the end */
    }
    return (int)n;
}

void piezo_usbd_status_done(piezo_usbd_t *d)
{
    if (d->pending_address != d->address) {
        d->address = d->pending_address; /* 9.4.6: after the status stage */
    }
}

int piezo_usbd_bulk_out(piezo_usbd_t *d, const uint8_t *pkt, size_t n)
{
    if (d->configuration == 0u || n > PIEZO_USBD_BULK_SIZE) {
        return 0;
    }
    size_t r = piezo_usb_feed(&d->rx, pkt, n, PIEZO_USBD_BULK_SIZE, d->regs, d->rsp, sizeof d->rsp);
    if (r == 0u) {
        return 0;
    }
    d->rsp_len = (uint16_t)r;
    d->rsp_pos = 0u;
    d->rsp_zlp = (uint8_t)((r % PIEZO_USBD_BULK_SIZE) == 0u);
    return 1;
}

int piezo_usbd_bulk_in(piezo_usbd_t *d, uint8_t *pkt)
{
    if (d->rsp_pos >= d->rsp_len) {
        if (d->rsp_len != 0u && d->rsp_zlp) {
            d->rsp_zlp = 0u;
            d->rsp_len = 0u;
            return 0; /* the answer filled its last packet: a ZLP ends the transfer */
        }
        d->rsp_len = 0u;
        return -1;
    }
    uint16_t n = (uint16_t)(d->rsp_len - d->rsp_pos);
    if (n > PIEZO_USBD_BULK_SIZE) {
        n = PIEZO_USBD_BULK_SIZE;
    }
    memcpy(pkt, d->rsp + d->rsp_pos, n);
    d->rsp_pos = (uint16_t)(d->rsp_pos + n);
    return (int)n;
}
