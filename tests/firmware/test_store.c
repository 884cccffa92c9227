/* A/B table storage: boot, save, rollback, and a power cut at every step. */
#include <string.h>

#include "piezo_test.h"
#include "nor_flash.h"
#include "crc32.h"
#include "piezo_err.h"
#include "store.h"
#include "table_image.h"
#include "tables_vectors.h"

#define SLOT (PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES)

static uint8_t flash_mem[2 * SLOT];
static uint8_t scratch[PIEZO_TABLE_MAX_BYTES];
static uint8_t img_b[GOLDEN_TABLE_LEN];

/* A second valid image: the golden one with another table_version and CRC. */
static void make_second_image(void)
{
    memcpy(img_b, golden_table, sizeof img_b);
    img_b[PIEZO_TABLE_HDR_TABLE_VERSION_OFFSET] = 8;
    uint32_t crc = piezo_crc32(0u, img_b, sizeof img_b - 4u);
    img_b[sizeof img_b - 4] = (uint8_t)crc;
    img_b[sizeof img_b - 3] = (uint8_t)(crc >> 8);
    img_b[sizeof img_b - 2] = (uint8_t)(crc >> 16);
    img_b[sizeof img_b - 1] = (uint8_t)(crc >> 24);
}

static uint32_t active_version(piezo_store_t *st)
{
    uint8_t buf[PIEZO_TABLE_MAX_BYTES];
    piezo_table_info_t info;
    uint32_t len = piezo_store_load(st, 0, buf, sizeof buf);
    if (len == 0u) {
        return 0u;
    }
    assert_int_equal(piezo_table_check(buf, len, &info), PIEZO_TABLE_REASON_OK);
    return info.table_version;
}

static void test_empty_flash_has_no_table(void **state)
{
    (void)state;
    nor_flash_t f;
    nor_flash_init(&f, flash_mem, sizeof flash_mem);
    piezo_storage_t io = nor_flash_storage(&f, SLOT);
    piezo_store_t st;
    assert_int_equal(piezo_store_open(&st, &io, scratch), PIEZO_OK);
    assert_int_equal(st.active, -1);
    assert_int_equal(piezo_store_rollback(&st, scratch), PIEZO_TABLE_REASON_NO_PREVIOUS);
}

static void test_save_survives_reboot_and_rolls_back(void **state)
{
    (void)state;
    nor_flash_t f;
    nor_flash_init(&f, flash_mem, sizeof flash_mem);
    piezo_storage_t io = nor_flash_storage(&f, SLOT);
    piezo_store_t st;
    assert_int_equal(piezo_store_open(&st, &io, scratch), PIEZO_OK);
    assert_int_equal(piezo_store_save(&st, golden_table, GOLDEN_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    assert_int_equal(piezo_store_save(&st, img_b, sizeof img_b), PIEZO_TABLE_REASON_OK);
    assert_int_equal(piezo_store_open(&st, &io, scratch), PIEZO_OK); /* reboot */
    assert_int_equal(active_version(&st), 8);
    assert_int_equal(piezo_store_rollback(&st, scratch), PIEZO_TABLE_REASON_OK);
    assert_int_equal(piezo_store_open(&st, &io, scratch), PIEZO_OK);
    assert_int_equal(active_version(&st), 7);
}

static void test_power_cut_at_every_operation_leaves_a_consistent_table(void **state)
{
    (void)state;
    for (long cut = 0; cut < 8; cut++) {
        nor_flash_t f;
        piezo_store_t st;
        nor_flash_init(&f, flash_mem, sizeof flash_mem);
        piezo_storage_t io = nor_flash_storage(&f, SLOT);
        assert_int_equal(piezo_store_open(&st, &io, scratch), PIEZO_OK);
        assert_int_equal(piezo_store_save(&st, golden_table, GOLDEN_TABLE_LEN), PIEZO_TABLE_REASON_OK);
        f.ops_left = cut;
        uint16_t r = piezo_store_save(&st, img_b, sizeof img_b);
        int finished = (r == PIEZO_TABLE_REASON_OK);
        f.dead = 0; /* power back: reboot */
        f.ops_left = -1;
        assert_int_equal(piezo_store_open(&st, &io, scratch), PIEZO_OK);
        uint32_t v = active_version(&st);
        print_message("cut after %ld operations: save %s, boots table %u\n", cut,
                      finished ? "done" : "cut", (unsigned)v);
        assert_true(v == (finished ? 8u : 7u));
        /* and a rollback cut at the same point never loses both tables */
        if (finished) {
            f.ops_left = cut;
            (void)piezo_store_rollback(&st, scratch);
            f.dead = 0;
            f.ops_left = -1;
            assert_int_equal(piezo_store_open(&st, &io, scratch), PIEZO_OK);
            v = active_version(&st);
            assert_true(v == 7u || v == 8u);
        }
    }
}

int main(void)
{
    make_second_image();
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_empty_flash_has_no_table),
        cmocka_unit_test(test_save_survives_reboot_and_rolls_back),
        cmocka_unit_test(test_power_cut_at_every_operation_leaves_a_consistent_table),
    };
    return cmocka_run_group_tests_name("store", tests, NULL, NULL);
}
