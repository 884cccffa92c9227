/* stage_bench: how many stage_step() calls per second (CPU time).
 *
 *   stage_bench [PARAMS.json] [SAMPLES]
 *
 * Drives every axis with a full-range 10 Hz sine of DAC codes (the default
 * stage when no file is given) and prints steps per second and the real-time
 * factor at the stage's sample rate. */
#include "stage_model.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

int main(int argc, char **argv)
{
    stage_params p = stage_params_default();
    stage_t s;
    char err[512];
    long n = 2000000, k;
    int32_t dac[STAGE_MAX_AXES], adc[STAGE_MAX_AXES];
    int64_t sum = 0;
    clock_t t0, t1;
    double sec;

    if (argc > 1 && stage_params_load_json(argv[1], &p, err, sizeof err) != STAGE_OK) {
        fprintf(stderr, "stage_bench: %s\n", err);
        return 2;
    }
    if (argc > 2) {
        n = strtol(argv[2], NULL, 10);
    }
    if (stage_init(&s, &p, 1) != STAGE_OK) {
        fprintf(stderr, "stage_bench: stage_init failed\n");
        return 2;
    }
    t0 = clock();
    for (k = 0; k < n; k++) {
        double ph = 2.0 * 3.14159265358979 * 10.0 * (double)k / p.sample_rate_hz;
        int32_t c = (int32_t)(32767.5 - 32767.0 * cos(ph));
        dac[0] = c;
        dac[1] = 65535 - c;
        stage_step(&s, dac, adc);
        sum += adc[0];
    }
    t1 = clock();
    sec = (double)(t1 - t0) / CLOCKS_PER_SEC;
    printf("%s: %d axis, %ld steps in %.3f s: %.0f steps/s, %.3f us/step (incl. the cos of the drive), "
           "%.0fx real time at %.0f Hz (checksum %lld)\n",
           p.name, p.num_axes, n, sec, (double)n / sec, 1e6 * sec / (double)n,
           (double)n / sec / p.sample_rate_hz, p.sample_rate_hz, (long long)sum);
    return 0;
}
