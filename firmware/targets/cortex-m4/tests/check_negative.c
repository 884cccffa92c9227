/*
 * Code the division/float checks must refuse (tests check_refuses_*): a
 * control hook in the tick path that divides 64-bit values (a libgcc helper),
 * divides in hardware and computes in floating point.
 */
#include <stdint.h>

#include "tick.h"

volatile int64_t neg_num = 1000, neg_den = 7;
volatile int32_t neg_a = 100, neg_b = 3;
volatile float neg_f = 1.5f;
volatile int32_t neg_out;

void piezo_control_tick(void)
{
    neg_out = (int32_t)(neg_num / neg_den) + neg_a / neg_b + (int32_t)(neg_f * 3.0f);
}

int main(void)
{
    return 0;
}
