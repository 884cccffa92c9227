/*
 * pacer.h - the fixed-rate loop of the Linux targets (sil-stage, the comedi
 * DAQ controller): deadlines on CLOCK_MONOTONIC, what a late wake-up means,
 * and the statistics (lateness histogram, overruns, tick duration).
 *
 * The arithmetic takes the time as an argument, so it is tested with a fake
 * clock; piezo_pacer_sleep() and piezo_now_ns() are the real clock.
 *
 * One period of a loop:
 *     if (piezo_pacer_sleep(&p) != 0) continue;        // EINTR: check the stop flag
 *     int64_t start = piezo_now_ns();
 *     uint32_t n = piezo_pacer_wake(&p, start, &late); // n ticks due now
 *     ... run n ticks (and report overruns when late) ...
 *     piezo_pacer_done(&p, start, piezo_now_ns());
 *
 * Lateness is the wake-up time minus the deadline. A wake-up more than one
 * period late is an overrun. What happens to the deadlines that passed
 * meanwhile is the policy:
 *   CATCH_UP  every passed deadline gets its tick, at once (a simulation whose
 *             time must keep up with the wall clock); each counts as an
 *             overrun when the wake-up was an overrun
 *   SKIP      one tick now; the passed deadlines are dropped and counted in
 *             `skipped` (hardware: the samples of the missed periods are
 *             gone, and a burst of ticks would only re-read the same input)
 */
#ifndef PIEZO_PACER_H
#define PIEZO_PACER_H

#include <stdint.h>

#define PIEZO_PACER_HIST_BINS 20000 /* 1 us bins up to 20 ms of lateness; the last counts all beyond */

typedef enum { PIEZO_PACE_CATCH_UP = 0, PIEZO_PACE_SKIP = 1 } piezo_pace_policy_t;

typedef struct {
    int64_t period_ns;
    int64_t next_ns;           /* deadline of the next tick [CLOCK_MONOTONIC ns] */
    piezo_pace_policy_t policy;
    uint64_t wakeups;          /* wake-ups that ran ticks (histogram entries) */
    uint64_t ticks;            /* ticks run */
    uint64_t overruns;         /* ticks that started more than a period late */
    uint64_t skipped;          /* deadlines dropped (SKIP) */
    uint64_t long_ticks;       /* wake-ups whose work ended after the next deadline */
    int64_t max_late_ns;
    uint32_t tick_time_ns;     /* work of the last wake-up: start to end [ns] */
    uint32_t tick_time_max_ns;
    uint32_t hist[PIEZO_PACER_HIST_BINS + 1];
} piezo_pacer_t;

/** Starts the schedule: the first deadline is now_ns. */
void piezo_pacer_init(piezo_pacer_t *p, int64_t period_ns, piezo_pace_policy_t policy, int64_t now_ns);

/** After waking at now_ns: records the lateness and moves the deadline past
 *  the ticks it returns. Returns the number of ticks to run now (0: woken
 *  before the deadline, nothing recorded); *overrun is 1 when the wake-up was
 *  more than one period late (each returned tick is then an overrun). */
uint32_t piezo_pacer_wake(piezo_pacer_t *p, int64_t now_ns, int *overrun);

/** After the ticks of a wake-up: their duration (tick_time_ns, max). Returns
 *  1 when the work ended after the next deadline (a tick that ran past its
 *  period), else 0. */
int piezo_pacer_done(piezo_pacer_t *p, int64_t start_ns, int64_t end_ns);

/** Lateness percentile in whole microseconds (q in [0, 1]; the lower bound of
 *  the bin holding it; PIEZO_PACER_HIST_BINS when beyond the histogram). */
long piezo_pacer_percentile_us(const piezo_pacer_t *p, double q);

/** CLOCK_MONOTONIC in ns. */
int64_t piezo_now_ns(void);

/** Sleeps until the next deadline (clock_nanosleep, TIMER_ABSTIME). Returns 0,
 *  or the error number (EINTR: a signal arrived; the caller checks its stop flag). */
int piezo_pacer_sleep(const piezo_pacer_t *p);

/* Real-time set-up where permitted: what piezo_rt_setup() achieved. */
typedef struct {
    int fifo;      /* SCHED_FIFO set; else errno of the refusal in fifo_errno */
    int fifo_errno;
    int locked;    /* mlockall(MCL_CURRENT | MCL_FUTURE) done; else errno in lock_errno */
    int lock_errno;
} piezo_rt_result_t;

/** SCHED_FIFO at priority prio (0: leave the scheduler alone), mlockall when
 *  lock_memory, timer slack 1 ns. Nothing here is fatal: refusals (no
 *  CAP_SYS_NICE, RLIMIT_MEMLOCK) are reported in the result. */
piezo_rt_result_t piezo_rt_setup(int prio, int lock_memory);

/** SIGINT and SIGTERM call on_stop (a handler that sets the loop's stop
 *  flag: piezo_pacer_sleep() returns EINTR and the loop looks at it);
 *  SIGPIPE is ignored (a client that went away is an error on its socket,
 *  not the end of the process). */
void piezo_stop_signals(void (*on_stop)(int sig));

/** "HOST:PORT" (PORT 0..65535) into host (NUL-terminated) and *port.
 *  Returns 0; -1 when there is no colon or the host does not fit host_len;
 *  -2 when PORT is not a number in 0..65535. */
int piezo_parse_host_port(const char *spec, char *host, unsigned long host_len, long *port);

#endif /* PIEZO_PACER_H */
