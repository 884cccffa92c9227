/*
 * bench.h - instruction-count benchmarks on the target (tools/bench-target).
 *
 * piezo_bench_run() announces a case over semihosting ("bench NAME N") and
 * runs N ticks of it, each between the markers piezo_bench_begin() and
 * piezo_bench_end(). The QEMU plugin tools/qemu-plugins/insn_window.c counts
 * the instructions of each window exactly; tools/bench-target matches the
 * windows to the announced cases in order and subtracts the "overhead" case
 * (the same call with an empty tick).
 */
#ifndef PIEZO_BENCH_H
#define PIEZO_BENCH_H

#include <stdint.h>

#define PIEZO_BENCH_TICKS 1000u

typedef void (*piezo_bench_tick_fn)(uint32_t k);

void piezo_bench_begin(void);
void piezo_bench_end(void);
void piezo_bench_run(const char *name, uint32_t n_ticks, piezo_bench_tick_fn tick);

/* Test input: a 50 Hz sine of amplitude 30000 q15 LSB at 10 kHz, sample k. */
extern int16_t piezo_bench_u[PIEZO_BENCH_TICKS];
extern volatile int32_t piezo_bench_sink;
extern uint32_t piezo_bench_failures; /* cases whose set-up failed */

/* Cases: each kernel of the core alone (bench_kernels.c), each hysteresis
 * model of the reference configuration alone (bench_models.c). */
void piezo_bench_kernels(void);
void piezo_bench_models(void);

/* The reference configuration: the whole control tick (bench_reference.c);
 * tools/bench-target prints its count first, as "instructions_per_tick: N". */
void piezo_bench_reference(void) __attribute__((weak));

#endif /* PIEZO_BENCH_H */
