/* USB bulk framing: header checks, sequence echo, reassembly from packets. */
#include <string.h>

#include "piezo_test.h"
#include "usb_bulk.h"
#include "test_modbus_regs.h"

static tregs_t bank;
static piezo_mb_regs_t regs;
static piezo_usb_rx_t rx;
static uint8_t rsp[PIEZO_USB_FRAME_MAX];

static int setup(void **state)
{
    (void)state;
    regs = tregs_init(&bank);
    piezo_usb_rx_init(&rx);
    return 0;
}

/* header + FC 16 writing n registers (v = 0x0100 + i) at 0x2000. */
static size_t write_req(uint8_t *f, uint8_t seq, uint16_t n)
{
    size_t pdu = 6u + 2u * n;
    f[0] = 0xA5; f[1] = seq; f[2] = (uint8_t)pdu; f[3] = (uint8_t)(pdu >> 8);
    f[4] = 0x10; f[5] = 0x20; f[6] = 0x00; f[7] = 0x00; f[8] = (uint8_t)n; f[9] = (uint8_t)(2 * n);
    for (uint16_t i = 0; i < n; i++) {
        f[10 + 2 * i] = 0x01;
        f[11 + 2 * i] = (uint8_t)i;
    }
    return 4u + pdu;
}

static void test_process_answers_with_echoed_sequence(void **state)
{
    (void)state;
    const uint8_t req[] = {0xA5, 0x37, 0x05, 0x00, 0x04, 0x00, 0x00, 0x00, 0x02};
    size_t n = piezo_usb_process(&regs, req, sizeof req, rsp, sizeof rsp);
    const uint8_t want[] = {0xA5, 0x37, 0x06, 0x00, 0x04, 0x04, 0x50, 0x5A, 0x40, 0x03};
    assert_int_equal(n, sizeof want);
    assert_memory_equal(rsp, want, sizeof want);
    /* exception responses travel the same way */
    const uint8_t bad[] = {0xA5, 0x38, 0x05, 0x00, 0x03, 0x00, 0x00, 0x00, 0x01};
    n = piezo_usb_process(&regs, bad, sizeof bad, rsp, sizeof rsp);
    const uint8_t ex[] = {0xA5, 0x38, 0x02, 0x00, 0x83, 0x02};
    assert_int_equal(n, sizeof ex);
    assert_memory_equal(rsp, ex, sizeof ex);
}

static void test_process_refuses_malformed_headers(void **state)
{
    (void)state;
    uint8_t req[] = {0xA5, 0x01, 0x05, 0x00, 0x04, 0x00, 0x00, 0x00, 0x01};
    uint8_t f[sizeof req];
    memcpy(f, req, sizeof f);
    f[0] = 0xA4;
    assert_int_equal(piezo_usb_process(&regs, f, sizeof f, rsp, sizeof rsp), 0);
    memcpy(f, req, sizeof f);
    f[2] = 0x04;  /* announces one byte less */
    assert_int_equal(piezo_usb_process(&regs, f, sizeof f, rsp, sizeof rsp), 0);
    f[2] = 0x06;  /* one byte more */
    assert_int_equal(piezo_usb_process(&regs, f, sizeof f, rsp, sizeof rsp), 0);
    f[2] = 0x05; f[3] = 0x01;  /* 261 */
    assert_int_equal(piezo_usb_process(&regs, f, sizeof f, rsp, sizeof rsp), 0);
    const uint8_t zero[] = {0xA5, 0x01, 0x00, 0x00};
    assert_int_equal(piezo_usb_process(&regs, zero, sizeof zero, rsp, sizeof rsp), 0);
    for (size_t n = 0; n < sizeof req; n++) {
        assert_int_equal(piezo_usb_process(&regs, req, n, rsp, sizeof rsp), 0);
    }
    assert_int_equal(piezo_usb_process(&regs, req, sizeof req, rsp, sizeof rsp - 1), 0);
    assert_int_equal(bank.calls_read_input, 0);
    assert_int_equal(piezo_usb_process(&regs, req, sizeof req, rsp, sizeof rsp), 8);
}

/* A request of 123 registers is 256 bytes: four full 64-byte packets and no
 * zero-length packet; the header's length completes it. */
static void test_feed_reassembles_full_packets(void **state)
{
    (void)state;
    uint8_t f[PIEZO_USB_FRAME_MAX];
    size_t n = write_req(f, 9, 123);
    assert_int_equal(n, 256);
    for (size_t off = 0; off < n; off += 64) {
        size_t got = piezo_usb_feed(&rx, &f[off], 64, 64, &regs, rsp, sizeof rsp);
        if (off + 64 < n) {
            assert_int_equal(got, 0);
            assert_int_equal(bank.calls_write_holding, 0);
        } else {
            assert_int_equal(got, 9);
        }
    }
    assert_int_equal(rsp[1], 9);
    assert_int_equal(rsp[4], 0x10);
    assert_int_equal(*tregs_holding(&bank, 0x207A), 0x017A);
    assert_int_equal(rx.dropped, 0);
}

static void test_feed_every_packet_size(void **state)
{
    (void)state;
    uint8_t f[PIEZO_USB_FRAME_MAX];
    size_t n = write_req(f, 1, 40);
    for (size_t mps = 1; mps <= 96; mps++) {
        size_t answers = 0;
        for (size_t off = 0; off < n; off += mps) {
            size_t k = n - off < mps ? n - off : mps;
            size_t got = piezo_usb_feed(&rx, &f[off], k, mps, &regs, rsp, sizeof rsp);
            if (got != 0) {
                answers++;
                assert_int_equal(off + k, n);
                assert_int_equal(got, 9);
            }
        }
        assert_int_equal(answers, 1);
    }
    assert_int_equal(rx.dropped, 0);
}

static void test_feed_drops_short_extra_and_bad(void **state)
{
    (void)state;
    uint8_t f[PIEZO_USB_FRAME_MAX + 1];
    size_t n = write_req(f, 2, 40);
    /* the transfer ends (short packet) before the announced length */
    assert_int_equal(piezo_usb_feed(&rx, f, 64, 64, &regs, rsp, sizeof rsp), 0);
    assert_int_equal(piezo_usb_feed(&rx, &f[64], 10, 64, &regs, rsp, sizeof rsp), 0);
    assert_int_equal(rx.dropped, 1);
    /* one byte more than announced in the same transfer */
    f[n] = 0x00;
    assert_int_equal(piezo_usb_feed(&rx, f, n + 1, 512, &regs, rsp, sizeof rsp), 0);
    assert_int_equal(rx.dropped, 2);
    /* bad magic */
    f[0] = 0x5A;
    assert_int_equal(piezo_usb_feed(&rx, f, n, 512, &regs, rsp, sizeof rsp), 0);
    assert_int_equal(rx.dropped, 3);
    assert_int_equal(bank.calls_write_holding, 0);
    /* and the next good request is answered */
    f[0] = 0xA5;
    assert_int_equal(piezo_usb_feed(&rx, f, n, 512, &regs, rsp, sizeof rsp), 9);
    /* a zero-length packet between requests is harmless */
    assert_int_equal(piezo_usb_feed(&rx, f, 0, 64, &regs, rsp, sizeof rsp), 0);
    assert_int_equal(rx.dropped, 3);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_process_answers_with_echoed_sequence, setup),
        cmocka_unit_test_setup(test_process_refuses_malformed_headers, setup),
        cmocka_unit_test_setup(test_feed_reassembles_full_packets, setup),
        cmocka_unit_test_setup(test_feed_every_packet_size, setup),
        cmocka_unit_test_setup(test_feed_drops_short_extra_and_bad, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
