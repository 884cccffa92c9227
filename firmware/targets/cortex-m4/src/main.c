/*
 * main.c - the firmware image: board, control loop, Modbus RTU on USART1,
 * then the 10 kHz tick runs the control loop (piezo_control_tick) while the
 * background loop serves the line and the USB link (comm.c, usb_board.c).
 */
#include "board.h"
#include "comm.h"
#include "control.h"
#include "tick.h"
#include "uart.h"
#include "usb_board.h"

int main(void)
{
    piezo_board_init();
    piezo_uart_init(PIEZO_UART_BRR(PIEZO_MODBUS_BAUD));
    if (piezo_control_init() != 0) {
        piezo_board_fault("control init", 0);
    }
    /* the register map provisions the controller (stage, axis, unlock key)
     * before the stored table is loaded and checked against them */
    if (piezo_comm_init() != 0) {
        piezo_board_fault("comm init", 0);
    }
    /* USB on the same register map; without an OTG core (QEMU) init gives
     * up within its bounded waits and the image runs without USB */
    (void)piezo_usb_init(piezo_comm_regs());
    /* a stored table that does not load is reported by the status registers;
     * the unit then runs without one */
    (void)piezo_ctl_attach_store(&piezo_axis, piezo_control_storage());
    /* the controller parameters saved with params_command (sectors 8/9);
     * a record that does not load is reported (params_result,
     * params_ignored) and the board's defaults run */
    (void)piezo_regmap_attach_params(&piezo_comm_map, piezo_control_params_storage());
    piezo_tick_start(PIEZO_TICK_RELOAD);
    piezo_irq_enable();
    for (;;) {
        if (!piezo_comm_poll()) {
            piezo_wait_for_interrupt();
        }
    }
}
