#include "coefset.h"

#include <stddef.h>
#include <string.h>

#include "fixed_q.h"
#include "piezo_interface.h"
#include "table_image.h"

/* Maps a kernel init error to the reason a commit reports. */
static uint16_t reason_of(int err)
{
    switch (err) {
    case PIEZO_OK:
        return PIEZO_TABLE_REASON_OK;
    case PIEZO_EORDER:
        return PIEZO_TABLE_REASON_NOT_MONOTONIC;
    default:
        /* PIEZO_EINVAL and PIEZO_ERANGE: a value or a kernel bound (the
         * section counts were checked against the set's capacity before) */
        return PIEZO_TABLE_REASON_OUT_OF_RANGE;
    }
}

/* The section `id` with the given type and lo <= count <= hi, or a reason. */
static uint16_t need(const piezo_table_info_t *info, uint16_t id, uint16_t type, uint32_t lo, uint32_t hi,
                     const piezo_section_t **out)
{
    const piezo_section_t *s = piezo_table_section(info, id);
    if (s == NULL || s->type != type) {
        return PIEZO_TABLE_REASON_BAD_SECTION;
    }
    if (s->count < lo || s->count > hi) {
        return PIEZO_TABLE_REASON_BAD_LENGTH;
    }
    *out = s;
    return PIEZO_TABLE_REASON_OK;
}

static void copy_i32(int32_t *dst, const piezo_section_t *s)
{
    for (uint32_t i = 0; i < s->count; i++) {
        dst[i] = piezo_section_i32(s, i);
    }
}

static int fits_q15(int32_t v)
{
    return v >= PIEZO_Q15_MIN && v <= PIEZO_Q15_MAX;
}

/* The KP grid shared by kp_dcc and rkp: thresholds and ridge, up to max_ops. */
static uint16_t load_grid(piezo_coefset_t *cs, const piezo_table_info_t *info, uint32_t max_ops)
{
    const piezo_section_t *g, *n1, *n2;
    uint16_t r;
    struct piezo_kp_grid *grid = &cs->dcc.grid;
    if ((r = need(info, PIEZO_SECTION_KP_GRID, PIEZO_SECTION_TYPE_INT32, 4u, 4u, &g)) != 0u ||
        (r = need(info, PIEZO_SECTION_KP_N1_Q15, PIEZO_SECTION_TYPE_INT16, 1u, max_ops, &n1)) != 0u ||
        (r = need(info, PIEZO_SECTION_KP_N2_Q15, PIEZO_SECTION_TYPE_INT16, n1->count, n1->count, &n2)) != 0u) {
        return r;
    }
    for (uint32_t i = 0; i < n1->count; i++) {
        cs->n1_q15[i] = piezo_section_i16(n1, i);
        cs->n2_q15[i] = piezo_section_i16(n2, i);
    }
    if (!fits_q15(piezo_section_i32(g, 0)) || !fits_q15(piezo_section_i32(g, 1))) {
        return PIEZO_TABLE_REASON_OUT_OF_RANGE;
    }
    grid->n1_q15 = cs->n1_q15;
    grid->n2_q15 = cs->n2_q15;
    grid->n_ops = (uint16_t)n1->count;
    grid->nmin_q15 = (int16_t)piezo_section_i32(g, 0);
    grid->rmax_q15 = (int16_t)piezo_section_i32(g, 1);
    grid->slope_q16 = piezo_section_i32(g, 2);
    grid->xsat_q15 = piezo_section_i32(g, 3);
    cs->rkp.grid = *grid;
    cs->dcc.csum_q24 = NULL; /* kp_dcc sets them once c is loaded */
    return PIEZO_TABLE_REASON_OK;
}

static uint16_t load_dcc_gain(piezo_coefset_t *cs, const piezo_table_info_t *info)
{
    const piezo_section_t *s;
    uint16_t r = need(info, PIEZO_SECTION_DCC_G_Q24, PIEZO_SECTION_TYPE_INT32, 1u, 1u, &s);
    if (r == 0u) {
        cs->dcc.g_q24 = piezo_section_i32(s, 0);
    }
    return r;
}

static uint16_t load_kp_dcc(piezo_coefset_t *cs, piezo_ff_state_t *ff, const piezo_table_info_t *info)
{
    const piezo_section_t *c;
    uint16_t r;
    if ((r = load_grid(cs, info, PIEZO_CS_MAX_KP_OPS)) != 0u || (r = load_dcc_gain(cs, info)) != 0u ||
        (r = need(info, PIEZO_SECTION_DCC_C_Q24, PIEZO_SECTION_TYPE_INT32, cs->dcc.grid.n_ops,
                  cs->dcc.grid.n_ops, &c)) != 0u) {
        return r;
    }
    copy_i32(cs->c_q24, c);
    cs->dcc.c_q24 = cs->c_q24;
    r = reason_of(piezo_dcc_init(&ff->dcc, &cs->dcc, ff->cpsi_q15, ff->zo_q15, PIEZO_CS_MAX_KP_OPS));
    /* the weights' prefix sums, for the DCC's lines that join as one (none
     * when sum |c| >= 2^31: the kernel then works operator by operator) */
    if (r == 0u && piezo_dcc_prefix_sums(&ff->dcc, cs->by_kind.dcc_csum_q24,
                                         sizeof cs->by_kind.dcc_csum_q24 / sizeof cs->by_kind.dcc_csum_q24[0]) == PIEZO_OK) {
        cs->dcc.csum_q24 = cs->by_kind.dcc_csum_q24;
    }
    return r;
}

static uint16_t load_rkp(piezo_coefset_t *cs, piezo_ff_state_t *ff, const piezo_table_info_t *info)
{
    const piezo_section_t *th, *ce, *iw, *al;
    uint16_t r;
    uint32_t n;
    if ((r = load_grid(cs, info, PIEZO_CS_MAX_RKP_OPS)) != 0u || (r = load_dcc_gain(cs, info)) != 0u ||
        (r = need(info, PIEZO_SECTION_RKP_CENTER_Q24, PIEZO_SECTION_TYPE_INT32, 1u, PIEZO_CS_MAX_RBF, &ce)) != 0u ||
        (r = need(info, PIEZO_SECTION_RKP_INV_WIDTH_Q16, PIEZO_SECTION_TYPE_INT32, ce->count, ce->count, &iw)) != 0u ||
        (r = need(info, PIEZO_SECTION_RKP_ALPHA_Q16, PIEZO_SECTION_TYPE_INT32, 1u, 1u, &al)) != 0u) {
        return r;
    }
    n = (uint32_t)cs->rkp.grid.n_ops * ce->count;
    if ((r = need(info, PIEZO_SECTION_RKP_THETA_Q24, PIEZO_SECTION_TYPE_INT32, n, n, &th)) != 0u) {
        return r;
    }
    copy_i32(cs->by_kind.theta_q24, th);
    copy_i32(cs->center_q24, ce);
    copy_i32(cs->inv_width_q16, iw);
    cs->rkp.theta_q24 = cs->by_kind.theta_q24;
    cs->rkp.center_q24 = cs->center_q24;
    cs->rkp.inv_width_q16 = cs->inv_width_q16;
    cs->rkp.n_rbf = (uint16_t)ce->count;
    cs->rkp.alpha_q16 = piezo_section_i32(al, 0);
    cs->dcc.c_q24 = cs->c_q24; /* replaced by the state's density in piezo_ff_bind */
    memset(cs->c_q24, 0, sizeof cs->c_q24);
    r = reason_of(piezo_rkp_init(&ff->rkp, &cs->rkp, ff->psi_q15, ff->w_q24, PIEZO_CS_MAX_RKP_OPS));
    return r != 0u ? r : reason_of(piezo_dcc_init(&ff->dcc, &cs->dcc, ff->cpsi_q15, ff->zo_q15, PIEZO_CS_MAX_KP_OPS));
}

static uint64_t abs64(int64_t v)
{
    return v < 0 ? (uint64_t)(-v) : (uint64_t)v;
}

/* Small-gain condition in q48 (see coefset.h); valid after the kernel's own
 * init check, which bounds the UPI weights and the polynomial.
 * d(G_UPI + P)/du lies in [lo, hi] with lo = -Pb, hi = S + Pb, where
 * S = sum_ij d_ij max(1, a_j) (every UPI slope is 0, 1 or a_j, weights >= 0)
 * and Pb = sum_m (m + 2) |p_m| bounds |P'| for |u| <= 1. Then
 * |d G2/du| <= max(hi - k_ex, k_ex - lo) must stay below a0 + k_ex. */
static uint16_t check_small_gain(const piezo_coefset_t *cs)
{
    const struct piezo_eupi_inv_coef *k = &cs->inv;
    int64_t big_a0 = (int64_t)cs->a0_q24 + k->kex_q24;
    int64_t s = 0, pb = 0, kex = (int64_t)k->kex_q24 * PIEZO_Q24_ONE, bound, prod;
    if (cs->a0_q24 <= 0 || big_a0 <= 0) {
        return PIEZO_TABLE_REASON_UNSTABLE_INVERSE;
    }
    for (uint16_t i = 0; i < k->upi.n_r; i++) {
        for (uint16_t j = 0; j < k->upi.n_a; j++) {
            int64_t slope = k->upi.a_q24[j] > (int32_t)PIEZO_Q24_ONE ? k->upi.a_q24[j] : (int64_t)PIEZO_Q24_ONE;
            s += (int64_t)k->upi.w_q24[(size_t)i * k->upi.n_a + j] * slope;
        }
    }
    for (uint16_t m = 0; m < k->n_p; m++) {
        pb += (int64_t)(m + 2u) * (int64_t)abs64(k->p_q24[m]) * PIEZO_Q24_ONE;
    }
    bound = s + pb - kex;
    if (kex + pb > bound) {
        bound = kex + pb;
    }
    if (big_a0 * PIEZO_Q24_ONE <= bound) {
        return PIEZO_TABLE_REASON_UNSTABLE_INVERSE;
    }
    /* a0_inv must be 1 / (a0 + k_ex) to within the rounding of the three
     * (half an LSB of a0_inv times a0 + k_ex, one LSB of a0 + k_ex times a0_inv) */
    prod = (int64_t)k->a0_inv_q24 * big_a0 - ((int64_t)1 << 48);
    if (abs64(prod) > (uint64_t)big_a0 + (uint64_t)k->a0_inv_q24) {
        return PIEZO_TABLE_REASON_OUT_OF_RANGE;
    }
    return PIEZO_TABLE_REASON_OK;
}

static uint16_t load_eupi_inverse(piezo_coefset_t *cs, piezo_ff_state_t *ff, const piezo_table_info_t *info)
{
    const piezo_section_t *sc, *cr, *cw, *ur, *ua, *uw, *po;
    struct piezo_eupi_inv_coef *k = &cs->inv;
    uint16_t r;
    if ((r = need(info, PIEZO_SECTION_EUPI_INV_SCALARS, PIEZO_SECTION_TYPE_INT32, 4u, 4u, &sc)) != 0u ||
        (r = need(info, PIEZO_SECTION_EUPI_CPI_INV_R_Q15, PIEZO_SECTION_TYPE_INT32, 0u, PIEZO_CS_MAX_CPI, &cr)) != 0u ||
        (r = need(info, PIEZO_SECTION_EUPI_CPI_INV_W_Q24, PIEZO_SECTION_TYPE_INT32, cr->count, cr->count, &cw)) != 0u ||
        (r = need(info, PIEZO_SECTION_EUPI_UPI_R_Q15, PIEZO_SECTION_TYPE_INT32, 0u, PIEZO_CS_MAX_UPI_R, &ur)) != 0u ||
        (r = need(info, PIEZO_SECTION_EUPI_UPI_A_Q24, PIEZO_SECTION_TYPE_INT32, ur->count ? 1u : 0u,
                  ur->count ? PIEZO_CS_MAX_UPI_A : 0u, &ua)) != 0u ||
        (r = need(info, PIEZO_SECTION_EUPI_UPI_W_Q24, PIEZO_SECTION_TYPE_INT32, ur->count * ua->count,
                  ur->count * ua->count, &uw)) != 0u ||
        (r = need(info, PIEZO_SECTION_EUPI_POLY_Q24, PIEZO_SECTION_TYPE_INT32, 0u, PIEZO_CS_MAX_POLY, &po)) != 0u) {
        return r;
    }
    copy_i32(cs->cpi_r_q15, cr);
    copy_i32(cs->cpi_w_q24, cw);
    copy_i32(cs->upi_r_q15, ur);
    copy_i32(cs->upi_a_q24, ua);
    copy_i32(cs->upi_w_q24, uw);
    copy_i32(cs->poly_q24, po);
    k->cpi_inv.r_q15 = cs->cpi_r_q15;
    k->cpi_inv.a_q24 = NULL;
    k->cpi_inv.w_q24 = cs->cpi_w_q24;
    k->cpi_inv.n_r = (uint16_t)cr->count;
    k->cpi_inv.n_a = 0u;
    k->upi.r_q15 = cs->upi_r_q15;
    k->upi.a_q24 = cs->upi_a_q24;
    k->upi.w_q24 = cs->upi_w_q24;
    k->upi.n_r = (uint16_t)ur->count;
    k->upi.n_a = (uint16_t)ua->count;
    k->p_q24 = cs->poly_q24;
    k->n_p = (uint16_t)po->count;
    k->a0_inv_q24 = piezo_section_i32(sc, 0);
    k->kex_q24 = piezo_section_i32(sc, 1);
    k->p0_q24 = piezo_section_i32(sc, 2);
    cs->a0_q24 = piezo_section_i32(sc, 3);
    r = reason_of(piezo_eupi_inv_init(&ff->inv, k, ff->inv_state_q15,
                                      sizeof ff->inv_state_q15 / sizeof ff->inv_state_q15[0],
                                      ff->inv_work_q39, sizeof ff->inv_work_q39 / sizeof ff->inv_work_q39[0]));
    return r != 0u ? r : check_small_gain(cs);
}

/* Drive of the sweep's reference r through the set (u_applied: the drive of
 * the previous sample, as the tick feeds it back). */
#define SWEEP_BINS (65536u >> 6)

/* rail: per 64-LSB bin of the reference, where the rising major branch sat
 * on a rail (bit 0 bottom, bit 1 top); NULL on other segments. check_rail:
 * the falling major branch refuses a bin railed the same way, if the table's
 * own straight line reaches that reference inside the drive range. */
static uint16_t sweep_segment(piezo_ff_state_t *ff, const piezo_coefset_t *cs, int32_t *r, int32_t to,
                              int16_t *u, piezo_sweep_stats_t *st, uint8_t *rail, int check_rail)
{
    int32_t dir = to > *r ? 1 : -1;
    while (*r != to) {
        int32_t next = *r + dir * (int32_t)PIEZO_CS_SWEEP_STEP_Q15;
        int16_t un;
        if ((dir > 0 && next > to) || (dir < 0 && next < to)) {
            next = to;
        }
        *r = next;
        un = piezo_ff_process(ff, cs, (int16_t)next, *u);
        st->samples++;
        /* monotone: along a rising reference the drive must not fall (and
         * the reverse), beyond the rounding of the kernels */
        if (dir * ((int32_t)un - *u) < -(int32_t)PIEZO_CS_SWEEP_TOL_Q15) {
            return PIEZO_TABLE_REASON_NOT_MONOTONIC;
        }
        if (dir * ((int32_t)un - *u) < st->worst_step_q15) {
            st->worst_step_q15 = dir * ((int32_t)un - *u);
        }
        /* a reference inside the central part of the position range that
         * gets the same rail whichever way it is approached */
        if (rail != NULL) {
            uint32_t bin = (uint32_t)(next + 32768) >> 6;
            uint8_t at = un == PIEZO_Q15_MIN ? 1u : un == PIEZO_Q15_MAX ? 2u : 0u;
            int16_t ul = piezo_line_q15((int16_t)next, cs->open_loop_gain_q24, cs->open_loop_offset_q15);
            if (!check_rail) {
                rail[bin] |= at;
            } else if ((rail[bin] & at) != 0u && ul >= -(int32_t)PIEZO_CS_SWEEP_LINE_Q15 &&
                       ul <= (int32_t)PIEZO_CS_SWEEP_LINE_Q15) {
                return PIEZO_TABLE_REASON_OUTPUT_RANGE;
            }
        }
        *u = un;
    }
    return PIEZO_TABLE_REASON_OK;
}

/* The sweep's reversal points (q15 reference): the whole range up and down
 * twice, then minor loops nested inside the upper and the lower half. */
static const int32_t sweep_points[] = {
    PIEZO_Q15_MIN, PIEZO_Q15_MAX, PIEZO_Q15_MIN, PIEZO_Q15_MAX, 0, 16384, 8192, 12288, 10240,
    PIEZO_Q15_MIN, -16384, -24576, -20480, -22528, 0,
};

uint16_t piezo_coefset_sweep(piezo_coefset_t *cs, piezo_ff_state_t *ff, piezo_sweep_stats_t *stats)
{
    piezo_sweep_stats_t local;
    piezo_sweep_stats_t *st = stats != NULL ? stats : &local;
    uint8_t rail[SWEEP_BINS];
    int32_t r;
    int16_t u;
    uint16_t res = PIEZO_TABLE_REASON_OK;
    st->samples = 0u;
    st->worst_step_q15 = 0;
    /* the open-loop line first: the middle of the position range must have
     * a drive inside the drive range */
    {
        int16_t ul = piezo_line_q15(0, cs->open_loop_gain_q24, cs->open_loop_offset_q15);
        if (ul == PIEZO_Q15_MIN || ul == PIEZO_Q15_MAX) {
            return PIEZO_TABLE_REASON_OUTPUT_RANGE;
        }
    }
    if (piezo_ff_bind(ff, cs) != PIEZO_OK) {
        return PIEZO_TABLE_REASON_OUT_OF_RANGE;
    }
    /* the reset state: the drive rested at the bottom of the range */
    r = PIEZO_Q15_MIN;
    u = piezo_ff_process(ff, cs, (int16_t)r, PIEZO_Q15_MIN);
    memset(rail, 0, sizeof rail);
    for (size_t i = 1; i < sizeof sweep_points / sizeof sweep_points[0] && res == PIEZO_TABLE_REASON_OK; i++) {
        /* segments 1 and 2: the major loop, rising then falling */
        res = sweep_segment(ff, cs, &r, sweep_points[i], &u, st, i <= 2u ? rail : NULL, i == 2u);
    }
    (void)piezo_ff_bind(ff, cs); /* leave the state as a fresh bind does */
    return res;
}

uint16_t piezo_coefset_load_info(piezo_coefset_t *cs, piezo_ff_state_t *ff, const piezo_table_info_t *info)
{
    const piezo_section_t *ctl;
    uint16_t r;
    cs->kind = 0u;
    if ((r = need(info, PIEZO_SECTION_CTL_SCALARS, PIEZO_SECTION_TYPE_INT32, 4u, 4u, &ctl)) != 0u) {
        return r;
    }
    /* ranges: interface.toml (checked by piezo_table_check) */
    cs->open_loop_gain_q24 = piezo_section_i32(ctl, 0);
    cs->open_loop_offset_q15 = piezo_section_i32(ctl, 1);
    cs->y_to_u_gain_q24 = piezo_section_i32(ctl, 2);
    cs->y_offset_q15 = piezo_section_i32(ctl, 3);
    switch (info->kind) {
    case PIEZO_TABLE_KIND_KP_DCC:
        r = load_kp_dcc(cs, ff, info);
        break;
    case PIEZO_TABLE_KIND_RKP:
        r = load_rkp(cs, ff, info);
        break;
    case PIEZO_TABLE_KIND_EUPI_INVERSE:
        r = load_eupi_inverse(cs, ff, info);
        break;
    default:
        r = PIEZO_TABLE_REASON_BAD_KIND;
        break;
    }
    if (r == 0u) {
        cs->kind = info->kind;
        cs->crc = info->crc;
        cs->version = info->table_version;
    } else {
        cs->kind = 0u;
    }
    return r;
}

uint16_t piezo_coefset_load(piezo_coefset_t *cs, piezo_ff_state_t *ff, const uint8_t *img, uint32_t len)
{
    piezo_table_info_t info;
    uint16_t r;
    cs->kind = 0u;
    if ((r = piezo_table_check(img, len, &info)) != 0u || (r = piezo_table_check_specs(&info)) != 0u) {
        return r;
    }
    return piezo_coefset_load_info(cs, ff, &info);
}

int piezo_ff_bind(piezo_ff_state_t *ff, const piezo_coefset_t *cs)
{
    int rc;
    switch (cs->kind) {
    case PIEZO_TABLE_KIND_KP_DCC:
        rc = piezo_dcc_init(&ff->dcc, &cs->dcc, ff->cpsi_q15, ff->zo_q15, PIEZO_CS_MAX_KP_OPS);
        if (rc == PIEZO_OK) {
            piezo_dcc_const_weights(&ff->dcc); /* the table's weights: sums kept incrementally */
        }
        return rc;
    case PIEZO_TABLE_KIND_RKP:
        ff->dcc_rate = cs->dcc;
        ff->dcc_rate.c_q24 = ff->w_q24; /* this tick's density, g folded in */
        rc = piezo_rkp_init(&ff->rkp, &cs->rkp, ff->psi_q15, ff->w_q24, PIEZO_CS_MAX_RKP_OPS);
        return rc != PIEZO_OK ? rc : piezo_dcc_init(&ff->dcc, &ff->dcc_rate, ff->cpsi_q15, ff->zo_q15, PIEZO_CS_MAX_KP_OPS);
    case PIEZO_TABLE_KIND_EUPI_INVERSE:
        return piezo_eupi_inv_init(&ff->inv, &cs->inv, ff->inv_state_q15,
                                   sizeof ff->inv_state_q15 / sizeof ff->inv_state_q15[0], ff->inv_work_q39,
                                   sizeof ff->inv_work_q39 / sizeof ff->inv_work_q39[0]);
    default:
        return PIEZO_EINVAL;
    }
}

int16_t piezo_line_q15(int16_t r_q15, int32_t gain_q24, int32_t offset_q15)
{
    /* rshift_rnd(r g + o 2^24, 24) = o + rshift_rnd(r g, 24) exactly (o 2^24
     * is whole steps); |r g| < 2^46, so that term fits int32; the sum
     * saturated to int32 (QADD) and then to q15 is the q15 saturation of the
     * exact sum; rshift_rnd(r g, 24) as the rounded high word of (r 2^8) g
     * (one SMMULR on the Cortex-M4, round 17) */
    return piezo_sat_q15(piezo_add_sat_i32(offset_q15, piezo_mul_hi_rnd((int32_t)r_q15 * 256, gain_q24)));
}

/* The RKP kind's tick, out of line: its call to piezo_rkp_process() would
 * make piezo_ff_process() save registers for every kind. */
static int16_t __attribute__((noinline)) ff_rkp(piezo_ff_state_t *ff, const piezo_coefset_t *cs, int16_t r_q15,
                                                int16_t u_applied_q15)
{
    (void)piezo_rkp_process(&ff->rkp, u_applied_q15); /* the density of this rate */
    ff->dcc.u_last_q15 = u_applied_q15;
    return piezo_dcc_process(&ff->dcc, piezo_line_q15(r_q15, cs->y_to_u_gain_q24, cs->y_offset_q15));
}

/* The kinds after the DCC and the EUPI inverse (the RKP, else the line), out
 * of line: the line's registers here would make piezo_ff_process() save
 * registers for every kind (round 16). */
static int16_t __attribute__((noinline, used)) ff_rest(piezo_ff_state_t *ff, const piezo_coefset_t *cs, int16_t r_q15,
                                                 int16_t u_applied_q15)
{
    if (cs->kind == PIEZO_TABLE_KIND_RKP) {
        return ff_rkp(ff, cs, r_q15, u_applied_q15);
    }
    return piezo_line_q15(r_q15, cs->open_loop_gain_q24, cs->open_loop_offset_q15);
}

#if defined(__thumb2__) && defined(__ARM_ARCH_7EM__) && defined(__GNUC__)
/* The C form below, in Thumb-2 (round 17): gcc saved and restored four
 * registers on every kind's path (a value kept in r4 for the DCC's store,
 * the kind in a saved register) and sign-extended the line's SSAT #16
 * result, which is already an int16_t in its register: 10 instructions to
 * the DCC's call instead of 14, 8 to the EUPI inverse's instead of 10. The
 * line is piezo_line_q15's (one SMMULR, QADD, SSAT #16). test_controller's
 * golden DCC and EUPI inverse runs check it against the C under QEMU. */
typedef char piezo_ff_process_m4_layout_check_t[
    (offsetof(piezo_ff_state_t, dcc) == 0u && offsetof(struct piezo_dcc, u_last_q15) == 36u &&
     offsetof(piezo_ff_state_t, inv) == 376u && offsetof(piezo_coefset_t, kind) == 0u &&
     offsetof(piezo_coefset_t, y_to_u_gain_q24) == 20u && offsetof(piezo_coefset_t, y_offset_q15) == 24u &&
     PIEZO_TABLE_KIND_KP_DCC == 1u && PIEZO_TABLE_KIND_EUPI_INVERSE == 3u) ? 1 : -1];

__attribute__((naked, noinline)) int16_t piezo_ff_process(piezo_ff_state_t *ff, const piezo_coefset_t *cs,
                                                          int16_t r_q15, int16_t u_applied_q15)
{
    (void)ff;
    (void)cs;
    (void)r_q15;
    (void)u_applied_q15;
    __asm__ volatile(
        "    ldrh   ip, [r1]\n"           /* kind */
        "    cmp    ip, #1\n"
        "    bne    1f\n"
        "    strh   r3, [r0, #36]\n"      /* ff->dcc.u_last_q15 = u_applied */
        "    ldrd   r3, r1, [r1, #20]\n"  /* y_to_u_gain_q24, y_offset_q15 */
        "    lsls   r2, r2, #8\n"
        "    smmulr r2, r2, r3\n"         /* rshift_rnd(r g, 24) */
        "    qadd   r1, r1, r2\n"
        "    ssat   r1, #16, r1\n"
        "    b.w    piezo_dcc_process\n"
        "1:  cmp    ip, #3\n"
        "    bne.w  ff_rest\n"
        "    mov    r1, r2\n"
        "    add    r0, r0, #376\n"       /* &ff->inv */
        "    b.w    piezo_eupi_inv_process\n");
}
#else
int16_t piezo_ff_process(piezo_ff_state_t *ff, const piezo_coefset_t *cs, int16_t r_q15, int16_t u_applied_q15)
{
    /* the kinds tested in this order, not by a switch: gcc's switch tested
     * the RKP and EUPI kinds before the DCC (issue 15, round 14) */
    const uint16_t kind = cs->kind;
    if (kind == PIEZO_TABLE_KIND_KP_DCC) {
        ff->dcc.u_last_q15 = u_applied_q15;
        return piezo_dcc_process(&ff->dcc, piezo_line_q15(r_q15, cs->y_to_u_gain_q24, cs->y_offset_q15));
    }
    if (kind == PIEZO_TABLE_KIND_EUPI_INVERSE) {
        return piezo_eupi_inv_process(&ff->inv, r_q15);
    }
    return ff_rest(ff, cs, r_q15, u_applied_q15);
}
#endif

uint16_t piezo_xcset_load(piezo_xcset_t *xs, struct piezo_xc *st, const uint8_t *img, uint32_t len)
{
    piezo_table_info_t info;
    uint16_t r;
    xs->kind = 0u;
    if ((r = piezo_table_check(img, len, &info)) != 0u || (r = piezo_table_check_specs(&info)) != 0u) {
        return r;
    }
    return piezo_xcset_load_info(xs, st, &info);
}

uint16_t piezo_xcset_load_info(piezo_xcset_t *xs, struct piezo_xc *st, const piezo_table_info_t *ip)
{
    const piezo_table_info_t info = *ip;
    const piezo_section_t *sc, *a, *b, *e, *eta, *xi;
    struct piezo_xc_coef *k = &xs->xc;
    uint32_t m, nch, npow, ndeg;
    uint16_t r;
    xs->kind = 0u;
    if (info.kind != PIEZO_TABLE_KIND_CROSS_COUPLING) {
        return PIEZO_TABLE_REASON_BAD_KIND;
    }
    if ((r = need(&info, PIEZO_SECTION_XC_SCALARS, PIEZO_SECTION_TYPE_INT32, 9u, 9u, &sc)) != 0u) {
        return r;
    }
    m = (uint32_t)piezo_section_i32(sc, 0);
    nch = (uint32_t)piezo_section_i32(sc, 1);
    npow = (uint32_t)piezo_section_i32(sc, 2);
    ndeg = (uint32_t)piezo_section_i32(sc, 3);
    if (m < 1u || m > PIEZO_XC_MAX_M || nch < 1u || nch > PIEZO_XC_MAX_CH || npow < 1u ||
        npow > PIEZO_XC_MAX_POW || ndeg < 1u || ndeg > PIEZO_XC_MAX_DEG) {
        return PIEZO_TABLE_REASON_BAD_LENGTH;
    }
    if ((r = need(&info, PIEZO_SECTION_XC_A_Q24, PIEZO_SECTION_TYPE_INT32, m * m, m * m, &a)) != 0u ||
        (r = need(&info, PIEZO_SECTION_XC_B_Q24, PIEZO_SECTION_TYPE_INT32, m, m, &b)) != 0u ||
        (r = need(&info, PIEZO_SECTION_XC_E_Q24, PIEZO_SECTION_TYPE_INT32, m, m, &e)) != 0u ||
        (r = need(&info, PIEZO_SECTION_XC_ETA_Q24, PIEZO_SECTION_TYPE_INT32, nch * npow * ndeg, nch * npow * ndeg,
                  &eta)) != 0u ||
        (r = need(&info, PIEZO_SECTION_XC_XI_Q24, PIEZO_SECTION_TYPE_INT32, nch * m * ndeg, nch * m * ndeg, &xi)) != 0u) {
        return r;
    }
    if (piezo_section_i32(sc, 8) != 0 && piezo_section_i32(sc, 8) != 1) {
        return PIEZO_TABLE_REASON_OUT_OF_RANGE;
    }
    copy_i32(xs->a_q24, a);
    copy_i32(xs->b_q24, b);
    copy_i32(xs->e_q24, e);
    copy_i32(xs->eta_q24, eta);
    copy_i32(xs->xi_q24, xi);
    k->m = (uint8_t)m;
    k->n_ch = (uint8_t)nch;
    k->n_pow = (uint8_t)npow;
    k->n_deg = (uint8_t)ndeg;
    k->u_center_q15 = piezo_section_i32(sc, 4);
    k->u_gain_q16 = piezo_section_i32(sc, 5);
    k->x_center_q15 = piezo_section_i32(sc, 6);
    k->x_gain_q16 = piezo_section_i32(sc, 7);
    k->a_q24 = xs->a_q24;
    k->b_q24 = xs->b_q24;
    k->e_q24 = xs->e_q24;
    k->eta_q24 = xs->eta_q24;
    k->xi_q24 = xs->xi_q24;
    xs->x_source = (uint8_t)piezo_section_i32(sc, 8);
    if (piezo_xc_init(st, k) != PIEZO_OK) {
        return PIEZO_TABLE_REASON_OUT_OF_RANGE; /* a kernel bound (sizes were checked above) */
    }
    xs->kind = info.kind;
    xs->crc = info.crc;
    xs->version = info.table_version;
    return PIEZO_TABLE_REASON_OK;
}
