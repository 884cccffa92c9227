/* uart.c - USART1 driver (see uart.h; RM0090 section 30).
 *
 * Transmit by interrupt, and what QEMU 7.2 models of it: its stm32f2xx_usart
 * writes a data-register byte to the character device at once, keeps TXE and
 * TC set, and raises its interrupt only for RXNE (TXEIE and TCIE are stored
 * but never interrupt). So the driver (1) pends USART1 in the NVIC when it
 * starts a frame, besides setting TXEIE (on silicon TXEIE alone interrupts:
 * the extra pending entry finds TXE set and sends the first byte, or finds
 * nothing to do); (2) refills the data register in a loop while TXE is set
 * (one or two bytes per interrupt on silicon, the whole frame under QEMU);
 * (3) after the last byte ends the frame at once when TC is already set
 * (QEMU), else waits for the TC interrupt (silicon). */
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

#define NVIC_ISPR(n) PIEZO_REG(0xE000E200u + 4u * (n))

/* RM0090 30.6.1 (USART_SR) and 30.6.4 (USART_CR1) */
#define SR_ORE (1u << 3)
#define SR_RXNE (1u << 5)
#define SR_TC (1u << 6)
#define SR_TXE (1u << 7)
#define CR1_RE (1u << 2)
#define CR1_TE (1u << 3)
#define CR1_RXNEIE (1u << 5)
#define CR1_TCIE (1u << 6)
#define CR1_TXEIE (1u << 7)
#define CR1_UE (1u << 13)

#if (PIEZO_UART_RX_SIZE & (PIEZO_UART_RX_SIZE - 1u)) != 0
#error "PIEZO_UART_RX_SIZE must be a power of two"
#endif

static uint8_t rx_buf[PIEZO_UART_RX_SIZE];
static uint32_t rx_stamp[PIEZO_UART_RX_SIZE];
static volatile uint32_t rx_head; /* written by the interrupt */
static volatile uint32_t rx_tail; /* written by the reader */
static volatile uint32_t rx_tick;
static volatile uint32_t rx_dropped;

static uint8_t tx_buf[PIEZO_UART_TX_SIZE];
static volatile uint32_t tx_len;  /* bytes of the frame being sent */
static volatile uint32_t tx_pos;  /* next byte to the data register */
static volatile uint32_t tx_busy; /* 1 from send until TC after the last byte */

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
    tx_len = 0u;
    tx_pos = 0u;
    tx_busy = 0u;
    USART1_CR1 = CR1_UE | CR1_TE | CR1_RE | CR1_RXNEIE;
    (void)USART1_SR;
    (void)USART1_DR;

    NVIC_IPR8(PIEZO_IRQ_USART1) = PIEZO_PRIO_UART;
    NVIC_ISER(PIEZO_IRQ_USART1 / 32u) = 1u << (PIEZO_IRQ_USART1 % 32u);
}

int piezo_uart_send(const uint8_t *data, size_t n)
{
    if (tx_busy != 0u || n > PIEZO_UART_TX_SIZE) {
        return -1;
    }
    if (n == 0u) {
        return 0;
    }
    for (size_t i = 0; i < n; i++) {
        tx_buf[i] = data[i];
    }
    tx_len = (uint32_t)n;
    tx_pos = 0u;
    tx_busy = 1u;
    /* CR1 is also written by the interrupt: no interrupt between read and write */
    NVIC_ICER(PIEZO_IRQ_USART1 / 32u) = 1u << (PIEZO_IRQ_USART1 % 32u);
    USART1_CR1 = (USART1_CR1 & ~CR1_TCIE) | CR1_TXEIE;
    NVIC_ISER(PIEZO_IRQ_USART1 / 32u) = 1u << (PIEZO_IRQ_USART1 % 32u);
    NVIC_ISPR(PIEZO_IRQ_USART1 / 32u) = 1u << (PIEZO_IRQ_USART1 % 32u); /* QEMU 7.2: see above */
    return 0;
}

int piezo_uart_tx_busy(void)
{
    return tx_busy != 0u;
}

void piezo_uart_write(const uint8_t *data, size_t n)
{
    while (n > 0u) {
        size_t k = n < PIEZO_UART_TX_SIZE ? n : PIEZO_UART_TX_SIZE;
        while (piezo_uart_send(data, k) != 0) {
        }
        data += k;
        n -= k;
    }
    while (piezo_uart_tx_busy()) {
    }
}

int piezo_uart_get(uint8_t *byte, uint32_t *tick)
{
    uint32_t tail = rx_tail;
    if (tail == rx_head) {
        return 0;
    }
    *byte = rx_buf[tail & (PIEZO_UART_RX_SIZE - 1u)];
    *tick = rx_stamp[tail & (PIEZO_UART_RX_SIZE - 1u)];
    rx_tail = tail + 1u;
    return 1;
}

int piezo_uart_getc(void)
{
    uint8_t b;
    uint32_t t;
    return piezo_uart_get(&b, &t) ? (int)b : -1;
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

static void uart_rx(uint32_t sr)
{
    uint8_t c = (uint8_t)USART1_DR; /* reading DR clears RXNE and ORE */
    uint32_t now = piezo_tick_count();
    if ((sr & SR_ORE) != 0u) {
        rx_dropped = rx_dropped + 1u;
    }
    uint32_t head = rx_head;
    if (head - rx_tail < PIEZO_UART_RX_SIZE) {
        rx_buf[head & (PIEZO_UART_RX_SIZE - 1u)] = c;
        rx_stamp[head & (PIEZO_UART_RX_SIZE - 1u)] = now;
        rx_head = head + 1u;
    } else {
        rx_dropped = rx_dropped + 1u;
    }
    rx_tick = now;
}

static void uart_tx(uint32_t cr1)
{
    if ((cr1 & CR1_TXEIE) != 0u) {
        uint32_t pos = tx_pos;
        while (pos < tx_len && (USART1_SR & SR_TXE) != 0u) {
            USART1_DR = tx_buf[pos];
            pos++;
        }
        tx_pos = pos;
        if (pos < tx_len) {
            return; /* the next TXE interrupt continues */
        }
        cr1 = (cr1 & ~CR1_TXEIE) | CR1_TCIE;
        USART1_CR1 = cr1;
    }
    if ((cr1 & CR1_TCIE) != 0u && (USART1_SR & SR_TC) != 0u) {
        USART1_CR1 = cr1 & ~CR1_TCIE;
        tx_busy = 0u;
    }
}

void USART1_IRQHandler(void);
void USART1_IRQHandler(void)
{
    uint32_t sr = USART1_SR;
    if ((sr & (SR_RXNE | SR_ORE)) != 0u) {
        uart_rx(sr);
    }
    if (tx_busy != 0u) {
        uart_tx(USART1_CR1);
    }
}
