/* uart.c - USART1 driver (see uart.h; RM0090 section 30). */
#include "board.h"
#include "tick.h"
#include "uart.h"

#define RCC_AHB1ENR PIEZO_REG(0x40023830u)
#define RCC_APB2ENR PIEZO_REG(0x40023844u)
#define GPIOA_MODER PIEZO_REG(0x40020000u)
#define GPIOA_AFRH PIEZO_REG(0x40020024u)

#define USART1_SR PIEZO_REG(0x40011000u)
#define USART1_DR PIEZO_REG(0x40011004u)
#define USART1_BRR PIEZO_REG(0x40011008u)
#define USART1_CR1 PIEZO_REG(0x4001100Cu)
#define USART1_CR2 PIEZO_REG(0x40011010u)
#define USART1_CR3 PIEZO_REG(0x40011014u)

#define SR_ORE (1u << 3)
#define SR_RXNE (1u << 5)
#define SR_TXE (1u << 7)
#define CR1_RE (1u << 2)
#define CR1_TE (1u << 3)
#define CR1_RXNEIE (1u << 5)
#define CR1_UE (1u << 13)

#if (PIEZO_UART_RX_SIZE & (PIEZO_UART_RX_SIZE - 1u)) != 0
#error "PIEZO_UART_RX_SIZE must be a power of two"
#endif

static uint8_t rx_buf[PIEZO_UART_RX_SIZE];
static volatile uint32_t rx_head; /* written by the interrupt */
static volatile uint32_t rx_tail; /* written by the reader */
static volatile uint32_t rx_tick;
static volatile uint32_t rx_dropped;

void piezo_uart_init(uint32_t brr)
{
    NVIC_ICER(PIEZO_IRQ_USART1 / 32u) = 1u << (PIEZO_IRQ_USART1 % 32u);
    RCC_AHB1ENR |= 1u << 0;  /* GPIOA */
    RCC_APB2ENR |= 1u << 4;  /* USART1 */
    /* PA9, PA10: alternate function 7 */
    GPIOA_MODER = (GPIOA_MODER & ~(0xFu << 18)) | (0xAu << 18);
    GPIOA_AFRH = (GPIOA_AFRH & ~0xFF0u) | (0x77u << 4);

    USART1_CR1 = 0u;
    USART1_BRR = brr;
    USART1_CR2 = 0u; /* 1 stop bit */
    USART1_CR3 = 0u;
    rx_head = 0u;
    rx_tail = 0u;
    rx_dropped = 0u;
    USART1_CR1 = CR1_UE | CR1_TE | CR1_RE | CR1_RXNEIE;
    (void)USART1_SR;
    (void)USART1_DR;

    NVIC_IPR8(PIEZO_IRQ_USART1) = PIEZO_PRIO_UART;
    NVIC_ISER(PIEZO_IRQ_USART1 / 32u) = 1u << (PIEZO_IRQ_USART1 % 32u);
}

void piezo_uart_write(const uint8_t *data, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        while ((USART1_SR & SR_TXE) == 0u) {
        }
        USART1_DR = data[i];
    }
}

int piezo_uart_getc(void)
{
    uint32_t tail = rx_tail;
    if (tail == rx_head) {
        return -1;
    }
    int c = rx_buf[tail & (PIEZO_UART_RX_SIZE - 1u)];
    rx_tail = tail + 1u;
    return c;
}

size_t piezo_uart_available(void)
{
    return (size_t)(rx_head - rx_tail);
}

uint32_t piezo_uart_last_rx_tick(void)
{
    return rx_tick;
}

uint32_t piezo_uart_dropped(void)
{
    return rx_dropped;
}

void USART1_IRQHandler(void);
void USART1_IRQHandler(void)
{
    uint32_t sr = USART1_SR;
    if ((sr & (SR_RXNE | SR_ORE)) != 0u) {
        uint8_t c = (uint8_t)USART1_DR; /* reading DR clears RXNE and ORE */
        if ((sr & SR_ORE) != 0u) {
            rx_dropped = rx_dropped + 1u;
        }
        uint32_t head = rx_head;
        if (head - rx_tail < PIEZO_UART_RX_SIZE) {
            rx_buf[head & (PIEZO_UART_RX_SIZE - 1u)] = c;
            rx_head = head + 1u;
        } else {
            rx_dropped = rx_dropped + 1u;
        }
        rx_tick = piezo_tick_count();
    }
}
