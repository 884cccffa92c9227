/*
 * uart.h - USART1 (PA9 TX, PA10 RX), 8N1, the Modbus RTU line.
 *
 * Receive is interrupt driven (RXNE) into a ring of PIEZO_UART_RX_SIZE bytes
 * (a power of two: indices wrap by mask). Each byte is stored with the tick
 * count at which the interrupt took it: the RTU framer measures its
 * 3.5-character silence from these stamps (uart.c says why ticks).
 *
 * Transmit is interrupt driven too: piezo_uart_send() copies a frame into the
 * transmit buffer and returns; the USART1 interrupt refills the data register
 * on TXE and ends the frame on TC. The background loop never waits on the
 * line, so neither the tick nor the receiver is delayed by an answer.
 * piezo_uart_write() is the blocking form (send, then wait until idle) for
 * test images.
 */
#ifndef PIEZO_UART_H
#define PIEZO_UART_H

#include <stddef.h>
#include <stdint.h>

#define PIEZO_UART_RX_SIZE 512u
#define PIEZO_UART_TX_SIZE 256u /* one RTU frame [SL 2.5.1] */

/** BRR value for a baud rate on the 84 MHz APB2 clock, oversampling by 16. */
#define PIEZO_UART_BRR(baud) ((PIEZO_APB2_HZ + (baud) / 2u) / (baud))

/** Configure pins, baud rate and the receive interrupt; drops pending input and output. */
void piezo_uart_init(uint32_t brr);

/** Queue n bytes (n <= PIEZO_UART_TX_SIZE) for transmission by interrupt.
 *  Returns 0, or -1 (nothing queued) while a frame is still being sent or n is too big. */
int piezo_uart_send(const uint8_t *data, size_t n);

/** 1 while a frame queued by piezo_uart_send() is not completely on the line (TC). */
int piezo_uart_tx_busy(void);

/** Send n bytes and wait until they are on the line (test images). */
void piezo_uart_write(const uint8_t *data, size_t n);

/** Next received byte and its tick stamp: 1, or 0 when none is waiting. */
int piezo_uart_get(uint8_t *byte, uint32_t *tick);

/** Next received byte, or -1 when none is waiting. */
int piezo_uart_getc(void);

/** Bytes waiting in the receive buffer. */
size_t piezo_uart_available(void);

/** Tick count when the last byte arrived. */
uint32_t piezo_uart_last_rx_tick(void);

/** Bytes lost: receive buffer full or hardware overrun. */
uint32_t piezo_uart_dropped(void);

#endif /* PIEZO_UART_H */
