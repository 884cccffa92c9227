/* tick.c - the 10 kHz control tick on SysTick (see tick.h). */
#include "board.h"
#include "tick.h"

static volatile uint32_t tick_count;
static volatile uint32_t tick_time_last; /* cycles from the SysTick wrap to the end of the tick's work */
static volatile uint32_t tick_time_max;
static volatile uint32_t tick_reload;

void piezo_tick_start(uint32_t reload)
{
    SYST_CSR = 0u;
    SYST_RVR = reload & 0x00FFFFFFu;
    SYST_CVR = 0u; /* any write clears the counter: the first period is full */
    SCB_SHPR3 = (SCB_SHPR3 & 0x00FFFFFFu) | ((uint32_t)PIEZO_PRIO_TICK << 24);
    tick_count = 0u;
    tick_reload = reload & 0x00FFFFFFu;
    tick_time_last = 0u;
    tick_time_max = 0u;
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
uint32_t piezo_tick_time_cycles(void)
{
    return tick_time_last;
}

uint32_t piezo_tick_time_max_cycles(void)
{
    return tick_time_max;
}

void piezo_tick_time_reset(void)
{
    tick_time_max = 0u;
}

/* The tick's time is measured from the instant it was due (the counter's
 * wrap to the reload value) to the end of its work, so it includes the
 * latency of the exception entry and any time the tick waited behind a
 * masked section: a tick that ends before the next one is due took less than
 * one period. COUNTFLAG is cleared on entry (reading CSR clears it); set again
 * at the end, the counter wrapped during the work: one more period. */
void SysTick_Handler(void)
{
    (void)SYST_CSR;
    tick_count = tick_count + 1u;
    piezo_control_tick();
    uint32_t cvr = SYST_CVR;
    uint32_t t = tick_reload - cvr + 1u;
    if ((SYST_CSR & SYST_CSR_COUNTFLAG) != 0u) {
        t += tick_reload + 1u;
    }
    tick_time_last = t;
    if (t > tick_time_max) {
        tick_time_max = t;
    }
}
