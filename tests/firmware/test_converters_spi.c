/* The AD5791 and AD7980 drivers (firmware/targets/cortex-m4/src/converters_spi.c)
 * against a fake SPI peripheral with both converters (fake_spi.c). */
#include "piezo_test.h"
#include "converters_spi.h"
#include "fake_spi.h"

static void assert_no_misuse(void)
{
    assert_int_equal(fake.bad_mode, 0);
    assert_int_equal(fake.bad_frames, 0);
    assert_int_equal(fake.read_while_converting, 0);
    assert_int_equal(fake.spi_disabled_writes, 0);
    assert_int_equal(fake.dr_without_rxne, 0);
}

static void test_init_configures_both_spis_and_releases_the_dac_clamp(void **state)
{
    (void)state;
    fake_spi_reset();
    piezo_conv_init(0x80000u);
    assert_true((fake.cr1[0] & (PIEZO_SPI_CR1_SPE | PIEZO_SPI_CR1_MSTR)) == (PIEZO_SPI_CR1_SPE | PIEZO_SPI_CR1_MSTR));
    assert_int_equal((fake.cr1[0] >> PIEZO_SPI_CR1_BR_SHIFT) & 7u, 1u); /* 84 MHz / 4 = 21 MHz <= 35 MHz */
    assert_int_equal((fake.cr1[1] >> PIEZO_SPI_CR1_BR_SHIFT) & 7u, 0u); /* 42 MHz / 2 */
    assert_int_equal(fake.dac_frames, 2);
    assert_int_equal(fake.dac_ctrl, PIEZO_AD5791_CTRL_RBUF | PIEZO_AD5791_CTRL_BIN2SC);
    assert_int_equal(fake.dac_output, 0x80000u);
    assert_true(fake.dac_output_enabled);
    assert_int_equal(fake.level[0][4], 1); /* SYNC idle high */
    assert_int_equal(fake.level[1][12], 0); /* CNV low after the read */
    assert_no_misuse();
}

static void test_dac_code_reaches_the_output_at_the_next_tick_edge(void **state)
{
    (void)state;
    fake_spi_reset();
    piezo_conv_init(0x80000u);
    piezo_ad5791_write(0x12345u);
    assert_int_equal(fake.dac_input, 0x12345u);
    assert_int_equal(fake.dac_output, 0x80000u); /* not before the edge */
    piezo_conv_tick_edge();
    assert_int_equal(fake.dac_output, 0x12345u);
    (void)piezo_ad7980_read();
    piezo_ad5791_write(0xFFFFFFu); /* clamped to 20 bits */
    piezo_conv_tick_edge();
    assert_int_equal(fake.dac_output, PIEZO_AD5791_CODE_MAX);
    (void)piezo_ad7980_read();
    assert_int_equal(fake.dac_frames, 4);
    assert_no_misuse();
}

static void test_adc_returns_the_sample_taken_at_the_tick_edge(void **state)
{
    (void)state;
    fake_spi_reset();
    piezo_conv_init(0u);
    const uint32_t values[] = {0x0000u, 0xFFFFu, 0x8001u, 0x1234u, 0xA5C3u};
    for (unsigned k = 0; k < sizeof values / sizeof values[0]; k++) {
        fake.adc_input = values[k];
        piezo_conv_tick_edge();
        fake.adc_input = 0x5555u; /* changes after the edge are not in this sample */
        assert_int_equal(piezo_ad7980_read(), values[k]);
    }
    assert_int_equal(fake.adc_conversions, 1u + 5u);
    assert_no_misuse();
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_init_configures_both_spis_and_releases_the_dac_clamp),
        cmocka_unit_test(test_dac_code_reaches_the_output_at_the_next_tick_edge),
        cmocka_unit_test(test_adc_returns_the_sample_taken_at_the_tick_edge),
    };
    return cmocka_run_group_tests_name("converters_spi", tests, NULL, NULL);
}
