/* converters_spi_mmio.c - converters_spi.c's access functions on the chip:
 * SPI registers and GPIO set/reset (BSRR, RM0090 8.4.7). Clocks and pin
 * modes: piezo_conv_board_init(). */
#include "board.h"
#include "converters_spi.h"

#define GPIO_BASE(port) (0x40020000u + 0x400u * (port))
#define GPIO_MODER 0x00u
#define GPIO_OSPEEDR 0x08u
#define GPIO_AFRL 0x20u
#define GPIO_AFRH 0x24u
#define GPIO_BSRR 0x18u
#define RCC_AHB1ENR PIEZO_REG(0x40023830u)
#define RCC_APB1ENR PIEZO_REG(0x40023840u)
#define RCC_APB2ENR PIEZO_REG(0x40023844u)

uint32_t piezo_spi_rd(uint32_t base, uint32_t off)
{
    return PIEZO_REG(base + off);
}

void piezo_spi_wr(uint32_t base, uint32_t off, uint32_t value)
{
    PIEZO_REG(base + off) = value;
}

void piezo_gpio_write(uint32_t pin, int level)
{
    uint32_t n = pin & 0xFu;
    PIEZO_REG(GPIO_BASE(pin >> 4) + GPIO_BSRR) = level ? (1u << n) : (1u << (n + 16u));
}

static void pin_mode(uint32_t pin, uint32_t mode, uint32_t af)
{
    uint32_t base = GPIO_BASE(pin >> 4), n = pin & 0xFu;
    PIEZO_REG(base + GPIO_MODER) = (PIEZO_REG(base + GPIO_MODER) & ~(3u << (2u * n))) | (mode << (2u * n));
    PIEZO_REG(base + GPIO_OSPEEDR) |= 3u << (2u * n); /* very high speed */
    if (mode == 2u) {
        uint32_t reg = n < 8u ? GPIO_AFRL : GPIO_AFRH, sh = 4u * (n & 7u);
        PIEZO_REG(base + reg) = (PIEZO_REG(base + reg) & ~(0xFu << sh)) | (af << sh);
    }
}

/** Clocks and pin functions of the converters (before piezo_conv_init). */
void piezo_conv_board_init(void);
void piezo_conv_board_init(void)
{
    RCC_AHB1ENR |= (1u << 0) | (1u << 1); /* GPIOA, GPIOB */
    RCC_APB2ENR |= 1u << 12;              /* SPI1 */
    RCC_APB1ENR |= 1u << 14;              /* SPI2 */
    pin_mode(PIEZO_PIN(0u, 5u), 2u, 5u);  /* SPI1 SCK, AF5 */
    pin_mode(PIEZO_PIN(0u, 6u), 2u, 5u);  /* SPI1 MISO */
    pin_mode(PIEZO_PIN(0u, 7u), 2u, 5u);  /* SPI1 MOSI */
    pin_mode(PIEZO_PIN(1u, 13u), 2u, 5u); /* SPI2 SCK, AF5 */
    pin_mode(PIEZO_PIN(1u, 14u), 2u, 5u); /* SPI2 MISO */
    piezo_gpio_write(PIEZO_PIN_DAC_SYNC, 1);
    piezo_gpio_write(PIEZO_PIN_DAC_LDAC, 1);
    piezo_gpio_write(PIEZO_PIN_DAC_CLR, 1);
    pin_mode(PIEZO_PIN_DAC_SYNC, 1u, 0u);
    pin_mode(PIEZO_PIN_DAC_LDAC, 1u, 0u);
    pin_mode(PIEZO_PIN_DAC_CLR, 1u, 0u);
    pin_mode(PIEZO_PIN_ADC_CNV, 1u, 0u);
}
