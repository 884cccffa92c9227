/*
 * The 10 kHz tick on SysTick, against QEMU's emulated clock. qemu-run uses
 * -icount shift=0: one instruction is one nanosecond of emulated time, so a
 * loop of a known number of instructions is a known time, and SysTick at
 * 168 MHz counts 168 per 1000 instructions.
 */
#include "piezo_test.h"

#include "board.h"
#include "tick.h"

static volatile uint32_t hook_calls;
static volatile uint32_t hook_bad_ipsr;
static volatile uint32_t hook_bad_order;

/* The control loop's hook: must run in the SysTick exception (IPSR 15), once
 * per tick, after the count went up. */
void piezo_control_tick(void)
{
    uint32_t ipsr;
    __asm volatile("mrs %0, ipsr" : "=r"(ipsr));
    if (ipsr != 15u) {
        hook_bad_ipsr = hook_bad_ipsr + 1u;
    }
    hook_calls = hook_calls + 1u;
    if (piezo_tick_count() != hook_calls) {
        hook_bad_order = hook_bad_order + 1u;
    }
}

/* Exactly 2 * n instructions (n >= 1): subs, bne. */
static void spin(uint32_t n)
{
    __asm volatile("1: subs %0, %0, #1\n\t"
                   "bne 1b"
                   : "+r"(n)
                   :
                   : "cc");
}

static int setup(void **state)
{
    (void)state;
    hook_calls = 0u;
    hook_bad_ipsr = 0u;
    hook_bad_order = 0u;
    piezo_irq_enable();
    piezo_tick_start(PIEZO_TICK_RELOAD);
    return 0;
}

static int teardown(void **state)
{
    (void)state;
    piezo_tick_stop();
    return 0;
}

static void test_systick_is_programmed_for_10khz_at_top_priority(void **state)
{
    (void)state;
    assert_int_equal(PIEZO_TICK_RELOAD, 16799);
    assert_int_equal(SYST_RVR, 16799);
    assert_int_equal(SYST_CSR & 7u, SYST_CSR_CLKSOURCE | SYST_CSR_TICKINT | SYST_CSR_ENABLE);
    assert_int_equal(SCB_SHPR3 >> 24, PIEZO_PRIO_TICK);
}

static void test_counter_runs_at_168_mhz_of_emulated_time(void **state)
{
    (void)state;
    /* 40000 instructions = 40 us = 6720 counts, read without interrupts; the
     * reads and the loop's entry add at most 8 instructions (2 counts). */
    piezo_irq_disable();
    uint32_t c0 = SYST_CVR;
    spin(20000u);
    uint32_t c1 = SYST_CVR;
    piezo_irq_enable();
    uint32_t counted = c0 >= c1 ? c0 - c1 : c0 + PIEZO_TICK_RELOAD + 1u - c1;
    print_message("SysTick: %lu counts in 40000 instructions\n", (unsigned long)counted);
    assert_in_range(counted, 6720, 6722);
}

static void test_ticks_come_every_100_us(void **state)
{
    (void)state;
    /* 2,000,000 instructions = 2 ms: 20 tick periods, and the handlers'
     * own instructions (under 100 per tick) can add at most one more. */
    uint32_t t0 = piezo_tick_count();
    spin(1000000u);
    uint32_t t1 = piezo_tick_count();
    print_message("%lu ticks in 2 ms\n", (unsigned long)(t1 - t0));
    assert_in_range(t1 - t0, 20, 21);
}

static void test_hook_runs_once_per_tick_in_the_systick_handler(void **state)
{
    (void)state;
    uint32_t start = piezo_tick_count();
    while (piezo_tick_count() - start < 1000u) {
        piezo_wait_for_interrupt();
    }
    piezo_irq_disable();
    uint32_t ticks = piezo_tick_count();
    uint32_t calls = hook_calls;
    piezo_irq_enable();
    assert_true(ticks >= 1000u);
    assert_int_equal(calls, ticks);
    assert_int_equal(hook_bad_ipsr, 0);
    assert_int_equal(hook_bad_order, 0);
}

static void test_stopped_tick_does_not_count(void **state)
{
    (void)state;
    spin(200000u); /* some ticks first */
    piezo_tick_stop();
    uint32_t t0 = piezo_tick_count();
    assert_true(t0 >= 3u);
    spin(1000000u);
    assert_int_equal(piezo_tick_count(), t0);
    assert_int_equal(SYST_CSR & SYST_CSR_ENABLE, 0);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup_teardown(test_systick_is_programmed_for_10khz_at_top_priority, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_counter_runs_at_168_mhz_of_emulated_time, setup, teardown),
        cmocka_unit_test_setup_teardown(test_ticks_come_every_100_us, setup, teardown),
        cmocka_unit_test_setup_teardown(test_hook_runs_once_per_tick_in_the_systick_handler, setup,
                                        teardown),
        cmocka_unit_test_setup_teardown(test_stopped_tick_does_not_count, setup, teardown),
    };
    return cmocka_run_group_tests_name("tick", tests, NULL, NULL);
}
