/* The Linux targets' pacing loop (firmware/targets/common/pacer.h) with a
 * fake clock: deadlines, catch-up and skip policies, overruns, long ticks,
 * the lateness histogram and its percentiles; against a transcription of
 * sil-stage's original loop for random lateness. Also HOST:PORT parsing. */
#include <string.h>

#include "pacer.h"
#include "piezo_test.h"

#define P 100000LL /* 10 kHz */

static piezo_pacer_t p;

static void test_on_time_and_early(void **state)
{
    int over = 7;
    (void)state;
    piezo_pacer_init(&p, P, PIEZO_PACE_CATCH_UP, 1000);
    assert_int_equal(piezo_pacer_wake(&p, 999, &over), 0); /* before the deadline: nothing */
    assert_int_equal(over, 0);
    assert_int_equal(p.wakeups, 0);
    assert_int_equal(piezo_pacer_wake(&p, 1000, &over), 1); /* exactly on time */
    assert_int_equal(over, 0);
    assert_true(p.next_ns == 1000 + P);
    assert_int_equal(piezo_pacer_wake(&p, 1000 + P + 3500, &over), 1); /* 3.5 us late */
    assert_int_equal(over, 0);
    assert_true(p.next_ns == 1000 + 2 * P);
    assert_int_equal(p.hist[0], 1);
    assert_int_equal(p.hist[3], 1);
    assert_true(p.max_late_ns == 3500);
    assert_int_equal(p.ticks, 2);
    assert_int_equal(p.overruns, 0);
}

static void test_catch_up_runs_every_passed_deadline(void **state)
{
    int over;
    (void)state;
    piezo_pacer_init(&p, P, PIEZO_PACE_CATCH_UP, 0);
    assert_int_equal(piezo_pacer_wake(&p, 0, &over), 1);
    /* deadline 100 us; woken at 350 us: deadlines 100, 200, 300 have passed */
    assert_int_equal(piezo_pacer_wake(&p, 350000, &over), 3);
    assert_int_equal(over, 1);
    assert_true(p.next_ns == 400000);
    assert_int_equal(p.ticks, 4);
    assert_int_equal(p.overruns, 3);
    assert_int_equal(p.skipped, 0);
    assert_int_equal(p.hist[250], 1);
    /* exactly one period late: two deadlines passed, not an overrun */
    assert_int_equal(piezo_pacer_wake(&p, 500000, &over), 2);
    assert_int_equal(over, 0);
    assert_int_equal(p.overruns, 3);
}

static void test_skip_drops_passed_deadlines(void **state)
{
    int over;
    (void)state;
    piezo_pacer_init(&p, P, PIEZO_PACE_SKIP, 0);
    assert_int_equal(piezo_pacer_wake(&p, 0, &over), 1);
    assert_int_equal(piezo_pacer_wake(&p, 350000, &over), 1);
    assert_int_equal(over, 1);
    assert_true(p.next_ns == 400000); /* the schedule stays on the grid */
    assert_int_equal(p.ticks, 2);
    assert_int_equal(p.overruns, 1);
    assert_int_equal(p.skipped, 2);
    assert_int_equal(piezo_pacer_wake(&p, 400000 + 20000, &over), 1);
    assert_int_equal(over, 0);
    assert_int_equal(p.skipped, 2);
}

static void test_tick_time_and_long_ticks(void **state)
{
    int over;
    (void)state;
    piezo_pacer_init(&p, P, PIEZO_PACE_SKIP, 0);
    assert_int_equal(piezo_pacer_wake(&p, 10000, &over), 1);
    assert_int_equal(piezo_pacer_done(&p, 10000, 40000), 0); /* 30 us of work, ends before 100 us */
    assert_int_equal(p.tick_time_ns, 30000);
    assert_int_equal(piezo_pacer_wake(&p, 130000, &over), 1);
    assert_int_equal(piezo_pacer_done(&p, 130000, 205000), 1); /* ends after the deadline at 200 us */
    assert_int_equal(p.tick_time_ns, 75000);
    assert_int_equal(p.tick_time_max_ns, 75000);
    assert_int_equal(p.long_ticks, 1);
    assert_int_equal(piezo_pacer_wake(&p, 205000, &over), 1);
    assert_int_equal(piezo_pacer_done(&p, 205000, 215000), 0);
    assert_int_equal(p.tick_time_ns, 10000);
    assert_int_equal(p.tick_time_max_ns, 75000);
}

static void test_percentiles(void **state)
{
    int over;
    int64_t t = 0;
    (void)state;
    piezo_pacer_init(&p, P, PIEZO_PACE_SKIP, 0);
    /* 100 wake-ups: 90 at 2 us late, 9 at 40 us, 1 at 30 ms (beyond the histogram) */
    for (int i = 0; i < 100; i++) {
        int64_t late = i < 90 ? 2000 : (i < 99 ? 40000 : 30000000);
        t = p.next_ns + late;
        assert_int_equal(piezo_pacer_wake(&p, t, &over), 1);
    }
    assert_int_equal(piezo_pacer_percentile_us(&p, 0.50), 2);
    assert_int_equal(piezo_pacer_percentile_us(&p, 0.90), 40);
    assert_int_equal(piezo_pacer_percentile_us(&p, 0.98), 40);
    assert_int_equal(piezo_pacer_percentile_us(&p, 0.995), PIEZO_PACER_HIST_BINS);
    assert_int_equal(p.hist[PIEZO_PACER_HIST_BINS], 1);
    assert_true(p.max_late_ns == 30000000);
    assert_int_equal(p.overruns, 1);
    assert_int_equal(p.skipped, 300);
}

/* sil-stage's loop before the pacer existed, transcribed. */
typedef struct {
    int64_t next;
    uint64_t ticks, overruns;
    int64_t max_late;
    uint32_t hist[PIEZO_PACER_HIST_BINS + 1];
} old_loop_t;

static uint32_t old_wake(old_loop_t *o, int64_t start)
{
    int64_t late = start - o->next;
    uint32_t n = 0;
    o->hist[late < 0 ? 0 : (late / 1000 >= PIEZO_PACER_HIST_BINS ? PIEZO_PACER_HIST_BINS : late / 1000)]++;
    if (late > o->max_late) {
        o->max_late = late;
    }
    do {
        n++;
        o->ticks++;
        o->next += P;
        if (late > P) {
            o->overruns++;
        }
    } while (o->next <= start);
    return n;
}

static void test_catch_up_is_the_sil_loop(void **state)
{
    static old_loop_t o;
    uint64_t rng = 12345u;
    int over;
    (void)state;
    memset(&o, 0, sizeof o);
    o.next = 5000;
    piezo_pacer_init(&p, P, PIEZO_PACE_CATCH_UP, 5000);
    for (int i = 0; i < 20000; i++) {
        int64_t late;
        rng = rng * 6364136223846793005ull + 1442695040888963407ull;
        /* mostly small, sometimes several periods late */
        late = (int64_t)((rng >> 33) % ((rng >> 20) % 16u == 0u ? 700000u : 30000u));
        const int64_t start = o.next + late;
        const uint32_t want = old_wake(&o, start);
        assert_int_equal(piezo_pacer_wake(&p, start, &over), want);
        assert_true(p.next_ns == o.next);
    }
    assert_int_equal(p.ticks, o.ticks);
    assert_int_equal(p.overruns, o.overruns);
    assert_true(p.max_late_ns == o.max_late);
    assert_memory_equal(p.hist, o.hist, sizeof o.hist);
    assert_true(p.overruns > 0u);
}

static void test_host_port(void **state)
{
    char host[16];
    long port = -5;
    (void)state;
    assert_int_equal(piezo_parse_host_port("127.0.0.1:5020", host, sizeof host, &port), 0);
    assert_string_equal(host, "127.0.0.1");
    assert_int_equal(port, 5020);
    assert_int_equal(piezo_parse_host_port("[::1]:0", host, sizeof host, &port), 0);
    assert_string_equal(host, "[::1]");
    assert_int_equal(port, 0);
    assert_int_equal(piezo_parse_host_port("localhost", host, sizeof host, &port), -1);
    assert_int_equal(piezo_parse_host_port("a-very-long-host-name:1", host, sizeof host, &port), -1);
    assert_int_equal(piezo_parse_host_port("h:65536", host, sizeof host, &port), -2);
    assert_int_equal(piezo_parse_host_port("h:12x", host, sizeof host, &port), -2);
    assert_int_equal(piezo_parse_host_port("h:-1", host, sizeof host, &port), -2);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_on_time_and_early),
        cmocka_unit_test(test_catch_up_runs_every_passed_deadline),
        cmocka_unit_test(test_skip_drops_passed_deadlines),
        cmocka_unit_test(test_tick_time_and_long_ticks),
        cmocka_unit_test(test_percentiles),
        cmocka_unit_test(test_catch_up_is_the_sil_loop),
        cmocka_unit_test(test_host_port),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
