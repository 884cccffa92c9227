/* fake_spi.c - see fake_spi.h. */
#include "fake_spi.h"

#include <string.h>

#include "converters_spi.h"

fake_spi_t fake;

void fake_spi_reset(void)
{
    memset(&fake, 0, sizeof fake);
    fake.dac_ctrl = PIEZO_AD5791_CTRL_OPGND | PIEZO_AD5791_CTRL_DACTRI; /* power-on: clamped, tristate */
}

static int idx(uint32_t base)
{
    return base == PIEZO_SPI1_BASE ? 0 : 1;
}

uint32_t piezo_spi_rd(uint32_t base, uint32_t off)
{
    int i = idx(base);
    if (off == PIEZO_SPI_CR1) {
        return fake.cr1[i];
    }
    if (off == PIEZO_SPI_SR) {
        return PIEZO_SPI_SR_TXE | (fake.rxne[i] ? PIEZO_SPI_SR_RXNE : 0u);
    }
    if (off == PIEZO_SPI_DR) {
        if (!fake.rxne[i]) {
            fake.dr_without_rxne++;
        }
        fake.rxne[i] = 0;
        return fake.rx[i];
    }
    return 0u;
}

static uint8_t ad5791_clock(uint8_t in)
{
    if (fake.level[0][4] != 0) {
        return 0xFFu; /* SYNC high: the DAC ignores SCLK */
    }
    fake.dac_shift = (fake.dac_shift << 8) | in;
    fake.dac_bits += 8u;
    return 0u;
}

static uint8_t ad7980_clock(void)
{
    if (fake.level[1][12] != 0) {
        fake.read_while_converting++;
        return 0xFFu;
    }
    uint32_t shift = 16u - 8u - fake.adc_bits_out;
    uint8_t out = fake.adc_bits_out < 16u ? (uint8_t)(fake.adc_sample >> shift) : 0u;
    fake.adc_bits_out += 8u;
    return out;
}

void piezo_spi_wr(uint32_t base, uint32_t off, uint32_t value)
{
    int i = idx(base);
    if (off == PIEZO_SPI_CR1) {
        fake.cr1[i] = value;
        return;
    }
    if (off != PIEZO_SPI_DR) {
        return;
    }
    uint32_t need = PIEZO_SPI_CR1_SPE | PIEZO_SPI_CR1_MSTR;
    if ((fake.cr1[i] & need) != need) {
        fake.spi_disabled_writes++;
        return;
    }
    /* AD5791: SPI mode 1 (CPOL 0, CPHA 1); AD7980: mode 0 */
    uint32_t mode = fake.cr1[i] & (PIEZO_SPI_CR1_CPOL | PIEZO_SPI_CR1_CPHA);
    if (mode != (i == 0 ? PIEZO_SPI_CR1_CPHA : 0u)) {
        fake.bad_mode++;
    }
    fake.rx[i] = i == 0 ? ad5791_clock((uint8_t)value) : ad7980_clock();
    fake.rxne[i] = 1;
}

void piezo_gpio_write(uint32_t pin, int level)
{
    uint32_t port = pin >> 4, n = pin & 0xFu;
    int old = fake.level[port][n];
    fake.level[port][n] = level != 0;
    if (pin == PIEZO_PIN_DAC_SYNC && old == 0 && level) {
        if (fake.dac_bits == 0u) {
            /* no clock while SYNC was low: no frame */
        } else if (fake.dac_bits != 24u || (fake.dac_shift & 0x800000u) != 0u) {
            fake.bad_frames++;
        } else {
            uint32_t reg = (fake.dac_shift >> 20) & 7u, data = fake.dac_shift & 0xFFFFFu;
            if (reg == PIEZO_AD5791_REG_DAC) {
                fake.dac_input = data;
            } else if (reg == PIEZO_AD5791_REG_CTRL) {
                fake.dac_ctrl = data;
            }
            fake.dac_frames++;
        }
        fake.dac_shift = 0u;
        fake.dac_bits = 0u;
    }
    if (pin == PIEZO_PIN_DAC_SYNC && old && !level) {
        fake.dac_shift = 0u;
        fake.dac_bits = 0u;
    }
    if (pin == PIEZO_PIN_DAC_LDAC && old && !level) {
        fake.dac_output = fake.dac_input;
        fake.dac_output_enabled = (fake.dac_ctrl & (PIEZO_AD5791_CTRL_OPGND | PIEZO_AD5791_CTRL_DACTRI)) == 0u;
    }
    if (pin == PIEZO_PIN_ADC_CNV && !old && level) {
        fake.adc_sample = fake.adc_input & 0xFFFFu;
        fake.adc_conversions++;
    }
    if (pin == PIEZO_PIN_ADC_CNV && old && !level) {
        fake.adc_bits_out = 0u;
    }
}
