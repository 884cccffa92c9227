/* The OTG FS driver (firmware/targets/cortex-m4/src/usb_otgfs.c) against a
 * fake core (fake_otgfs.c): initialisation, bus reset, enumeration through
 * the receive FIFO, and a Modbus request over the bulk endpoints. Only the
 * register sequences the driver produces are checked: the fake is not the
 * silicon (docs/target-cortex-m4.md, "USB"). */
#include <string.h>

#include "piezo_test.h"
#include "fake_otgfs.h"
#include "test_modbus_regs.h"
#include "usb_otgfs.h"

static tregs_t bank;
static piezo_mb_regs_t regs;
static piezo_usbd_t dev;

#define REG(off) fotg.reg[(off) / 4u]

static void setup_request(uint8_t bm, uint8_t req, uint16_t value, uint16_t length)
{
    const uint8_t s[8] = {bm, req, (uint8_t)value, (uint8_t)(value >> 8), 0, 0, (uint8_t)length,
                          (uint8_t)(length >> 8)};
    fake_otg_rx(0u, OTG_RXSTS_SETUP_DATA, s, 8u);
    fake_otg_rx(0u, OTG_RXSTS_SETUP_DONE, NULL, 0u);
    piezo_otgfs_irq(&dev);
}

static int start(void **state)
{
    (void)state;
    fake_otg_reset();
    regs = tregs_init(&bank);
    assert_int_equal(piezo_otgfs_init(&dev), 0);
    dev.regs = &regs;
    return 0;
}

static void test_init_puts_the_core_in_full_speed_device_mode(void **state)
{
    (void)state;
    assert_true((REG(OTG_GUSBCFG) & (1u << 30)) != 0u); /* FDMOD */
    assert_int_equal(REG(OTG_DCFG) & 3u, 3u);           /* full speed */
    assert_true((REG(OTG_GAHBCFG) & 1u) != 0u);
    assert_int_equal(REG(OTG_DCTL) & 2u, 0u); /* not soft-disconnected */
    assert_int_equal(REG(OTG_GRXFSIZ) + (REG(OTG_DIEPTXF0) >> 16) + (REG(OTG_DIEPTXF1) >> 16) <= 320u, 1);
    assert_true((REG(OTG_GINTMSK) & (OTG_GINT_RXFLVL | OTG_GINT_USBRST)) == (OTG_GINT_RXFLVL | OTG_GINT_USBRST));
}

static void test_reset_and_enumeration(void **state)
{
    (void)state;
    REG(OTG_GINTSTS) = OTG_GINT_USBRST;
    piezo_otgfs_irq(&dev);
    assert_int_equal(REG(OTG_DOEPTSIZ(0)) >> 29, 3u); /* three SETUPs */
    assert_true((REG(OTG_DOEPCTL(0)) & OTG_EPCTL_EPENA) != 0u);

    setup_request(0x80, 6, 0x0100, 64); /* GET_DESCRIPTOR device */
    assert_int_equal(REG(OTG_DIEPTSIZ(0)) & 0x7FFFFu, 18u);
    assert_int_equal(fotg.tx_len[0], 20u); /* 18 bytes in five words */
    assert_memory_equal(fotg.tx[0], piezo_usbd_device_desc, 18);

    setup_request(0x00, 5, 9, 0); /* SET_ADDRESS 9 */
    assert_int_equal((REG(OTG_DCFG) >> 4) & 0x7Fu, 9u);
    assert_int_equal(REG(OTG_DIEPTSIZ(0)) & 0x7FFFFu, 0u); /* status: ZLP */

    setup_request(0x00, 9, 1, 0); /* SET_CONFIGURATION 1 */
    assert_int_equal(dev.configuration, 1);
    assert_true((REG(OTG_DOEPCTL(1)) & OTG_EPCTL_USBAEP) != 0u);
    assert_int_equal((REG(OTG_DOEPCTL(1)) >> 18) & 3u, 2u); /* bulk */
    assert_int_equal((REG(OTG_DIEPCTL(1)) >> 22) & 0xFu, 1u); /* TX FIFO 1 */
    assert_true((REG(OTG_DOEPCTL(1)) & OTG_EPCTL_EPENA) != 0u); /* armed for a request */
}

static void test_a_request_on_bulk_out_is_answered_on_bulk_in(void **state)
{
    (void)state;
    setup_request(0x00, 5, 9, 0);
    setup_request(0x00, 9, 1, 0);
    fotg.tx_len[1] = 0u;
    const uint8_t req[] = {0xA5, 7, 5, 0, 0x04, 0x00, 0x00, 0x00, 0x01};
    fake_otg_rx(1u, OTG_RXSTS_OUT_DATA, req, sizeof req);
    fake_otg_rx(1u, OTG_RXSTS_OUT_DONE, NULL, 0u);
    piezo_otgfs_irq(&dev);
    assert_int_equal(REG(OTG_DIEPTSIZ(1)) & 0x7FFFFu, 8u);
    assert_int_equal(fotg.tx[1][0], 0xA5);
    assert_int_equal(fotg.tx[1][1], 7);
    assert_int_equal((fotg.tx[1][6] << 8) | fotg.tx[1][7], tregs_input_value(0));
    assert_true((REG(OTG_DOEPCTL(1)) & OTG_EPCTL_EPENA) != 0u); /* re-armed */
}

static void test_an_unsupported_request_stalls_ep0(void **state)
{
    (void)state;
    setup_request(0x40, 1, 0, 0); /* vendor request */
    assert_true((REG(OTG_DIEPCTL(0)) & OTG_EPCTL_STALL) != 0u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_init_puts_the_core_in_full_speed_device_mode, start),
        cmocka_unit_test_setup(test_reset_and_enumeration, start),
        cmocka_unit_test_setup(test_a_request_on_bulk_out_is_answered_on_bulk_in, start),
        cmocka_unit_test_setup(test_an_unsupported_request_stalls_ep0, start),
    };
    return cmocka_run_group_tests_name("usb_otgfs", tests, NULL, NULL);
}
