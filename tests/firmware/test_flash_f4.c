/* The STM32F405 flash driver (firmware/targets/cortex-m4/src/flash_f4.c)
 * against the register-level model of the flash interface (f4_flash_model.c):
 * the RM0090 sequences, the error flags, and the A/B table store on it. */
#include <string.h>

#include "piezo_test.h"
#include "f4_flash_model.h"
#include "flash_f4.h"
#include "param_store.h"
#include "store.h"
#include "table_image.h"
#include "tables_vectors.h"

static uint8_t scratch[PIEZO_TABLE_MAX_BYTES];
static uint8_t buf[PIEZO_TABLE_MAX_BYTES];

static void assert_clean_and_locked(void)
{
    assert_int_equal(f4_model.writes_while_locked, 0);
    assert_int_equal(f4_model.ops_while_busy, 0);
    assert_int_equal(f4_model.wrong_keys, 0);
    assert_true((f4_model.cr & PIEZO_FLASH_CR_LOCK) != 0u);
    assert_int_equal(f4_model.sr & (PIEZO_FLASH_SR_ERRORS | PIEZO_FLASH_SR_BSY), 0);
}

static void test_erase_unlocks_erases_one_sector_and_locks(void **state)
{
    (void)state;
    f4_model_reset(5u);
    f4_model_busy_polls_unheld = 0u;
    f4_model.mem[1][100] = 0x00;
    f4_model.mem[0][100] = 0x00;
    assert_int_equal(piezo_f4_flash_erase_sector(11u), 0);
    /* the erase is waited for with only the tick let in, and released after */
    assert_int_equal(f4_model_busy_polls_unheld, 0);
    assert_int_equal(f4_model_hold_depth, 0);
    assert_int_equal(f4_model.erases[1], 1);
    assert_int_equal(f4_model.erases[0], 0);
    assert_int_equal(f4_model.mem[1][100], 0xFF);
    assert_int_equal(f4_model.mem[0][100], 0x00);
    assert_int_equal(f4_model.key_writes, 2);
    assert_clean_and_locked();
}

static void test_erase_refuses_the_code_sectors(void **state)
{
    (void)state;
    f4_model_reset(5u);
    for (uint32_t s = 0; s < 8u; s++) {
        assert_int_equal(piezo_f4_flash_erase_sector(s), -1);
    }
    assert_int_equal(piezo_f4_flash_erase_sector(12u), -1);
    assert_int_equal(f4_model.key_writes, 0);
    assert_int_equal(f4_model.erases[0] + f4_model.erases[1] + f4_model.erases[2] + f4_model.erases[3], 0);
    /* nor programming below the parameter sectors (the code) */
    assert_int_equal(piezo_f4_flash_program(PIEZO_FLASH_PARAMS_A_ADDR - 4u, golden_table, 4u), -1);
    assert_int_equal(f4_model.words_programmed, 0);
}

static void test_program_words_with_psize_x32_pads_the_tail(void **state)
{
    (void)state;
    const uint8_t data[7] = {1, 2, 3, 4, 5, 6, 7};
    f4_model_reset(3u);
    f4_model_busy_polls_unheld = 0u;
    assert_int_equal(piezo_f4_flash_program(PIEZO_FLASH_SLOT_A_ADDR + 16u, data, sizeof data), 0);
    assert_int_equal(f4_model_busy_polls_unheld, 0);
    assert_int_equal(f4_model_hold_depth, 0);
    assert_int_equal(f4_model.words_programmed, 2);
    assert_memory_equal(&f4_model.mem[0][16], data, sizeof data);
    assert_int_equal(f4_model.mem[0][23], 0xFF); /* padding leaves the cell erased */
    assert_int_equal(f4_model.cr & PIEZO_FLASH_CR_PG, 0);
    assert_clean_and_locked();
}

static void test_program_refuses_unaligned_and_outside_the_slots(void **state)
{
    (void)state;
    const uint8_t data[4] = {0};
    f4_model_reset(3u);
    assert_int_equal(piezo_f4_flash_program(PIEZO_FLASH_SLOT_A_ADDR + 2u, data, 4u), -1);
    assert_int_equal(piezo_f4_flash_program(0x08000000u, data, 4u), -1);
    assert_int_equal(piezo_f4_flash_program(PIEZO_FLASH_SLOT_A_ADDR + 2u * PIEZO_FLASH_SLOT_BYTES - 2u, data, 4u), -1);
    assert_int_equal(f4_model.key_writes, 0);
}

static void test_a_write_protection_error_fails_and_is_cleared(void **state)
{
    (void)state;
    const uint8_t data[8] = {0};
    f4_model_reset(2u);
    f4_model.inject_sr = PIEZO_FLASH_SR_WRPERR;
    assert_int_equal(piezo_f4_flash_program(PIEZO_FLASH_SLOT_A_ADDR, data, sizeof data), -1);
    assert_int_equal(f4_model.words_programmed, 1); /* stopped at the first error */
    assert_clean_and_locked();
    f4_model.inject_sr = PIEZO_FLASH_SR_OPERR;
    assert_int_equal(piezo_f4_flash_erase_sector(10u), -1);
    assert_clean_and_locked();
    /* the next operation starts clean */
    assert_int_equal(piezo_f4_flash_erase_sector(10u), 0);
}

static void test_a_stale_error_flag_is_cleared_before_the_next_operation(void **state)
{
    (void)state;
    const uint8_t data[4] = {9, 9, 9, 9};
    f4_model_reset(2u);
    f4_model.sr = PIEZO_FLASH_SR_PGSERR; /* left by someone else */
    assert_int_equal(piezo_f4_flash_program(PIEZO_FLASH_SLOT_A_ADDR, data, 4u), 0);
    assert_clean_and_locked();
}

static void test_busy_that_never_ends_times_out(void **state)
{
    (void)state;
    f4_model_reset(2u);
    f4_model.stuck_busy = 1;
    f4_model.sr = PIEZO_FLASH_SR_BSY;
    assert_int_equal(piezo_f4_flash_erase_sector(10u), -1);
    assert_int_equal(f4_model.key_writes, 0); /* never touched CR while busy */
    assert_int_equal(f4_model.ops_while_busy, 0);
}

static void test_unlock_once_even_when_already_unlocked(void **state)
{
    (void)state;
    f4_model_reset(2u);
    f4_model.cr = 0u; /* unlocked by an earlier sequence: a second KEYR write would lock until reset */
    assert_int_equal(piezo_f4_flash_erase_sector(10u), 0);
    assert_int_equal(f4_model.key_writes, 0);
    assert_clean_and_locked();
}

/* The A/B store (firmware/tables/store.c) on the two sectors: save, reboot,
 * save again, reboot, rollback. */
static void test_store_on_the_flash_driver(void **state)
{
    (void)state;
    f4_model_reset(4u);
    piezo_storage_t io = piezo_f4_flash_storage();
    piezo_store_t st;
    assert_int_equal(piezo_store_open(&st, &io, scratch), 0);
    assert_int_equal(st.active, -1);
    assert_int_equal(piezo_store_save(&st, golden_table, GOLDEN_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    assert_clean_and_locked();

    piezo_store_t again;
    assert_int_equal(piezo_store_open(&again, &io, scratch), 0);
    assert_true(again.active >= 0);
    assert_int_equal(piezo_store_load(&again, 0, buf, sizeof buf), GOLDEN_TABLE_LEN);
    assert_memory_equal(buf, golden_table, GOLDEN_TABLE_LEN);

    assert_int_equal(piezo_store_save(&again, golden_table, GOLDEN_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    assert_int_equal(f4_model.erases[0] + f4_model.erases[1], 2); /* one per save, the other slot each time */
    assert_true(f4_model.erases[0] == 1 && f4_model.erases[1] == 1);
    assert_int_equal(piezo_store_open(&st, &io, scratch), 0);
    assert_true(st.active >= 0 && st.previous >= 0);
    assert_int_equal(piezo_store_rollback(&st, scratch), PIEZO_TABLE_REASON_OK);
    assert_clean_and_locked();
}

/* The parameter store (firmware/tables/param_store.c) on sectors 8 and 9:
 * save, reboot, save again (the other sector), reboot; the table sectors and
 * the code are never touched. */
static void test_params_on_the_flash_driver(void **state)
{
    (void)state;
    uint8_t payload[40], back[PIEZO_PARAMS_SLOT_BYTES];
    piezo_pstore_t ps;
    f4_model_reset(4u);
    piezo_storage_t io = piezo_f4_params_storage();
    for (uint32_t i = 0; i < sizeof payload; i++) {
        payload[i] = (uint8_t)(3u * i + 1u);
    }
    assert_int_equal(piezo_pstore_open(&ps, &io), 0);
    assert_int_equal(ps.active, -1);
    assert_int_equal(piezo_pstore_save(&ps, payload, sizeof payload), PIEZO_PARAMS_REASON_OK);
    assert_clean_and_locked();
    assert_int_equal(f4_model.erases[2], 1); /* sector 8 */
    assert_int_equal(piezo_pstore_open(&ps, &io), 0);
    assert_int_equal(piezo_pstore_load(&ps, back, sizeof back), sizeof payload);
    assert_memory_equal(back, payload, sizeof payload);
    payload[0] ^= 0xFFu;
    assert_int_equal(piezo_pstore_save(&ps, payload, sizeof payload), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(f4_model.erases[3], 1); /* sector 9: the inactive one */
    assert_int_equal(piezo_pstore_open(&ps, &io), 0);
    assert_int_equal(piezo_pstore_seq(&ps), 2);
    assert_int_equal(piezo_pstore_load(&ps, back, sizeof back), sizeof payload);
    assert_memory_equal(back, payload, sizeof payload);
    assert_int_equal(f4_model.erases[0] + f4_model.erases[1], 0); /* the tables' sectors */
    assert_int_equal(f4_model.mem[0][0], 0xFF);
    assert_int_equal(f4_model.mem[1][0], 0xFF);
}

/* The RAM storage of the PIL image: NOR semantics and the same store. */
static uint8_t ram[2u * (PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES)];

static void test_store_on_ram(void **state)
{
    (void)state;
    piezo_storage_t io = piezo_ram_storage(ram, PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES);
    const uint8_t zero = 0x0F, ones = 0xF0;
    piezo_store_t st;
    assert_int_equal(io.program(io.ctx, 0u, &zero, 1u), 0);
    assert_int_equal(io.program(io.ctx, 0u, &ones, 1u), 0);
    assert_int_equal(ram[0], 0x00); /* bits only cleared */
    assert_int_equal(io.erase(io.ctx, 0u, 1u), 0);
    assert_int_equal(ram[0], 0xFF);
    assert_int_equal(piezo_store_open(&st, &io, scratch), 0);
    assert_int_equal(piezo_store_save(&st, golden_table, GOLDEN_TABLE_LEN), PIEZO_TABLE_REASON_OK);
    assert_int_equal(piezo_store_open(&st, &io, scratch), 0);
    assert_int_equal(piezo_store_load(&st, 0, buf, sizeof buf), GOLDEN_TABLE_LEN);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_erase_unlocks_erases_one_sector_and_locks),
        cmocka_unit_test(test_erase_refuses_the_code_sectors),
        cmocka_unit_test(test_program_words_with_psize_x32_pads_the_tail),
        cmocka_unit_test(test_program_refuses_unaligned_and_outside_the_slots),
        cmocka_unit_test(test_a_write_protection_error_fails_and_is_cleared),
        cmocka_unit_test(test_a_stale_error_flag_is_cleared_before_the_next_operation),
        cmocka_unit_test(test_busy_that_never_ends_times_out),
        cmocka_unit_test(test_unlock_once_even_when_already_unlocked),
        cmocka_unit_test(test_store_on_the_flash_driver),
        cmocka_unit_test(test_store_on_ram),
        cmocka_unit_test(test_params_on_the_flash_driver),
    };
    return cmocka_run_group_tests_name("flash_f4", tests, NULL, NULL);
}
