/*
 * The cmocka shim must report failures: every test here but the first fails
 * on purpose (or skips), and shim_harness.py checks the exit status (the
 * number of failed tests) and the messages.
 */
#include <string.h>

#include "piezo_test.h"

static void test_passes(void **state)
{
    (void)state;
    assert_int_equal(-5, -5);
    assert_in_range(7, 1, 10);
    assert_string_equal("kp", "kp");
    assert_memory_equal("abc", "abc", 3);
    assert_signed_in_range(-3, -4, 0);
}

static void test_int_equal_fails(void **state)
{
    (void)state;
    assert_int_equal(1, 2);
    fail_msg("not reached");
}

static void test_negative_is_out_of_unsigned_range(void **state)
{
    (void)state;
    assert_in_range(-1, 0, 10); /* cmocka 1.1.5 semantics: unsigned */
}

static void test_memory_difference_is_located(void **state)
{
    (void)state;
    assert_memory_equal("abcd", "abxd", 4);
}

static void test_fail_msg_formats(void **state)
{
    (void)state;
    fail_msg("golden sample %d differs by %.1f", 42, 0.5);
}

static void test_skips(void **state)
{
    (void)state;
    skip();
}

static int failing_setup(void **state)
{
    (void)state;
    return -1;
}

static void test_not_run_after_failed_setup(void **state)
{
    (void)state;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_passes),
        cmocka_unit_test(test_int_equal_fails),
        cmocka_unit_test(test_negative_is_out_of_unsigned_range),
        cmocka_unit_test(test_memory_difference_is_located),
        cmocka_unit_test(test_fail_msg_formats),
        cmocka_unit_test(test_skips),
        cmocka_unit_test_setup(test_not_run_after_failed_setup, failing_setup),
    };
    return cmocka_run_group_tests_name("shim", tests, NULL, NULL);
}
