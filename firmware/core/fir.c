#include "fir.h"

#include "fixed_q.h"
#include "piezo_err.h"

int piezo_fir_check(const piezo_fir_coef_t *k)
{
    if (k == 0 || k->n_taps > PIEZO_FIR_MAX_TAPS || k->spacing > PIEZO_FIR_MAX_SPACING) {
        return PIEZO_EINVAL;
    }
    return PIEZO_OK;
}

void piezo_fir_reset(piezo_fir_t *f, int16_t x0_q15)
{
    for (uint32_t i = 0; i < PIEZO_FIR_HIST; i++) {
        f->hist_q15[i] = x0_q15;
    }
    f->pos = 0u;
}

int16_t piezo_fir_q13_process(piezo_fir_t *f, const piezo_fir_coef_t *k, int16_t x_q15)
{
    uint8_t d = k->spacing > 1u ? k->spacing : 1u;
    uint8_t i = f->pos;
    int64_t acc = 0;
    f->hist_q15[i] = x_q15;
    f->pos = (uint8_t)(i + 1u);
    for (uint8_t t = 0; t < k->n_taps; t++) {
        acc += (int32_t)k->h_q13[t] * f->hist_q15[i]; /* |product| <= 2^30: int32 */
        i = (uint8_t)(i - d);                          /* the ring's wrap is uint8_t's */
    }
    return piezo_sat_q15(piezo_rshift_rnd64(acc, PIEZO_FIR_Q13_FRAC));
}
