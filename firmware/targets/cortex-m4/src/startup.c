/*
 * startup.c - vector table and reset handler for the STM32F405.
 *
 * Reset: enable the FPU (CP10, CP11: the hard-float ABI may use its registers
 * anywhere outside the core), copy .ramfunc and .data from flash, zero .bss,
 * set the stack canary, copy the vector table to RAM and point VTOR at the
 * copy, run main() and hand its status to piezo_board_exit().
 *
 * Why RAM: while a flash sector erases (1-2 s) or a word programs, every
 * fetch from the flash stalls (RM0090 section 3). The tick's vector, its handler
 * and everything it calls (link.ld's .ramfunc, checked by check_image.py
 * ram) then come from RAM, so the tick keeps running during a table commit.
 */
#include <stdint.h>

#include "board.h"

extern uint32_t piezo_data_start[], piezo_data_end[], piezo_data_load[];
extern uint32_t piezo_bss_start[], piezo_bss_end[];
extern uint32_t piezo_stack_top[], piezo_stack_limit[];
extern uint32_t piezo_ramfunc_start[], piezo_ramfunc_end[], piezo_ramfunc_load[];
extern uint32_t piezo_ram_vectors[];

int main(void);
void Reset_Handler(void);
void Default_Handler(void);
void HardFault_Handler(void);
void MemManage_Handler(void);
void BusFault_Handler(void);
void UsageFault_Handler(void);
void NMI_Handler(void);
void SysTick_Handler(void);
/* PendSV: the PIL image runs the stage model there (pil_stage.c); elsewhere unused. */
void PendSV_Handler(void) __attribute__((weak, alias("Default_Handler")));
void USART1_IRQHandler(void);
/* OTG FS: usb_board.c in the firmware and PIL images; elsewhere unused. */
void OTG_FS_IRQHandler(void) __attribute__((weak, alias("Default_Handler")));

#define PIEZO_STACK_CANARY 0x5AC4A11Eu

typedef void (*piezo_vector_t)(void);

/* Cortex-M4 exceptions 0..15, then the chip's interrupts (IRQ n at 16 + n). */
__attribute__((section(".vectors"), used))
const piezo_vector_t piezo_vector_table[16u + PIEZO_N_IRQ] = {
    [0] = (piezo_vector_t)(uintptr_t)piezo_stack_top,
    [1] = Reset_Handler,
    [2] = NMI_Handler,
    [3] = HardFault_Handler,
    [4] = MemManage_Handler,
    [5] = BusFault_Handler,
    [6] = UsageFault_Handler,
    [11] = Default_Handler, /* SVCall */
    [12] = Default_Handler, /* DebugMonitor */
    [14] = PendSV_Handler,
    [15] = SysTick_Handler,
    [16u + PIEZO_IRQ_USART1] = USART1_IRQHandler,
    [16u + PIEZO_IRQ_OTG_FS] = OTG_FS_IRQHandler,
};

void Reset_Handler(void)
{
    SCB_CPACR |= 0xFu << 20; /* CP10, CP11 full access */
    __asm volatile("dsb\n\tisb" ::: "memory");

    const uint32_t *code = piezo_ramfunc_load;
    for (uint32_t *dst = piezo_ramfunc_start; dst < piezo_ramfunc_end; dst++) {
        *dst = *code++;
    }
    const uint32_t *src = piezo_data_load;
    for (uint32_t *dst = piezo_data_start; dst < piezo_data_end; dst++) {
        *dst = *src++;
    }
    for (uint32_t *dst = piezo_bss_start; dst < piezo_bss_end; dst++) {
        *dst = 0u;
    }
    piezo_stack_limit[0] = PIEZO_STACK_CANARY;
    for (uint32_t i = 0; i < 16u + PIEZO_N_IRQ; i++) {
        piezo_ram_vectors[i] = (uint32_t)(uintptr_t)piezo_vector_table[i];
    }
    __asm volatile("dsb" ::: "memory");
    SCB_VTOR = (uint32_t)(uintptr_t)piezo_ram_vectors;
    __asm volatile("dsb\n\tisb" ::: "memory");

    piezo_board_exit(main());
}

int piezo_board_stack_intact(void)
{
    return piezo_stack_limit[0] == PIEZO_STACK_CANARY;
}

/* Unused vector slots are 0 in the table; a stray interrupt that has a vector
 * lands here. */
void Default_Handler(void)
{
    piezo_board_fault("unexpected interrupt", 0);
}

void NMI_Handler(void)
{
    piezo_board_fault("NMI", 0);
}

/* Faults: r1 = the stacked frame (r0-r3, r12, lr, pc, xpsr) on MSP or PSP,
 * r0 = which fault; then report it. */
void piezo_fault_entry(uint32_t kind, const uint32_t *frame) __attribute__((noreturn, used));
void piezo_fault_entry(uint32_t kind, const uint32_t *frame)
{
    static const char *const names[] = {"HardFault", "MemManage", "BusFault", "UsageFault"};
    piezo_board_fault(names[kind & 3u], frame);
}

#define PIEZO_FAULT_HANDLER(fn, kind)                                            \
    __attribute__((naked)) void fn(void)                                         \
    {                                                                            \
        __asm volatile("movs r0, #" #kind "\n\t"                                 \
                       "tst lr, #4\n\t"                                          \
                       "ite eq\n\t"                                              \
                       "mrseq r1, msp\n\t"                                       \
                       "mrsne r1, psp\n\t"                                       \
                       "b piezo_fault_entry\n\t");                               \
    }

PIEZO_FAULT_HANDLER(HardFault_Handler, 0)
PIEZO_FAULT_HANDLER(MemManage_Handler, 1)
PIEZO_FAULT_HANDLER(BusFault_Handler, 2)
PIEZO_FAULT_HANDLER(UsageFault_Handler, 3)
