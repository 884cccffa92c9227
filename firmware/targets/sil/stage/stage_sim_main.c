/* stage_sim: drives the stage model through stage_step() with DAC codes, as the
 * SIL firmware does, and writes the ADC codes and the displacement they mean.
 *
 *   stage_sim PARAMS.json INPUT.csv OUTPUT.csv [SEED]
 *
 * INPUT.csv: '#' lines are skipped, then a header naming the columns u (drive
 * [V], axis 1) and optionally u2 (axis 2; 0 V when absent), one row per sample
 * at the stage's sample rate. OUTPUT.csv: k,adc[,adc2],y[,y2] with y in um
 * printed with 17 significant digits (it reads back exactly). */
#include "stage_model.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LINE_MAX_LEN 4096
#define MAX_COLS 16

static int split(char *line, char *cols[], int max)
{
    int n = 0;
    char *p = line;
    for (;;) {
        char *c = strchr(p, ',');
        if (n == max) {
            return n;
        }
        cols[n++] = p;
        if (!c) {
            break;
        }
        *c = '\0';
        p = c + 1;
    }
    return n;
}

static void chomp(char *s)
{
    size_t n = strlen(s);
    while (n > 0 && (s[n - 1] == '\n' || s[n - 1] == '\r' || s[n - 1] == ' ')) {
        s[--n] = '\0';
    }
}

int main(int argc, char **argv)
{
    stage_params p;
    stage_t s;
    char err[512], line[LINE_MAX_LEN];
    char *cols[MAX_COLS];
    FILE *in, *out;
    int iu = -1, iu2 = -1, ncols, i, header = 0;
    unsigned long long seed = 1;
    unsigned long k = 0;

    if (argc < 4 || argc > 5) {
        fprintf(stderr, "usage: %s PARAMS.json INPUT.csv OUTPUT.csv [SEED]\n", argv[0]);
        return 2;
    }
    if (argc == 5) {
        seed = strtoull(argv[4], NULL, 0);
    }
    if (stage_params_load_json(argv[1], &p, err, sizeof err) != STAGE_OK) {
        fprintf(stderr, "stage_sim: %s\n", err);
        return 2;
    }
    if (stage_init(&s, &p, seed) != STAGE_OK) {
        fprintf(stderr, "stage_sim: stage_init failed\n");
        return 2;
    }
    in = fopen(argv[2], "r");
    if (!in) {
        fprintf(stderr, "stage_sim: cannot open %s\n", argv[2]);
        return 2;
    }
    out = fopen(argv[3], "w");
    if (!out) {
        fclose(in);
        fprintf(stderr, "stage_sim: cannot write %s\n", argv[3]);
        return 2;
    }
    while (fgets(line, sizeof line, in)) {
        int32_t dac[STAGE_MAX_AXES] = {0, 0}, adc[STAGE_MAX_AXES] = {0, 0};
        chomp(line);
        if (line[0] == '#' || line[0] == '\0') {
            continue;
        }
        ncols = split(line, cols, MAX_COLS);
        if (!header) {
            for (i = 0; i < ncols; i++) {
                if (strcmp(cols[i], "u") == 0) iu = i;
                if (strcmp(cols[i], "u2") == 0) iu2 = i;
            }
            if (iu < 0) {
                fprintf(stderr, "stage_sim: %s: no column u\n", argv[2]);
                fclose(in);
                fclose(out);
                return 2;
            }
            header = 1;
            fprintf(out, p.num_axes == 2 ? "k,adc,adc2,y,y2\n" : "k,adc,y\n");
            continue;
        }
        if (iu >= ncols || (iu2 >= ncols)) {
            fprintf(stderr, "stage_sim: %s: short row %lu\n", argv[2], k);
            fclose(in);
            fclose(out);
            return 2;
        }
        dac[0] = stage_drive_to_dac_code(&s, 0, strtod(cols[iu], NULL));
        if (p.num_axes == 2) {
            dac[1] = stage_drive_to_dac_code(&s, 1, iu2 >= 0 ? strtod(cols[iu2], NULL) : 0.0);
        }
        stage_step(&s, dac, adc);
        if (p.num_axes == 2) {
            fprintf(out, "%lu,%ld,%ld,%.17g,%.17g\n", k, (long)adc[0], (long)adc[1],
                    stage_adc_code_to_um(&s, 0, adc[0]), stage_adc_code_to_um(&s, 1, adc[1]));
        } else {
            fprintf(out, "%lu,%ld,%.17g\n", k, (long)adc[0], stage_adc_code_to_um(&s, 0, adc[0]));
        }
        k++;
    }
    fclose(in);
    if (fclose(out) != 0) {
        fprintf(stderr, "stage_sim: error writing %s\n", argv[3]);
        return 2;
    }
    return 0;
}
