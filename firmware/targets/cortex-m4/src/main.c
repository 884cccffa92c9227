/*
 * main.c - the firmware image: board, Modbus UART, then the 10 kHz tick runs
 * the control loop (piezo_control_tick) while the background loop serves the
 * line.
 */
#include "board.h"
#include "control.h"
#include "tick.h"
#include "uart.h"

#define PIEZO_MODBUS_BAUD 115200u

/* The Modbus RTU framer (another issue) takes the received bytes; until it is
 * there they are dropped. */
__attribute__((weak)) void piezo_comm_byte(uint8_t byte, uint32_t tick);
__attribute__((weak)) void piezo_comm_byte(uint8_t byte, uint32_t tick)
{
    (void)byte;
    (void)tick;
}

int main(void)
{
    piezo_board_init();
    piezo_uart_init(PIEZO_UART_BRR(PIEZO_MODBUS_BAUD));
    if (piezo_control_init() != 0) {
        piezo_board_fault("control init", 0);
    }
    piezo_tick_start(PIEZO_TICK_RELOAD);
    piezo_irq_enable();
    for (;;) {
        int c = piezo_uart_getc();
        if (c >= 0) {
            piezo_comm_byte((uint8_t)c, piezo_uart_last_rx_tick());
        } else {
            piezo_wait_for_interrupt();
        }
    }
}
