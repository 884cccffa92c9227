/* cmocka_shim.c - the runner behind shim/cmocka.h (see there). */
#include <stdio.h>
#include <string.h>

#include "cmocka.h"

enum { RESULT_PASS = 0, RESULT_FAIL = 1, RESULT_SKIP = 2 };

static jmp_buf *current_jump; /* set while a test or fixture runs */

static void vreport(const char *prefix, const char *file, int line, const char *fmt, va_list ap)
{
    if (file != NULL) {
        printf("[   LINE   ] --- %s:%d: %s", file, line, prefix);
    }
    vprintf(fmt, ap);
    printf("\n");
}

void print_message(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
}

void print_error(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
}

void _cmocka_fail(const char *file, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vreport("error: ", file, line, fmt, ap);
    va_end(ap);
    if (current_jump == NULL) {
        printf("[  ERROR   ] assertion outside a test\n");
        fflush(stdout);
        _Exit(1);
    }
    longjmp(*current_jump, RESULT_FAIL);
}

void _cmocka_skip(const char *file, int line)
{
    (void)file;
    (void)line;
    if (current_jump == NULL) {
        _cmocka_fail(file, line, "%s", "skip() outside a test");
    }
    longjmp(*current_jump, RESULT_SKIP);
}

void _cmocka_int_equal(uintmax_t a, uintmax_t b, int want_equal, const char *file, int line)
{
    if ((a == b) != (want_equal != 0)) {
        _cmocka_fail(file, line, "%lld (%#llx) %s %lld (%#llx)", (long long)a, (unsigned long long)a,
                     want_equal ? "!=" : "==", (long long)b, (unsigned long long)b);
    }
}

void _cmocka_in_range(uintmax_t v, uintmax_t lo, uintmax_t hi, int want_in, const char *file,
                      int line)
{
    int in = v >= lo && v <= hi;
    if (in != (want_in != 0)) {
        _cmocka_fail(file, line, "%llu is %s range [%llu, %llu]", (unsigned long long)v,
                     want_in ? "not within" : "within", (unsigned long long)lo,
                     (unsigned long long)hi);
    }
}

void _cmocka_string_equal(const char *a, const char *b, int want_equal, const char *file, int line)
{
    int equal = a != NULL && b != NULL && strcmp(a, b) == 0;
    if (equal != (want_equal != 0)) {
        _cmocka_fail(file, line, "\"%s\" %s \"%s\"", a != NULL ? a : "(null)",
                     want_equal ? "!=" : "==", b != NULL ? b : "(null)");
    }
}

void _cmocka_memory_equal(const void *a, const void *b, size_t n, int want_equal, const char *file,
                          int line)
{
    const unsigned char *pa = a, *pb = b;
    size_t first = n;
    for (size_t i = 0; i < n; i++) {
        if (pa[i] != pb[i]) {
            first = i;
            break;
        }
    }
    if ((first == n) != (want_equal != 0)) {
        if (want_equal) {
            _cmocka_fail(file, line, "memory differs at byte %lu: 0x%02x != 0x%02x of %lu bytes",
                         (unsigned long)first, pa[first], pb[first], (unsigned long)n);
        }
        _cmocka_fail(file, line, "%lu bytes of memory are equal", (unsigned long)n);
    }
}

/* Runs fn(state) (a fixture when fixture != NULL) under the jump buffer. */
static int guarded(CMUnitTestFunction test, CMFixtureFunction fixture, void **state)
{
    jmp_buf jump;
    volatile int rc = RESULT_PASS;
    int jumped = setjmp(jump);
    if (jumped == 0) {
        current_jump = &jump;
        if (fixture != NULL) {
            if (fixture(state) != 0) {
                printf("[  ERROR   ] fixture returned an error\n");
                rc = RESULT_FAIL;
            }
        } else {
            test(state);
        }
    } else {
        rc = jumped;
    }
    current_jump = NULL;
    return rc;
}

int _cmocka_run_group_tests(const char *group, const struct CMUnitTest *tests, size_t n,
                            CMFixtureFunction setup, CMFixtureFunction teardown)
{
    void *group_state = NULL;
    size_t passed = 0, failed = 0, skipped = 0, named = 0;
    const char *failed_names[64];

    printf("[==========] %s: Running %lu test(s).\n", group, (unsigned long)n);
    if (setup != NULL && guarded(NULL, setup, &group_state) != RESULT_PASS) {
        printf("[  ERROR   ] %s: group setup failed\n", group);
        fflush(stdout);
        return (int)n;
    }
    for (size_t i = 0; i < n; i++) {
        const struct CMUnitTest *t = &tests[i];
        void *state = t->initial_state != NULL ? t->initial_state : group_state;
        printf("[ RUN      ] %s\n", t->name);
        int rc = RESULT_PASS;
        if (t->setup_func != NULL) {
            rc = guarded(NULL, t->setup_func, &state);
        }
        if (rc == RESULT_PASS) {
            rc = guarded(t->test_func, NULL, &state);
        }
        if (t->teardown_func != NULL && guarded(NULL, t->teardown_func, &state) != RESULT_PASS) {
            rc = RESULT_FAIL;
        }
        if (rc == RESULT_PASS) {
            printf("[       OK ] %s\n", t->name);
            passed++;
        } else if (rc == RESULT_SKIP) {
            printf("[  SKIPPED ] %s\n", t->name);
            skipped++;
        } else {
            printf("[  FAILED  ] %s\n", t->name);
            if (named < sizeof(failed_names) / sizeof(failed_names[0])) {
                failed_names[named++] = t->name;
            }
            failed++;
        }
    }
    if (teardown != NULL && guarded(NULL, teardown, &group_state) != RESULT_PASS) {
        printf("[  ERROR   ] %s: group teardown failed\n", group);
        failed++;
    }
    printf("[==========] %s: %lu test(s) run.\n", group, (unsigned long)n);
    printf("[  PASSED  ] %lu test(s).\n", (unsigned long)passed);
    if (skipped != 0) {
        printf("[  SKIPPED ] %s: %lu test(s).\n", group, (unsigned long)skipped);
    }
    if (failed != 0) {
        printf("[  FAILED  ] %s: %lu test(s), listed below:\n", group, (unsigned long)failed);
        for (size_t i = 0; i < named; i++) {
            printf("[  FAILED  ] %s\n", failed_names[i]);
        }
        printf("\n %lu FAILED TEST(S)\n", (unsigned long)failed);
    }
    fflush(stdout);
    return (int)failed;
}
