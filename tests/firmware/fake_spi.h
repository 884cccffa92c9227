/*
 * fake_spi.h - a fake of the STM32F405's SPI1 and SPI2 and GPIO pins with
 * the reference design's converters on them, at register level, for the
 * converter drivers' host test: SPI CR1/SR/DR (TXE, RXNE, BSY; a DR write
 * clocks 8 bits both ways), GPIO levels, an AD5791 on SPI1 (24-bit frames
 * framed by SYNC, input register, output on an LDAC pulse, control register,
 * clamped output until OPGND and DACTRI are cleared) and an AD7980 on SPI2
 * (samples its input at CNV's rising edge, shifts the result out MSB first
 * while CNV is low). Every misuse is counted.
 */
#ifndef FAKE_SPI_H
#define FAKE_SPI_H

#include <stdint.h>

typedef struct {
    uint32_t cr1[2];
    uint32_t rx[2];
    int rxne[2];
    int level[2][16];
    /* AD5791 */
    uint32_t dac_shift, dac_bits, dac_input, dac_output, dac_ctrl, dac_frames;
    int dac_output_enabled;
    /* AD7980 */
    uint32_t adc_input, adc_sample, adc_bits_out, adc_conversions;
    /* misuse */
    uint32_t bad_mode, bad_frames, read_while_converting, spi_disabled_writes, dr_without_rxne;
} fake_spi_t;

extern fake_spi_t fake;

/** Reset: pins low, registers 0, the AD5791 clamped (power-on), input 0. */
void fake_spi_reset(void);

#endif /* FAKE_SPI_H */
