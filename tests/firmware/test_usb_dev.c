/* The USB device layer (firmware/targets/cortex-m4/src/usb_dev.c) driven as a
 * host drives it: enumeration (descriptors, SET_ADDRESS after its status
 * stage, SET_CONFIGURATION), stalls, and Modbus requests over the bulk
 * endpoints with the usb_bulk framing, on the shared test register bank. */
#include <string.h>

#include "piezo_test.h"
#include "test_modbus_regs.h"
#include "usb_dev.h"

static tregs_t bank;
static piezo_mb_regs_t regs;
static piezo_usbd_t dev;
static uint8_t pkt[64];

static void setup8(uint8_t *s, uint8_t bm, uint8_t req, uint16_t value, uint16_t index, uint16_t length)
{
    s[0] = bm;
    s[1] = req;
    s[2] = (uint8_t)value;
    s[3] = (uint8_t)(value >> 8);
    s[4] = (uint8_t)index;
    s[5] = (uint8_t)(index >> 8);
    s[6] = (uint8_t)length;
    s[7] = (uint8_t)(length >> 8);
}

/* A control read: SETUP, every IN packet of the data stage into out. Returns the bytes read or -1 on a stall. */
static int control_read(uint8_t req, uint16_t value, uint16_t index, uint16_t length, uint8_t *out)
{
    uint8_t s[8];
    setup8(s, 0x80, req, value, index, length);
    int n = piezo_usbd_setup(&dev, s);
    if (n < 0) {
        return -1;
    }
    int got = 0, k;
    while ((k = piezo_usbd_ep0_in(&dev, pkt)) >= 0) {
        memcpy(out + got, pkt, (size_t)k);
        got += k;
        if (k < 64) {
            break;
        }
    }
    piezo_usbd_status_done(&dev);
    return got;
}

static int control_write(uint8_t bm, uint8_t req, uint16_t value, uint16_t index)
{
    uint8_t s[8];
    setup8(s, bm, req, value, index, 0);
    int n = piezo_usbd_setup(&dev, s);
    if (n == 0) {
        piezo_usbd_status_done(&dev);
    }
    return n;
}

static int fresh(void **state)
{
    (void)state;
    regs = tregs_init(&bank);
    piezo_usbd_init(&dev, &regs);
    return 0;
}

static void enumerate(void)
{
    uint8_t buf[64];
    assert_int_equal(control_read(6, 0x0100, 0, 64, buf), 18);
    assert_int_equal(control_write(0x00, 5, 7, 0), 0);
    assert_int_equal(dev.address, 7);
    assert_int_equal(control_write(0x00, 9, 1, 0), 0);
}

static void test_device_descriptor_names_the_ids_and_ep0_size(void **state)
{
    (void)state;
    uint8_t buf[64];
    assert_int_equal(control_read(6, 0x0100, 0, 8, buf), 8); /* the host's first 8-byte read */
    assert_int_equal(buf[7], 64);
    assert_int_equal(control_read(6, 0x0100, 0, 64, buf), 18);
    assert_int_equal(buf[8] | (buf[9] << 8), 0x1209);
    assert_int_equal(buf[10] | (buf[11] << 8), 0x0001);
    assert_int_equal(buf[17], 1);
}

static void test_configuration_is_one_vendor_interface_with_two_bulk_endpoints(void **state)
{
    (void)state;
    uint8_t buf[64];
    assert_int_equal(control_read(6, 0x0200, 0, 9, buf), 9);
    assert_int_equal(buf[2] | (buf[3] << 8), 32);
    assert_int_equal(control_read(6, 0x0200, 0, 255, buf), 32);
    assert_int_equal(buf[9 + 1], 4);    /* interface */
    assert_int_equal(buf[9 + 4], 2);    /* endpoints */
    assert_int_equal(buf[9 + 5], 0xFF); /* vendor class */
    assert_int_equal(buf[18 + 2], 0x01);
    assert_int_equal(buf[18 + 3], 0x02); /* bulk */
    assert_int_equal(buf[18 + 4], 64);
    assert_int_equal(buf[25 + 2], 0x81);
    assert_int_equal(buf[25 + 3], 0x02);
    /* strings: language, then UTF-16LE */
    assert_int_equal(control_read(6, 0x0300, 0, 255, buf), 4);
    assert_int_equal(buf[2] | (buf[3] << 8), 0x0409);
    assert_int_equal(control_read(6, 0x0302, 0x0409, 255, buf), 24);
    assert_int_equal(buf[2], 'p');
    assert_int_equal(control_read(6, 0x0304, 0x0409, 255, buf), -1);
}

static void test_address_applies_after_the_status_stage(void **state)
{
    (void)state;
    uint8_t s[8];
    setup8(s, 0x00, 5, 42, 0, 0);
    assert_int_equal(piezo_usbd_setup(&dev, s), 0);
    assert_int_equal(dev.address, 0); /* still 0 during the status stage (9.4.6) */
    piezo_usbd_status_done(&dev);
    assert_int_equal(dev.address, 42);
}

static void test_unsupported_requests_stall(void **state)
{
    (void)state;
    uint8_t buf[64];
    assert_int_equal(control_write(0x00, 9, 1, 0), PIEZO_USBD_STALL); /* configure before an address */
    assert_int_equal(control_read(6, 0x0600, 0, 10, buf), -1);          /* device qualifier: full speed only */
    assert_int_equal(control_write(0x40, 1, 0, 0), PIEZO_USBD_STALL);  /* vendor request */
    assert_int_equal(control_write(0x00, 5, 200, 0), PIEZO_USBD_STALL); /* address > 127 */
    assert_int_equal(control_read(6, 0x0201, 0, 64, buf), -1);          /* configuration 1 does not exist */
}

static void test_get_status_and_configuration(void **state)
{
    (void)state;
    uint8_t buf[64];
    enumerate();
    assert_int_equal(control_read(8, 0, 0, 1, buf), 1);
    assert_int_equal(buf[0], 1);
    assert_int_equal(control_read(0, 0, 0, 2, buf), 2);
    assert_int_equal(buf[0], 1); /* self-powered */
}

static void test_bulk_out_before_configuration_is_ignored(void **state)
{
    (void)state;
    const uint8_t req[] = {0xA5, 1, 5, 0, 0x04, 0x00, 0x00, 0x00, 0x01};
    assert_int_equal(piezo_usbd_bulk_out(&dev, req, sizeof req), 0);
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), -1);
}

static void test_a_read_over_bulk_answers_in_one_short_packet(void **state)
{
    (void)state;
    enumerate();
    /* FC 4, input register 0, count 1: seq 9 */
    const uint8_t req[] = {0xA5, 9, 5, 0, 0x04, 0x00, 0x00, 0x00, 0x01};
    assert_int_equal(piezo_usbd_bulk_out(&dev, req, sizeof req), 1);
    int n = piezo_usbd_bulk_in(&dev, pkt);
    assert_int_equal(n, 4 + 4);
    assert_int_equal(pkt[0], 0xA5);
    assert_int_equal(pkt[1], 9);
    assert_int_equal(pkt[4], 0x04);
    assert_int_equal(pkt[5], 2);
    assert_int_equal((pkt[6] << 8) | pkt[7], tregs_input_value(0));
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), -1);
}

/* An answer of exactly 64 bytes (FC 4 of 28 registers: 4 + 2 + 56 + 2 = 64? no:
 * header 4 + FC 1 + count 1 + 2 x 29 = 64) ends with a zero-length packet;
 * a request of 2 packets is reassembled. */
static void test_answers_that_fill_their_last_packet_end_with_a_zlp(void **state)
{
    (void)state;
    enumerate();
    const uint8_t req[] = {0xA5, 3, 5, 0, 0x04, 0x00, 0x00, 0x00, 29};
    assert_int_equal(piezo_usbd_bulk_out(&dev, req, sizeof req), 1);
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), 64);
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), 0);
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), -1);

    /* a 125-register read: 4 + 2 + 250 = 256 bytes, four full packets and a ZLP */
    const uint8_t big[] = {0xA5, 4, 5, 0, 0x04, 0x00, 0x00, 0x00, 125};
    assert_int_equal(piezo_usbd_bulk_out(&dev, big, sizeof big), 1);
    for (int k = 0; k < 4; k++) {
        assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), 64);
    }
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), 0);
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), -1);

    /* FC 16 of 40 registers: 4 + 6 + 80 = 90 bytes in two OUT packets */
    uint8_t w[90];
    memset(w, 0, sizeof w);
    w[0] = 0xA5;
    w[1] = 5;
    w[2] = 86;
    w[4] = 0x10;
    w[5] = 0x10;
    w[6] = 0x00; /* holding 0x1000 */
    w[8] = 40;
    w[9] = 80;
    assert_int_equal(piezo_usbd_bulk_out(&dev, w, 64), 0);
    assert_int_equal(piezo_usbd_bulk_out(&dev, w + 64, sizeof w - 64), 1);
    int n = piezo_usbd_bulk_in(&dev, pkt);
    assert_int_equal(pkt[1], 5);
    assert_true(n >= 5);
    assert_true(pkt[4] == 0x10 || pkt[4] == 0x90); /* an answer, normal or exception, echoing the sequence */
}

static void test_a_malformed_request_gets_no_answer(void **state)
{
    (void)state;
    enumerate();
    const uint8_t bad[] = {0x5A, 1, 5, 0, 0x04, 0x00, 0x00, 0x00, 0x01};
    assert_int_equal(piezo_usbd_bulk_out(&dev, bad, sizeof bad), 0);
    assert_int_equal(piezo_usbd_bulk_in(&dev, pkt), -1);
    assert_int_equal(dev.rx.dropped, 1);
}

static void test_bus_reset_forgets_address_and_configuration(void **state)
{
    (void)state;
    enumerate();
    piezo_usbd_reset(&dev);
    assert_int_equal(dev.address, 0);
    assert_int_equal(dev.configuration, 0);
}

/* The USB link's session ends at a bus reset and at SET_CONFIGURATION, so an
 * unlock or upload of the host before does not outlive it. */
static unsigned usb_ends;
static void count_session(void *ctx, uint8_t id, uint8_t event)
{
    (void)ctx;
    if (id == PIEZO_MB_SESSION_USB && event == PIEZO_MB_SESSION_END) {
        usb_ends++;
    }
}

static void test_bus_reset_and_configuration_end_the_session(void **state)
{
    (void)state;
    regs.session = count_session;
    usb_ends = 0u;
    enumerate();
    assert_int_equal(usb_ends, 1); /* SET_CONFIGURATION */
    piezo_usbd_reset(&dev);
    assert_int_equal(usb_ends, 2);
    regs.session = NULL;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_device_descriptor_names_the_ids_and_ep0_size, fresh),
        cmocka_unit_test_setup(test_configuration_is_one_vendor_interface_with_two_bulk_endpoints, fresh),
        cmocka_unit_test_setup(test_address_applies_after_the_status_stage, fresh),
        cmocka_unit_test_setup(test_unsupported_requests_stall, fresh),
        cmocka_unit_test_setup(test_get_status_and_configuration, fresh),
        cmocka_unit_test_setup(test_bulk_out_before_configuration_is_ignored, fresh),
        cmocka_unit_test_setup(test_a_read_over_bulk_answers_in_one_short_packet, fresh),
        cmocka_unit_test_setup(test_answers_that_fill_their_last_packet_end_with_a_zlp, fresh),
        cmocka_unit_test_setup(test_a_malformed_request_gets_no_answer, fresh),
        cmocka_unit_test_setup(test_bus_reset_forgets_address_and_configuration, fresh),
        cmocka_unit_test_setup(test_bus_reset_and_configuration_end_the_session, fresh),
    };
    return cmocka_run_group_tests_name("usb_dev", tests, NULL, NULL);
}
