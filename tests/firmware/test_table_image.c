/* The table parser refuses every damaged image and names why. */
#include <string.h>

#include "piezo_test.h"
#include "crc32.h"
#include "table_image.h"
#include "tables_vectors.h"

static void test_valid_image_is_accepted(void **state)
{
    (void)state;
    piezo_table_info_t info;
    assert_int_equal(piezo_table_check(golden_table, GOLDEN_TABLE_LEN, &info), PIEZO_TABLE_REASON_OK);
    assert_int_equal(info.kind, PIEZO_TABLE_KIND_KP_DCC);
    assert_int_equal(info.table_version, 7);
    assert_true(info.crc == (uint32_t)GOLDEN_TABLE_CRC);
    assert_int_equal(info.n_sections, 3);
    const piezo_section_t *s = piezo_table_section(&info, 3);
    assert_non_null(s);
    assert_int_equal(piezo_section_i32(s, 0), GOLDEN_TABLE_SECTION3_VALUE);
    assert_int_equal(piezo_table_section(&info, 1)->count, 11);
    assert_null(piezo_table_section(&info, 4));
}

static void test_crc_matches_zlib(void **state)
{
    (void)state;
    assert_true(piezo_crc32(0, golden_table, GOLDEN_TABLE_LEN - 4u) == (uint32_t)GOLDEN_TABLE_CRC);
    assert_true(piezo_crc32(0, (const uint8_t *)"123456789", 9) == 0xCBF43926u);
}

static void test_every_single_bit_flip_is_refused(void **state)
{
    (void)state;
    uint8_t img[GOLDEN_TABLE_LEN];
    piezo_table_info_t info;
    for (uint32_t bit = 0; bit < 8u * GOLDEN_TABLE_LEN; bit++) {
        memcpy(img, golden_table, sizeof img);
        img[bit >> 3] ^= (uint8_t)(1u << (bit & 7u));
        if (piezo_table_check(img, sizeof img, &info) == PIEZO_TABLE_REASON_OK) {
            fail_msg("flip of bit %u accepted", bit);
        }
    }
}

static void test_every_truncation_is_refused(void **state)
{
    (void)state;
    piezo_table_info_t info;
    for (uint32_t len = 0; len < GOLDEN_TABLE_LEN; len++) {
        if (piezo_table_check(golden_table, len, &info) == PIEZO_TABLE_REASON_OK) {
            fail_msg("truncation to %u bytes accepted", len);
        }
    }
}

static void test_damage_behind_a_good_crc_is_named(void **state)
{
    (void)state;
    piezo_table_info_t info;
    for (unsigned i = 0; i < GOLDEN_BAD_N; i++) {
        uint16_t got = piezo_table_check(golden_bad[i].img, golden_bad[i].len, &info);
        if (got != golden_bad[i].reason) {
            fail_msg("%s: reason %u, want %u", golden_bad[i].name, got, golden_bad[i].reason);
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_valid_image_is_accepted),
        cmocka_unit_test(test_crc_matches_zlib),
        cmocka_unit_test(test_every_single_bit_flip_is_refused),
        cmocka_unit_test(test_every_truncation_is_refused),
        cmocka_unit_test(test_damage_behind_a_good_crc_is_named),
    };
    return cmocka_run_group_tests_name("table_image", tests, NULL, NULL);
}
