#include "xcouple.h"

#include <stddef.h>

#include "fixed_q.h"
#include "piezo_err.h"

#define Q24_ONE ((int64_t)1 << 24)

static int64_t iabs64(int64_t v)
{
    return v < 0 ? -v : v;
}

/* Smallest s_i <= PIEZO_XC_MAX_SHIFT with a state bound Z_i = 2^(24 + s_i)
 * for every row (xcouple.h), or -1. */
static int state_bounds(const struct piezo_xc_coef *k, int64_t z_q24[PIEZO_XC_MAX_M], unsigned shift[PIEZO_XC_MAX_M])
{
    for (uint8_t i = 0; i < k->m; i++) {
        int64_t aii = k->a_q24[i * k->m + i];
        int64_t rhs = iabs64(k->b_q24[i]) * Q24_ONE + Q24_ONE;
        int ok = 0;
        for (uint8_t j = 0; j < i; j++) {
            rhs += iabs64(k->a_q24[i * k->m + j]) * z_q24[j];
        }
        for (unsigned s = 0; s <= PIEZO_XC_MAX_SHIFT && !ok; s++) {
            int64_t z = Q24_ONE << s;
            if ((Q24_ONE - aii) * z >= rhs && iabs64(k->e_q24[i]) < z) {
                z_q24[i] = z;
                shift[i] = s;
                ok = 1;
            }
        }
        if (!ok) {
            return -1;
        }
    }
    return 0;
}

int piezo_xc_init(struct piezo_xc *s, const struct piezo_xc_coef *k)
{
    int64_t z_q24[PIEZO_XC_MAX_M];
    unsigned shift[PIEZO_XC_MAX_M];
    if (s == NULL || k == NULL || k->a_q24 == NULL || k->b_q24 == NULL || k->e_q24 == NULL ||
        k->eta_q24 == NULL || k->xi_q24 == NULL || k->m < 1u || k->m > PIEZO_XC_MAX_M || k->n_ch < 1u ||
        k->n_ch > PIEZO_XC_MAX_CH || k->n_pow < 1u || k->n_pow > PIEZO_XC_MAX_POW || k->n_deg < 1u ||
        k->n_deg > PIEZO_XC_MAX_DEG) {
        return PIEZO_EINVAL;
    }
    if (k->u_gain_q16 <= 0 || k->x_gain_q16 <= 0 || k->u_center_q15 < -32768 || k->u_center_q15 > 32768 ||
        k->x_center_q15 < -32768 || k->x_center_q15 > 32768) {
        return PIEZO_ERANGE;
    }
    for (uint8_t i = 0; i < k->m; i++) {
        if (k->a_q24[i * k->m + i] < 0 || k->a_q24[i * k->m + i] >= Q24_ONE ||
            iabs64(k->b_q24[i]) >= 2 * Q24_ONE) {
            return PIEZO_ERANGE;
        }
        for (uint8_t j = 0; j < k->m; j++) {
            int32_t a = k->a_q24[i * k->m + j];
            if ((j > i && a != 0) || iabs64(a) >= 2 * Q24_ONE) {
                return PIEZO_ERANGE;
            }
        }
    }
    for (uint8_t c = 0; c < k->n_ch; c++) {
        int64_t eta_sum = 0;
        for (uint32_t q = 0; q < (uint32_t)k->n_pow * k->n_deg; q++) {
            eta_sum += iabs64(k->eta_q24[(uint32_t)c * k->n_pow * k->n_deg + q]);
        }
        if (eta_sum > Q24_ONE) {
            return PIEZO_ERANGE;
        }
    }
    if (state_bounds(k, z_q24, shift) != 0) {
        return PIEZO_ERANGE;
    }
    /* output: (sum_b |xi_cib| + 1) Z_i <= 2^59 for each (c, i), so the
     * accumulator of at most 8 products stays below 2^62; Z_i = 2^(24 + s_i) */
    for (uint8_t c = 0; c < k->n_ch; c++) {
        for (uint8_t i = 0; i < k->m; i++) {
            int64_t sum = 1;
            for (uint8_t b = 0; b < k->n_deg; b++) {
                sum += iabs64(k->xi_q24[((uint32_t)c * k->m + i) * k->n_deg + b]);
            }
            if (sum > ((int64_t)1 << (35u - shift[i]))) {
                return PIEZO_ERANGE;
            }
        }
    }
    s->k = k;
    piezo_xc_reset(s);
    return PIEZO_OK;
}

void piezo_xc_reset(struct piezo_xc *s)
{
    for (uint32_t i = 0; i < PIEZO_XC_MAX_CH * PIEZO_XC_MAX_M; i++) {
        s->zeta_q24[i] = 0;
    }
    s->started = 0u;
}

/* clamp(rshift_rnd((v - c) g, 16), +-32767): a normalized input */
static int32_t normalize(int16_t v_q15, int32_t center_q15, int32_t gain_q16)
{
    int64_t n = piezo_rshift_rnd64(((int64_t)v_q15 - center_q15) * gain_q16, 16u);
    return (int32_t)(n > 32767 ? 32767 : (n < -32767 ? -32767 : n));
}

/* out[0] = 32768, out[j] = rshift_rnd(out[j-1] v, 15): |out[j]| <= 2^15 */
static void powers(int32_t v_q15, uint8_t n, int32_t *out)
{
    out[0] = 32768;
    for (uint8_t j = 1; j < n; j++) {
        out[j] = (int32_t)piezo_rshift_rnd64((int64_t)out[j - 1] * v_q15, 15u);
    }
}

int16_t piezo_xc_process(struct piezo_xc *s, int16_t u_q15, int16_t x_q15)
{
    const struct piezo_xc_coef *k = s->k;
    int32_t p[PIEZO_XC_MAX_POW], sx[PIEZO_XC_MAX_DEG];
    int64_t mu_q24[PIEZO_XC_MAX_CH];
    int64_t out = 0;
    const uint8_t m = k->m, nd = k->n_deg, np = k->n_pow;

    powers(normalize(u_q15, k->u_center_q15, k->u_gain_q16), np, p);
    powers(normalize(x_q15, k->x_center_q15, k->x_gain_q16), nd, sx);

    for (uint8_t c = 0; c < k->n_ch; c++) {
        const int32_t *eta = k->eta_q24 + (uint32_t)c * np * nd;
        int64_t acc = 0; /* Q39, <= 2^39 */
        for (uint8_t j = 0; j < np; j++) {
            for (uint8_t b = 0; b < nd; b++) {
                int64_t f = piezo_rshift_rnd64((int64_t)p[j] * sx[b], 15u); /* q15, <= 2^15 */
                acc += (int64_t)eta[j * nd + b] * f;
            }
        }
        mu_q24[c] = piezo_rshift_rnd64(acc, 15u);
    }

    if (!s->started) { /* steady start: the equilibrium of this input */
        for (uint8_t c = 0; c < k->n_ch; c++) {
            for (uint8_t i = 0; i < m; i++) {
                s->zeta_q24[c * m + i] = piezo_rshift_rnd64((int64_t)k->e_q24[i] * mu_q24[c], 24u);
            }
        }
        s->started = 1u;
    }

    for (uint8_t c = 0; c < k->n_ch; c++) {
        int64_t *z = s->zeta_q24 + c * m;
        const int32_t *xi = k->xi_q24 + (uint32_t)c * m * nd;
        /* output with the states of time t */
        for (uint8_t i = 0; i < m; i++) {
            int64_t rho = 0; /* Q39 */
            for (uint8_t b = 0; b < nd; b++) {
                rho += (int64_t)xi[i * nd + b] * sx[b];
            }
            out += piezo_rshift_rnd64(rho, 15u) * z[i]; /* Q48, <= 2^58 in all */
        }
        /* states of time t + 1 from those of time t: A is lower triangular, so
         * updating the rows from the last one up reads only old states */
        for (uint8_t ii = m; ii > 0u; ii--) {
            uint8_t i = (uint8_t)(ii - 1u);
            int64_t acc = (int64_t)k->b_q24[i] * mu_q24[c];
            for (uint8_t j = 0; j <= i; j++) {
                acc += (int64_t)k->a_q24[i * m + j] * z[j];
            }
            z[i] = piezo_rshift_rnd64(acc, 24u);
        }
    }
    return piezo_sat_q15(piezo_rshift_rnd64(out, 33u));
}
