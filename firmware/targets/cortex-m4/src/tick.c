/* tick.c - the 10 kHz control tick on SysTick (see tick.h). */
#include "board.h"
#include "tick.h"

static volatile uint32_t tick_count;

void piezo_tick_start(uint32_t reload)
{
    SYST_CSR = 0u;
    SYST_RVR = reload & 0x00FFFFFFu;
    SYST_CVR = 0u; /* any write clears the counter: the first period is full */
    SCB_SHPR3 = (SCB_SHPR3 & 0x00FFFFFFu) | ((uint32_t)PIEZO_PRIO_TICK << 24);
    tick_count = 0u;
    SYST_CSR = SYST_CSR_CLKSOURCE | SYST_CSR_TICKINT | SYST_CSR_ENABLE;
}

void piezo_tick_stop(void)
{
    SYST_CSR = 0u;
}

uint32_t piezo_tick_count(void)
{
    return tick_count;
}

/* Test images without the control loop (src/control.c defines it in the
 * firmware image and the benchmark). */
__attribute__((weak)) void piezo_control_tick(void)
{
}

void SysTick_Handler(void);
void SysTick_Handler(void)
{
    tick_count = tick_count + 1u;
    piezo_control_tick();
}
