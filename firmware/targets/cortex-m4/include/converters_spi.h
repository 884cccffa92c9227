/*
 * converters_spi.h - the reference design's converters on SPI, behind the
 * control loop's seams (piezo_adc_read / piezo_dac_write, control.h).
 *
 * DAC: Analog Devices AD5791 (20-bit, +-1 LSB INL, SPI up to 35 MHz, 24-bit
 * frames [R/W | A2..A0 | D19..D0], data sampled on SCLK falling edges: SPI
 * mode 1), on SPI1 at 21 MHz (84 MHz / 4):
 *   PA5 SCLK, PA7 SDIN (MOSI), PA6 SDO (MISO, unused), PA4 SYNC (chip
 *   select, GPIO), PB0 LDAC (GPIO, output update), PB1 CLR (GPIO, held high),
 *   RESET tied high (10 k).
 * ADC: Analog Devices AD7980 (16-bit, 1 MSPS SAR, tCONV <= 710 ns), 3-wire
 * CS mode without busy indicator (SDI high), data shifted out MSB first on
 * SCK falling edges (SPI mode 0), on SPI2 at 21 MHz (42 MHz / 2):
 *   PB13 SCK, PB14 SDO (MISO), PB12 CNV (GPIO).
 *
 * Pacing by the tick: at the start of every tick piezo_conv_tick_edge()
 * pulses LDAC (the DAC code written in the previous tick reaches the output
 * at the tick edge: one tick of output latency, no jitter from the tick's
 * work) and raises CNV (the sample is taken at the tick edge);
 * piezo_adc_read() waits out tCONV, lowers CNV and reads the 16 bits;
 * piezo_dac_write() shifts the new code into the AD5791's input register.
 *
 * Register and pin access goes through piezo_spi_rd/wr and piezo_gpio_write
 * (converters_spi_mmio.c on the chip; a fake SPI peripheral with both
 * converters on the host, tests/firmware/fake_spi.c).
 */
#ifndef PIEZO_CONVERTERS_SPI_H
#define PIEZO_CONVERTERS_SPI_H

#include <stdint.h>

/* RM0090 28.5: SPI registers */
#define PIEZO_SPI1_BASE 0x40013000u
#define PIEZO_SPI2_BASE 0x40003800u
#define PIEZO_SPI_CR1 0x00u
#define PIEZO_SPI_CR2 0x04u
#define PIEZO_SPI_SR 0x08u
#define PIEZO_SPI_DR 0x0Cu
#define PIEZO_SPI_CR1_CPHA (1u << 0)
#define PIEZO_SPI_CR1_CPOL (1u << 1)
#define PIEZO_SPI_CR1_MSTR (1u << 2)
#define PIEZO_SPI_CR1_BR_SHIFT 3u
#define PIEZO_SPI_CR1_SPE (1u << 6)
#define PIEZO_SPI_CR1_SSI (1u << 8)
#define PIEZO_SPI_CR1_SSM (1u << 9)
#define PIEZO_SPI_SR_RXNE (1u << 0)
#define PIEZO_SPI_SR_TXE (1u << 1)
#define PIEZO_SPI_SR_BSY (1u << 7)

/* pins: port index (0 = GPIOA) and number */
#define PIEZO_PIN(port, n) (((port) << 4) | (n))
#define PIEZO_PIN_DAC_SYNC PIEZO_PIN(0u, 4u)
#define PIEZO_PIN_DAC_LDAC PIEZO_PIN(1u, 0u)
#define PIEZO_PIN_DAC_CLR PIEZO_PIN(1u, 1u)
#define PIEZO_PIN_ADC_CNV PIEZO_PIN(1u, 12u)

/* AD5791 data sheet, table 11/12: registers and control bits */
#define PIEZO_AD5791_REG_DAC 1u
#define PIEZO_AD5791_REG_CTRL 2u
#define PIEZO_AD5791_CTRL_RBUF (1u << 1)
#define PIEZO_AD5791_CTRL_OPGND (1u << 2)
#define PIEZO_AD5791_CTRL_DACTRI (1u << 3)
#define PIEZO_AD5791_CTRL_BIN2SC (1u << 4) /* 1: offset binary codes */
#define PIEZO_AD5791_CODE_MAX 0xFFFFFu

/* AD7980: tCONV <= 710 ns = 120 cycles at 168 MHz; the wait loop takes at
 * least 3 cycles per pass */
#define PIEZO_AD7980_TCONV_LOOPS 40u

uint32_t piezo_spi_rd(uint32_t base, uint32_t off);
void piezo_spi_wr(uint32_t base, uint32_t off, uint32_t value);
void piezo_gpio_write(uint32_t pin, int level);

/** Clocks, pins, both SPIs; the AD5791 out of its power-on clamp (control
 *  register: RBUF, offset binary, output on), its output at code. */
void piezo_conv_init(uint32_t dac_code);

/** Tick edge: LDAC pulse (previous code out), CNV high (sample now). */
void piezo_conv_tick_edge(void);

/** The conversion started at this tick's edge (16-bit code). */
uint32_t piezo_ad7980_read(void);

/** The next code (20 bits, offset binary) into the DAC's input register. */
void piezo_ad5791_write(uint32_t code);

#endif /* PIEZO_CONVERTERS_SPI_H */
