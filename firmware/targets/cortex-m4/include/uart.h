/*
 * uart.h - USART1 (PA9 TX, PA10 RX), 8N1, the Modbus RTU line.
 *
 * Receive is interrupt driven into a ring buffer of PIEZO_UART_RX_SIZE bytes
 * (a power of two: indices wrap by mask). Each received byte is stamped with
 * the tick count, which the RTU framer needs for its 3.5-character silence.
 * Transmit waits for the data register (TXE) byte by byte: it runs in the
 * background loop, never in the tick.
 */
#ifndef PIEZO_UART_H
#define PIEZO_UART_H

#include <stddef.h>
#include <stdint.h>

#define PIEZO_UART_RX_SIZE 256u

/** BRR value for a baud rate on the 84 MHz APB2 clock, oversampling by 16. */
#define PIEZO_UART_BRR(baud) ((PIEZO_APB2_HZ + (baud) / 2u) / (baud))

/** Configure pins, baud rate and the receive interrupt; drops pending input. */
void piezo_uart_init(uint32_t brr);

/** Send n bytes (blocking until the last one is in the data register). */
void piezo_uart_write(const uint8_t *data, size_t n);

/** Next received byte, or -1 when none is waiting. */
int piezo_uart_getc(void);

/** Bytes waiting in the receive buffer. */
size_t piezo_uart_available(void);

/** Tick count when the last byte arrived. */
uint32_t piezo_uart_last_rx_tick(void);

/** Bytes lost: receive buffer full or hardware overrun. */
uint32_t piezo_uart_dropped(void);

#endif /* PIEZO_UART_H */
