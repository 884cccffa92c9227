/*
 * tick.h - the 10 kHz control tick on SysTick.
 *
 * SysTick counts the 168 MHz processor clock from PIEZO_TICK_RELOAD down to 0
 * and interrupts at the highest priority. Each interrupt increments the tick
 * counter and calls piezo_control_tick(), the control loop's one function per
 * tick. The control loop defines it; until it does, a weak default does
 * nothing. Everything reachable from the handler is the tick path, which the
 * build checks for division and floating-point helpers (check_tick_path.py).
 */
#ifndef PIEZO_TICK_H
#define PIEZO_TICK_H

#include <stdint.h>

/** Start SysTick with the given reload (PIEZO_TICK_RELOAD for 10 kHz). */
void piezo_tick_start(uint32_t reload);

/** Stop the tick; the counter keeps its value. */
void piezo_tick_stop(void);

/** Ticks since piezo_tick_start() (wraps after 2^32 ticks, about 5 days). */
uint32_t piezo_tick_count(void);

/** Processor cycles (168 MHz) from the instant the last tick was due to the
 *  end of its work: entry latency, any wait behind masked code, and the work. */
uint32_t piezo_tick_time_cycles(void);

/** The largest piezo_tick_time_cycles() since start or the last reset. */
uint32_t piezo_tick_time_max_cycles(void);

/** Start a new maximum. */
void piezo_tick_time_reset(void);

/** The control loop's work for one tick, called from the SysTick handler. */
void piezo_control_tick(void);

#endif /* PIEZO_TICK_H */
