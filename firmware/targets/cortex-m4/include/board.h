/*
 * board.h - board support for the Cortex-M4 target: an STM32F405RG at 168 MHz,
 * the chip of QEMU's netduinoplus2 machine (1 MiB flash at 0x08000000, SRAM at
 * 0x20000000; we use the 128 KiB that real silicon has there).
 *
 * Registers are named after the ARMv7-M Architecture Reference Manual (SCB,
 * SysTick, NVIC) and ST's RM0090 (RCC, FLASH, GPIO, USART).
 */
#ifndef PIEZO_BOARD_H
#define PIEZO_BOARD_H

#include <stdint.h>

#define PIEZO_BOARD_NAME "netduinoplus2 / STM32F405RG"

/* Clocks. SYSCLK from the PLL on HSI (RM0090 6.3.2); QEMU fixes it at 168 MHz. */
#define PIEZO_SYSCLK_HZ 168000000u
#define PIEZO_APB2_HZ (PIEZO_SYSCLK_HZ / 2u) /* USART1 */

/* The control tick. SysTick counts the processor clock (CLKSOURCE = 1). */
#define PIEZO_TICK_HZ 10000u
#define PIEZO_TICK_RELOAD (PIEZO_SYSCLK_HZ / PIEZO_TICK_HZ - 1u) /* 16799 */

/* Memory map (link.ld uses the same numbers). */
#define PIEZO_FLASH_BASE 0x08000000u
#define PIEZO_FLASH_SIZE (1024u * 1024u)
#define PIEZO_RAM_BASE 0x20000000u
#define PIEZO_RAM_SIZE (128u * 1024u)

#define PIEZO_REG(addr) (*(volatile uint32_t *)(addr))

/* System control block, ARMv7-M B3.2 */
#define SCB_VTOR PIEZO_REG(0xE000ED08u)
#define SCB_AIRCR PIEZO_REG(0xE000ED0Cu)
#define SCB_SHPR3 PIEZO_REG(0xE000ED20u)
#define SCB_CPACR PIEZO_REG(0xE000ED88u)
#define SCB_CFSR PIEZO_REG(0xE000ED28u)
#define SCB_HFSR PIEZO_REG(0xE000ED2Cu)

/* SysTick, ARMv7-M B3.3 */
#define SYST_CSR PIEZO_REG(0xE000E010u)
#define SYST_RVR PIEZO_REG(0xE000E014u)
#define SYST_CVR PIEZO_REG(0xE000E018u)
#define SYST_CSR_ENABLE (1u << 0)
#define SYST_CSR_TICKINT (1u << 1)
#define SYST_CSR_CLKSOURCE (1u << 2)
#define SYST_CSR_COUNTFLAG (1u << 16)

/* NVIC, ARMv7-M B3.4 */
#define NVIC_ISER(n) PIEZO_REG(0xE000E100u + 4u * (n))
#define NVIC_ICER(n) PIEZO_REG(0xE000E180u + 4u * (n))
#define NVIC_IPR8(irq) (*(volatile uint8_t *)(0xE000E400u + (irq)))

/* STM32F405 interrupt numbers (RM0090 table 61) */
#define PIEZO_IRQ_USART1 37u
#define PIEZO_IRQ_OTG_FS 67u /* the same in usb_board.h */
#define PIEZO_N_IRQ 82u

/* Priorities (upper 4 bits implemented): the tick preempts everything else. */
#define PIEZO_PRIO_TICK 0x00u
#define PIEZO_PRIO_UART 0x40u

/** Interrupts on and off around short critical sections. */
static inline void piezo_irq_disable(void) { __asm volatile("cpsid i" ::: "memory"); }
static inline void piezo_irq_enable(void) { __asm volatile("cpsie i" ::: "memory"); }
static inline void piezo_wait_for_interrupt(void) { __asm volatile("wfi" ::: "memory"); }

/* piezo_board_status() bits */
#define PIEZO_BOARD_PLL_LOCKED 1u  /* the PLL locked and SYSCLK switched to it */

/**
 * Clock tree for 168 MHz from the internal 16 MHz oscillator: flash wait
 * states, PLL (M 16, N 336, P 2, Q 7), AHB /1, APB1 /4, APB2 /2. The waits
 * for the PLL are bounded: QEMU does not model the RCC (its reads are 0, and
 * its SYSCLK is 168 MHz anyway), so there the waits time out and the board
 * goes on without PIEZO_BOARD_PLL_LOCKED.
 */
void piezo_board_init(void);
uint32_t piezo_board_status(void);

/** What the program does when main() returns (semihosting exit in test images). */
void piezo_board_exit(int status) __attribute__((noreturn));

/** Fault report hook: test images print it over semihosting. */
void piezo_board_fault(const char *what, const uint32_t *frame) __attribute__((noreturn));

/** Stack overflow canary at the bottom of the stack: 1 while intact. */
int piezo_board_stack_intact(void);

#endif /* PIEZO_BOARD_H */
