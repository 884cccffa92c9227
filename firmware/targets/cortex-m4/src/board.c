/* board.c - clock tree of the STM32F405 (RM0090 section 6). */
#include "board.h"

#define RCC_CR PIEZO_REG(0x40023800u)
#define RCC_PLLCFGR PIEZO_REG(0x40023804u)
#define RCC_CFGR PIEZO_REG(0x40023808u)
#define FLASH_ACR PIEZO_REG(0x40023C00u)

#define RCC_CR_HSIRDY (1u << 1)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_CFGR_SW_PLL 2u
#define RCC_CFGR_SWS_MASK (3u << 2)
#define RCC_CFGR_SWS_PLL (2u << 2)

/* Polls before giving up on a clock flag (far longer than silicon needs). */
#define PIEZO_CLOCK_WAIT 100000u

static uint32_t board_status;

static int wait_set(volatile uint32_t *reg, uint32_t mask, uint32_t value)
{
    for (uint32_t i = 0; i < PIEZO_CLOCK_WAIT; i++) {
        if ((*reg & mask) == value) {
            return 1;
        }
    }
    return 0;
}

void piezo_board_init(void)
{
    board_status = 0u;
    if (!wait_set(&RCC_CR, RCC_CR_HSIRDY, RCC_CR_HSIRDY)) {
        return;
    }
    /* 5 wait states for 168 MHz at 2.7-3.6 V; prefetch, I- and D-cache on. */
    FLASH_ACR = 5u | (1u << 8) | (1u << 9) | (1u << 10);
    /* AHB /1, APB1 /4 (42 MHz), APB2 /2 (84 MHz) */
    RCC_CFGR = (RCC_CFGR & ~0xFCF0u) | (5u << 10) | (4u << 13);
    /* HSI 16 MHz / M 16 * N 336 / P 2 = 168 MHz; Q 7 gives 48 MHz for USB. */
    RCC_PLLCFGR = 16u | (336u << 6) | (0u << 16) | (7u << 24);
    RCC_CR |= RCC_CR_PLLON;
    if (!wait_set(&RCC_CR, RCC_CR_PLLRDY, RCC_CR_PLLRDY)) {
        return;
    }
    RCC_CFGR = (RCC_CFGR & ~3u) | RCC_CFGR_SW_PLL;
    if (wait_set(&RCC_CFGR, RCC_CFGR_SWS_MASK, RCC_CFGR_SWS_PLL)) {
        board_status |= PIEZO_BOARD_PLL_LOCKED;
    }
}

uint32_t piezo_board_status(void)
{
    return board_status;
}
