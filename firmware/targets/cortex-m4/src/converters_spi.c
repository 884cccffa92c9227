/* converters_spi.c - AD5791 DAC and AD7980 ADC on SPI1 and SPI2 (see converters_spi.h). */
#include "converters_spi.h"

/* One 8-bit transfer: wait TXE, write, wait RXNE, read (full duplex). */
static uint32_t xfer8(uint32_t base, uint32_t out)
{
    while ((piezo_spi_rd(base, PIEZO_SPI_SR) & PIEZO_SPI_SR_TXE) == 0u) {
    }
    piezo_spi_wr(base, PIEZO_SPI_DR, out & 0xFFu);
    while ((piezo_spi_rd(base, PIEZO_SPI_SR) & PIEZO_SPI_SR_RXNE) == 0u) {
    }
    return piezo_spi_rd(base, PIEZO_SPI_DR) & 0xFFu;
}

static void wait_idle(uint32_t base)
{
    while ((piezo_spi_rd(base, PIEZO_SPI_SR) & PIEZO_SPI_SR_BSY) != 0u) {
    }
}

static void ad5791_frame(uint32_t reg, uint32_t data)
{
    uint32_t w = (reg << 20) | (data & PIEZO_AD5791_CODE_MAX); /* R/W = 0: write */
    piezo_gpio_write(PIEZO_PIN_DAC_SYNC, 0);
    (void)xfer8(PIEZO_SPI1_BASE, w >> 16);
    (void)xfer8(PIEZO_SPI1_BASE, w >> 8);
    (void)xfer8(PIEZO_SPI1_BASE, w);
    wait_idle(PIEZO_SPI1_BASE); /* the last SCLK edge before SYNC rises */
    piezo_gpio_write(PIEZO_PIN_DAC_SYNC, 1);
}

void piezo_conv_init(uint32_t dac_code)
{
    piezo_gpio_write(PIEZO_PIN_DAC_SYNC, 1);
    piezo_gpio_write(PIEZO_PIN_DAC_LDAC, 1);
    piezo_gpio_write(PIEZO_PIN_DAC_CLR, 1);
    piezo_gpio_write(PIEZO_PIN_ADC_CNV, 0);
    /* SPI1: master, mode 1 (CPOL 0, CPHA 1), fPCLK/4, software NSS */
    piezo_spi_wr(PIEZO_SPI1_BASE, PIEZO_SPI_CR1, PIEZO_SPI_CR1_MSTR | PIEZO_SPI_CR1_CPHA |
                                                     (1u << PIEZO_SPI_CR1_BR_SHIFT) | PIEZO_SPI_CR1_SSM |
                                                     PIEZO_SPI_CR1_SSI | PIEZO_SPI_CR1_SPE);
    /* SPI2: master, mode 0, fPCLK/2 */
    piezo_spi_wr(PIEZO_SPI2_BASE, PIEZO_SPI_CR1, PIEZO_SPI_CR1_MSTR | (0u << PIEZO_SPI_CR1_BR_SHIFT) |
                                                     PIEZO_SPI_CR1_SSM | PIEZO_SPI_CR1_SSI | PIEZO_SPI_CR1_SPE);
    ad5791_frame(PIEZO_AD5791_REG_DAC, dac_code);
    ad5791_frame(PIEZO_AD5791_REG_CTRL, PIEZO_AD5791_CTRL_RBUF | PIEZO_AD5791_CTRL_BIN2SC);
    piezo_conv_tick_edge();
    (void)piezo_ad7980_read();
}

void piezo_conv_tick_edge(void)
{
    piezo_gpio_write(PIEZO_PIN_DAC_LDAC, 0); /* LDAC low >= 20 ns: the input register goes out */
    piezo_gpio_write(PIEZO_PIN_DAC_LDAC, 1);
    piezo_gpio_write(PIEZO_PIN_ADC_CNV, 1); /* rising edge: sample, convert */
}

uint32_t piezo_ad7980_read(void)
{
    for (volatile uint32_t i = 0; i < PIEZO_AD7980_TCONV_LOOPS; i = i + 1u) {
    }
    piezo_gpio_write(PIEZO_PIN_ADC_CNV, 0); /* CNV low: the MSB appears on SDO */
    uint32_t hi = xfer8(PIEZO_SPI2_BASE, 0xFFu);
    uint32_t lo = xfer8(PIEZO_SPI2_BASE, 0xFFu);
    return (hi << 8) | lo;
}

void piezo_ad5791_write(uint32_t code)
{
    ad5791_frame(PIEZO_AD5791_REG_DAC, code > PIEZO_AD5791_CODE_MAX ? PIEZO_AD5791_CODE_MAX : code);
}
