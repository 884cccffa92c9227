/*
 * cmocka.h - a small cmocka-compatible test runner for the target images.
 *
 * Debian's cmocka is built for the host only. The target tests compile the
 * same test_*.c against this header instead: it provides the part of cmocka
 * 1.1.5's API that tests/firmware uses (unit tests with optional fixtures, the
 * group runner, the assert_* family, fail, skip, print_message), with the
 * same semantics (assert_in_range compares unsigned, as cmocka 1.1.5 does)
 * and output in cmocka's format. No heap, no signals: a failed assertion
 * longjmps back to the runner, which goes on with the next test. The group
 * runner returns the number of failed tests. Anything else from cmocka
 * (mocks, expect_*, test_malloc) is deliberately absent: using it is a
 * compile error on the target.
 */
#ifndef PIEZO_CMOCKA_SHIM_H
#define PIEZO_CMOCKA_SHIM_H

#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>

typedef uintmax_t LargestIntegralType;
typedef void (*CMUnitTestFunction)(void **state);
typedef int (*CMFixtureFunction)(void **state);

struct CMUnitTest {
    const char *name;
    CMUnitTestFunction test_func;
    CMFixtureFunction setup_func;
    CMFixtureFunction teardown_func;
    void *initial_state;
};

#define cmocka_unit_test(f) {#f, f, NULL, NULL, NULL}
#define cmocka_unit_test_setup(f, setup) {#f, f, setup, NULL, NULL}
#define cmocka_unit_test_teardown(f, teardown) {#f, f, NULL, teardown, NULL}
#define cmocka_unit_test_setup_teardown(f, setup, teardown) {#f, f, setup, teardown, NULL}
#define cmocka_unit_test_prestate(f, state) {#f, f, NULL, NULL, state}
#define cmocka_unit_test_prestate_setup_teardown(f, setup, teardown, state) \
    {#f, f, setup, teardown, state}

#define cmocka_run_group_tests(tests, setup, teardown) \
    _cmocka_run_group_tests(#tests, tests, sizeof(tests) / sizeof((tests)[0]), setup, teardown)
#define cmocka_run_group_tests_name(name, tests, setup, teardown) \
    _cmocka_run_group_tests(name, tests, sizeof(tests) / sizeof((tests)[0]), setup, teardown)

int _cmocka_run_group_tests(const char *group, const struct CMUnitTest *tests, size_t n,
                            CMFixtureFunction setup, CMFixtureFunction teardown);

/* Reporting; the _cmocka_* functions do not return. No format attribute: the
 * host build checks the formats (cmocka's own attribute), and on this target
 * uint32_t is unsigned long, so a "%u" that is right on the host would be
 * refused here although both are the same 32 bits in the AAPCS. */
void print_message(const char *fmt, ...);
void print_error(const char *fmt, ...);
void _cmocka_fail(const char *file, int line, const char *fmt, ...) __attribute__((noreturn));
void _cmocka_skip(const char *file, int line) __attribute__((noreturn));
void _cmocka_int_equal(uintmax_t a, uintmax_t b, int want_equal, const char *file, int line);
void _cmocka_in_range(uintmax_t v, uintmax_t lo, uintmax_t hi, int want_in, const char *file,
                      int line);
void _cmocka_string_equal(const char *a, const char *b, int want_equal, const char *file, int line);
void _cmocka_memory_equal(const void *a, const void *b, size_t n, int want_equal, const char *file,
                          int line);

#define fail() _cmocka_fail(__FILE__, __LINE__, "%s", "fail()")
#define fail_msg(...) _cmocka_fail(__FILE__, __LINE__, __VA_ARGS__)
#define skip() _cmocka_skip(__FILE__, __LINE__)

#define assert_true(c) \
    do { if (!(c)) { _cmocka_fail(__FILE__, __LINE__, "%s", #c); } } while (0)
#define assert_false(c) \
    do { if (c) { _cmocka_fail(__FILE__, __LINE__, "%s", #c); } } while (0)
#define assert_return_code(rc, error)                                                 \
    do { if ((long long)(rc) < 0) {                                                   \
            _cmocka_fail(__FILE__, __LINE__, "%lld < 0 (error %lld)", (long long)(rc), \
                         (long long)(error)); } } while (0)
#define assert_non_null(p) \
    do { if ((p) == NULL) { _cmocka_fail(__FILE__, __LINE__, "%s is NULL", #p); } } while (0)
#define assert_null(p) \
    do { if ((p) != NULL) { _cmocka_fail(__FILE__, __LINE__, "%s is not NULL", #p); } } while (0)
#define assert_ptr_equal(a, b) \
    _cmocka_int_equal((uintmax_t)(uintptr_t)(a), (uintmax_t)(uintptr_t)(b), 1, __FILE__, __LINE__)
#define assert_ptr_not_equal(a, b) \
    _cmocka_int_equal((uintmax_t)(uintptr_t)(a), (uintmax_t)(uintptr_t)(b), 0, __FILE__, __LINE__)
#define assert_int_equal(a, b) \
    _cmocka_int_equal((uintmax_t)(a), (uintmax_t)(b), 1, __FILE__, __LINE__)
#define assert_int_not_equal(a, b) \
    _cmocka_int_equal((uintmax_t)(a), (uintmax_t)(b), 0, __FILE__, __LINE__)
#define assert_in_range(v, lo, hi) \
    _cmocka_in_range((uintmax_t)(v), (uintmax_t)(lo), (uintmax_t)(hi), 1, __FILE__, __LINE__)
#define assert_not_in_range(v, lo, hi) \
    _cmocka_in_range((uintmax_t)(v), (uintmax_t)(lo), (uintmax_t)(hi), 0, __FILE__, __LINE__)
#define assert_string_equal(a, b) _cmocka_string_equal((a), (b), 1, __FILE__, __LINE__)
#define assert_string_not_equal(a, b) _cmocka_string_equal((a), (b), 0, __FILE__, __LINE__)
#define assert_memory_equal(a, b, n) _cmocka_memory_equal((a), (b), (n), 1, __FILE__, __LINE__)
#define assert_memory_not_equal(a, b, n) _cmocka_memory_equal((a), (b), (n), 0, __FILE__, __LINE__)

#endif /* PIEZO_CMOCKA_SHIM_H */
