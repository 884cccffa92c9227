/* bench_main.c - the benchmark image: announces and runs every case. */
#include <stdio.h>

#include "bench.h"
#include "semihost.h"
#include "wave.h"

int16_t piezo_bench_u[PIEZO_BENCH_TICKS];
volatile int32_t piezo_bench_sink;
uint32_t piezo_bench_failures;
static volatile uint32_t marks_begin, marks_end;

/* Distinct bodies and noipa: two functions the compiler cannot merge or inline. */
__attribute__((noipa)) void piezo_bench_begin(void)
{
    marks_begin = marks_begin + 1u;
}

__attribute__((noipa)) void piezo_bench_end(void)
{
    marks_end = marks_end + 1u;
}

void piezo_bench_run(const char *name, uint32_t n_ticks, piezo_bench_tick_fn tick)
{
    char line[96];
    snprintf(line, sizeof line, "bench %s %lu\n", name, (unsigned long)n_ticks);
    piezo_sh_write0(line);
    for (uint32_t k = 0; k < n_ticks; k++) {
        piezo_bench_begin();
        tick(k);
        piezo_bench_end();
    }
}

static void empty_tick(uint32_t k)
{
    piezo_bench_sink = piezo_bench_u[k];
}

/* The empty tick plus exactly 100 instructions: bench-target requires a
 * count of 100 for it, a check of the whole counting chain. */
static void calibration_tick(uint32_t k)
{
    piezo_bench_sink = piezo_bench_u[k];
    __asm volatile(".rept 100\n\tnop\n\t.endr" ::: "memory");
}

int main(void)
{
    /* 50 Hz: freq_word = 50 / 10000 * 2^32 */
    for (uint32_t k = 0; k < PIEZO_BENCH_TICKS; k++) {
        piezo_bench_u[k] = (int16_t)((30000 * (int32_t)piezo_sine_q15(k * 21474836u) + 16384) >> 15);
    }
    piezo_bench_run("overhead", PIEZO_BENCH_TICKS, empty_tick);
    piezo_bench_run("calibration", 10u, calibration_tick);
    if (piezo_bench_reference) {
        piezo_bench_reference();
    }
    piezo_bench_kernels();
    piezo_bench_models();
    piezo_sh_write0("bench done\n");
    return (int)piezo_bench_failures + (marks_begin == marks_end ? 0 : 1);
}
