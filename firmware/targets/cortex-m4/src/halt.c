/*
 * halt.c - exit and fault behaviour of the firmware image (test images use
 * semihost.c instead). No debugger is attached on a board: stop the tick so
 * the control loop no longer drives the stage, and wait for a reset.
 */
#include "board.h"

static void halt(void) __attribute__((noreturn));
static void halt(void)
{
    piezo_irq_disable();
    SYST_CSR = 0u;
    for (;;) {
        piezo_wait_for_interrupt();
    }
}

void piezo_board_exit(int status)
{
    (void)status;
    halt();
}

void piezo_board_fault(const char *what, const uint32_t *frame)
{
    (void)what;
    (void)frame;
    halt();
}
