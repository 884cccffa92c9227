/*
 * USART1 through QEMU's serial port (run by uart_harness.py): once the UART
 * is up the image says "ready\n"; then the host sends every byte value 0..255
 * in order, the image checks what arrived and sends them back in reverse order
 * followed by "uart ok\n", which the harness checks.
 */
#include "piezo_test.h"

#include "board.h"
#include "tick.h"
#include "uart.h"

#define USART1_BRR PIEZO_REG(0x40011008u)
#define USART1_CR1 PIEZO_REG(0x4001100Cu)
#define N_BYTES 256u
#define TIMEOUT_TICKS 100000u /* 10 s */

static uint8_t got[N_BYTES];

static void test_baud_rate_register_for_115200(void **state)
{
    (void)state;
    piezo_uart_init(PIEZO_UART_BRR(115200u));
    /* 84 MHz / 115200 = 729.17: mantissa 45, fraction 9 */
    assert_int_equal(USART1_BRR, 729);
    assert_int_equal(USART1_CR1 & 0x202Cu, 0x202Cu); /* UE, RXNEIE, TE, RE */
    piezo_uart_write((const uint8_t *)"ready\n", 6u);
}

static void test_receives_every_byte_value_in_order(void **state)
{
    (void)state;
    uint32_t start = piezo_tick_count();
    size_t n = 0;
    while (n < N_BYTES && piezo_tick_count() - start < TIMEOUT_TICKS) {
        int c = piezo_uart_getc();
        if (c < 0) {
            piezo_wait_for_interrupt();
            continue;
        }
        got[n++] = (uint8_t)c;
    }
    print_message("received %lu bytes in %lu ticks\n", (unsigned long)n,
                  (unsigned long)(piezo_tick_count() - start));
    assert_int_equal(n, N_BYTES);
    for (size_t i = 0; i < N_BYTES; i++) {
        assert_int_equal(got[i], i);
    }
    assert_int_equal(piezo_uart_dropped(), 0);
    assert_int_equal(piezo_uart_available(), 0);
    assert_int_equal(piezo_uart_getc(), -1);
    uint32_t stamp = piezo_uart_last_rx_tick();
    assert_true(stamp - start <= piezo_tick_count() - start); /* stamped within the wait */
}

static void test_sends_bytes_back(void **state)
{
    (void)state;
    uint8_t back[N_BYTES];
    for (size_t i = 0; i < N_BYTES; i++) {
        back[i] = got[N_BYTES - 1u - i];
    }
    piezo_uart_write(back, N_BYTES);
    piezo_uart_write((const uint8_t *)"uart ok\n", 8u);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_baud_rate_register_for_115200),
        cmocka_unit_test(test_receives_every_byte_value_in_order),
        cmocka_unit_test(test_sends_bytes_back),
    };
    piezo_irq_enable();
    piezo_tick_start(PIEZO_TICK_RELOAD);
    return cmocka_run_group_tests_name("uart", tests, NULL, NULL);
}
