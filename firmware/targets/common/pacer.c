/* pacer.c - deadlines and statistics of the Linux targets' fixed-rate loop. */
#define _GNU_SOURCE
#include "pacer.h"

#include <errno.h>
#include <sched.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <time.h>

void piezo_pacer_init(piezo_pacer_t *p, int64_t period_ns, piezo_pace_policy_t policy, int64_t now_ns)
{
    memset(p, 0, sizeof *p);
    p->period_ns = period_ns;
    p->policy = policy;
    p->next_ns = now_ns;
}

uint32_t piezo_pacer_wake(piezo_pacer_t *p, int64_t now_ns, int *overrun)
{
    int64_t late = now_ns - p->next_ns;
    uint64_t passed;
    uint32_t n;
    int over;
    if (late < 0) {
        *overrun = 0;
        return 0u;
    }
    p->hist[late / 1000 >= PIEZO_PACER_HIST_BINS ? PIEZO_PACER_HIST_BINS : late / 1000]++;
    p->wakeups++;
    if (late > p->max_late_ns) {
        p->max_late_ns = late;
    }
    over = late > p->period_ns;
    passed = (uint64_t)(late / p->period_ns) + 1u; /* deadlines at or before now */
    if (p->policy == PIEZO_PACE_SKIP) {
        n = 1u;
        p->skipped += passed - 1u;
    } else {
        n = passed > UINT32_MAX ? UINT32_MAX : (uint32_t)passed;
    }
    p->next_ns += (int64_t)passed * p->period_ns;
    p->ticks += n;
    if (over) {
        p->overruns += n;
    }
    *overrun = over;
    return n;
}

int piezo_pacer_done(piezo_pacer_t *p, int64_t start_ns, int64_t end_ns)
{
    int64_t dur = end_ns - start_ns;
    uint32_t d = dur < 0 ? 0u : (dur > (int64_t)UINT32_MAX ? UINT32_MAX : (uint32_t)dur);
    p->tick_time_ns = d;
    if (d > p->tick_time_max_ns) {
        p->tick_time_max_ns = d;
    }
    if (end_ns > p->next_ns) {
        p->long_ticks++;
        return 1;
    }
    return 0;
}

long piezo_pacer_percentile_us(const piezo_pacer_t *p, double q)
{
    uint64_t n = 0, want, seen = 0;
    for (long i = 0; i <= PIEZO_PACER_HIST_BINS; i++) {
        n += p->hist[i];
    }
    want = (uint64_t)(q * (double)n);
    for (long i = 0; i < PIEZO_PACER_HIST_BINS; i++) {
        seen += p->hist[i];
        if (seen > want) {
            return i;
        }
    }
    return PIEZO_PACER_HIST_BINS;
}

int64_t piezo_now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

int piezo_pacer_sleep(const piezo_pacer_t *p)
{
    struct timespec ts = {(time_t)(p->next_ns / 1000000000LL), (long)(p->next_ns % 1000000000LL)};
    return clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL);
}

piezo_rt_result_t piezo_rt_setup(int prio, int lock_memory)
{
    piezo_rt_result_t r = {0, 0, 0, 0};
    if (prio > 0) {
        struct sched_param sp;
        memset(&sp, 0, sizeof sp);
        sp.sched_priority = prio;
        if (sched_setscheduler(0, SCHED_FIFO, &sp) == 0) {
            r.fifo = 1;
        } else {
            r.fifo_errno = errno;
        }
    }
    if (lock_memory) {
        if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
            r.locked = 1;
        } else {
            r.lock_errno = errno;
        }
    }
    (void)prctl(PR_SET_TIMERSLACK, 1UL); /* default slack is 50 us */
    return r;
}

void piezo_stop_signals(void (*on_stop)(int sig))
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_stop;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
}

int piezo_parse_host_port(const char *spec, char *host, unsigned long host_len, long *port)
{
    const char *colon = spec != NULL ? strrchr(spec, ':') : NULL;
    char *end;
    long v;
    if (colon == NULL || (unsigned long)(colon - spec) >= host_len) {
        return -1;
    }
    v = strtol(colon + 1, &end, 10);
    if (*end != '\0' || v < 0 || v > 65535) {
        return -2;
    }
    memcpy(host, spec, (size_t)(colon - spec));
    host[colon - spec] = '\0';
    *port = v;
    return 0;
}
