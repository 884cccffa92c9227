#define _POSIX_C_SOURCE 200809L
/* The commit's checks on the calibrated SIL tables (issue 13): field ranges,
 * unknown and missing sections, the kernel sweep, the stage and axis the
 * image was built for, and the session rules of unlock and upload. Every
 * refusal is asserted together with the active table staying as it was. */
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "piezo_test.h"
#include "controller.h"
#include "crc32.h"
#include "ctl_test_cfg.h"
#include "piezo_err.h"
#include "sil_tables_vectors.h"
#include "table_image.h"

static piezo_ctl_t ctl; /* large: not on the stack */
static uint8_t img[PIEZO_TABLE_MAX_BYTES];

#define S1 1u
#define S2 2u

/* The SIL stage's identity (the scale piezo_sil_ctl_config derives). */
static piezo_ctl_stage_t sil_stage(void)
{
    piezo_ctl_stage_t s = {1u, 0u, (int32_t)(SIL_SCALE_DRIVE_MIN_V * 1000.0), (int32_t)(SIL_SCALE_DRIVE_MAX_V * 1000.0),
                           (int32_t)(SIL_SCALE_POSITION_MIN_UM * 1000.0),
                           (int32_t)(SIL_SCALE_POSITION_MAX_UM * 1000.0)};
    return s;
}

static void tick(void)
{
    int32_t in[2] = {0, 0}, dac = 0;
    piezo_ctl_tick(&ctl, in, &dac);
}

static uint16_t upload(uint8_t session, const uint8_t *p, uint32_t len)
{
    uint16_t r;
    if (piezo_ctl_stage_write(&ctl, session, 0u, p, len) != PIEZO_OK) {
        return ctl.st.table_result;
    }
    r = piezo_ctl_commit(&ctl, session, 0u);
    tick();
    return r;
}

/* A controller for the SIL stage, session 1 unlocked, the calibrated DCC
 * table active. */
static void setup_with_table(void)
{
    piezo_ctl_cfg_t cfg = unit_cfg();
    piezo_ctl_stage_t st = sil_stage();
    assert_int_equal(piezo_ctl_init(&ctl, &cfg), PIEZO_OK);
    piezo_ctl_set_stage(&ctl, &st);
    piezo_ctl_set_key(&ctl, TEST_UNLOCK_KEY);
    assert_int_equal(piezo_ctl_unlock(&ctl, S1, TEST_UNLOCK_KEY, 0u), PIEZO_OK);
    assert_int_equal(upload(S1, sil_dcc_img, SIL_DCC_IMG_LEN), PIEZO_TABLE_REASON_OK);
    assert_int_equal(ctl.set[ctl.active].kind, PIEZO_TABLE_KIND_KP_DCC);
}

static uint32_t dcc_crc(void)
{
    return piezo_le32(sil_dcc_img + SIL_DCC_IMG_LEN - 4u);
}

/* The CRC of a changed copy, recomputed. */
static void fix_crc(uint8_t *p, uint32_t len)
{
    uint32_t c = piezo_crc32(0u, p, len - 4u);
    for (int k = 0; k < 4; k++) {
        p[len - 4u + (uint32_t)k] = (uint8_t)(c >> (8 * k));
    }
}

static void put32(uint8_t *p, uint32_t v)
{
    for (int k = 0; k < 4; k++) {
        p[k] = (uint8_t)(v >> (8 * k));
    }
}

/* img = the calibrated EUPI inverse image; info describes it. */
static void eupi_copy(piezo_table_info_t *info)
{
    memcpy(img, sil_eupi_img, SIL_EUPI_IMG_LEN);
    assert_int_equal(piezo_table_check(img, SIL_EUPI_IMG_LEN, info), PIEZO_TABLE_REASON_OK);
}

static uint8_t *elem0(const piezo_table_info_t *info, uint16_t id)
{
    const piezo_section_t *s = piezo_table_section(info, id);
    assert_non_null(s);
    return img + (s->data - img);
}

static void assert_refused(uint16_t r, uint16_t want)
{
    if (r != want) {
        fprintf(stderr, "got %s, want %s\n", piezo_table_reason_str(r), piezo_table_reason_str(want));
    }
    assert_int_equal(r, want);
    assert_true(piezo_ctl_active_crc(&ctl) == dcc_crc()); /* the running table stayed */
}

/* The test: the first element of each int32 section of a calibrated
 * eupi_inverse image set to INT32_MAX, then to INT32_MIN, CRC recomputed. */
static void test_sixteen_absurd_images_are_refused(void **state)
{
    (void)state;
    piezo_table_info_t info;
    unsigned tried = 0, refused = 0;
    setup_with_table();
    /* the image itself is good */
    eupi_copy(&info);
    for (uint16_t i = 0; i < info.n_sections; i++) {
        for (int sign = 0; sign < 2; sign++) {
            piezo_table_info_t k;
            uint16_t id, r;
            eupi_copy(&k);
            if (k.section[i].type != PIEZO_SECTION_TYPE_INT32 || k.section[i].count == 0u) {
                continue;
            }
            id = k.section[i].id;
            put32(elem0(&k, id), sign == 0 ? 0x7FFFFFFFu : 0x80000000u);
            fix_crc(img, SIL_EUPI_IMG_LEN);
            r = upload(S1, img, SIL_EUPI_IMG_LEN);
            tried++;
            refused += r != PIEZO_TABLE_REASON_OK;
            printf("section %2u element 0 = %s: %s\n", id, sign == 0 ? "INT32_MAX" : "INT32_MIN",
                   piezo_table_reason_str(r));
            assert_true(r != PIEZO_TABLE_REASON_OK);
            assert_true(piezo_ctl_active_crc(&ctl) == dcc_crc());
        }
    }
    printf("absurd eupi_inverse images: %u tried, %u refused\n", tried, refused);
    assert_int_equal(tried, 16);
    assert_int_equal(refused, 16);
    /* and the untouched image is committed */
    assert_int_equal(upload(S1, sil_eupi_img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OK);
}

/* The other examples, each with its own reason code. */
static void test_each_check_has_its_reason(void **state)
{
    (void)state;
    piezo_table_info_t info;
    setup_with_table();

    /* CPI-inverse weights of +-2^31: outside [-16, 0] */
    eupi_copy(&info);
    put32(elem0(&info, PIEZO_SECTION_EUPI_CPI_INV_W_Q24), 0x7FFFFFFFu);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OUT_OF_RANGE);

    /* an open-loop gain of INT32_MAX */
    eupi_copy(&info);
    put32(elem0(&info, PIEZO_SECTION_CTL_SCALARS), 0x7FFFFFFFu);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OUT_OF_RANGE);

    /* a UPI threshold of 40000 (thresholds below 1 FS) */
    eupi_copy(&info);
    put32(elem0(&info, PIEZO_SECTION_EUPI_UPI_R_Q15), 40000u);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OUT_OF_RANGE);

    /* an unknown section id 999 (the section's id field rewritten) */
    eupi_copy(&info);
    {
        uint8_t *hdr = elem0(&info, PIEZO_SECTION_EUPI_POLY_Q24) - 8;
        hdr[0] = (uint8_t)999u;
        hdr[1] = (uint8_t)(999u >> 8);
    }
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_UNKNOWN_SECTION);

    /* a section of another kind (the DCC gain in an EUPI table) */
    eupi_copy(&info);
    {
        uint8_t *hdr = elem0(&info, PIEZO_SECTION_EUPI_POLY_Q24) - 8;
        hdr[0] = (uint8_t)PIEZO_SECTION_DCC_G_Q24;
        hdr[1] = 0u;
    }
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_UNKNOWN_SECTION);

    /* an eupi table with no polynomial: the last section dropped */
    eupi_copy(&info);
    {
        uint32_t cut = (uint32_t)(elem0(&info, PIEZO_SECTION_EUPI_POLY_Q24) - 8 - img);
        const piezo_section_t *po = piezo_table_section(&info, PIEZO_SECTION_EUPI_POLY_Q24);
        uint32_t len = SIL_EUPI_IMG_LEN - 8u - 4u * po->count;
        assert_true(cut + 8u + 4u * po->count + 4u == SIL_EUPI_IMG_LEN); /* it is the last one */
        put32(img + PIEZO_TABLE_HDR_PAYLOAD_LEN_OFFSET, len - PIEZO_TABLE_HDR_BYTES - 4u);
        img[PIEZO_TABLE_HDR_N_SECTIONS_OFFSET] = (uint8_t)(info.n_sections - 1u);
        fix_crc(img, len);
        ctl.staged_len = 0u;
        assert_refused(upload(S1, img, len), PIEZO_TABLE_REASON_MISSING_SECTION);
    }

    /* weights in range but inverted in sign where the model must rise: the
     * sweep (the small-gain check passes: the UPI part is untouched) */
    eupi_copy(&info);
    put32(elem0(&info, PIEZO_SECTION_EUPI_INV_SCALARS), 1u); /* a0' of 1 LSB: inconsistent with a0 + k_ex */
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OUT_OF_RANGE);

    /* a UPI too strong for the small-gain margin */
    eupi_copy(&info);
    {
        const piezo_section_t *w = piezo_table_section(&info, PIEZO_SECTION_EUPI_UPI_W_Q24);
        for (uint32_t k = 0; k < w->count; k++) {
            uint8_t *q = img + (w->data - img) + 4u * k;
            put32(q, 6u * piezo_le32(q)); /* six times the calibrated weights */
        }
    }
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_UNSTABLE_INVERSE);

    /* the open-loop line pinning a rail at mid-range: offset of -2 FS */
    eupi_copy(&info);
    put32(elem0(&info, PIEZO_SECTION_CTL_SCALARS) + 4, (uint32_t)-65536);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OUTPUT_RANGE);
}

/* img = the calibrated EUPI inverse image with its polynomial (the last
 * section) replaced by p[0..n-1]; returns the image's length. */
static uint32_t eupi_with_poly(const int32_t *p, uint32_t n)
{
    piezo_table_info_t info;
    eupi_copy(&info);
    const piezo_section_t *po = piezo_table_section(&info, PIEZO_SECTION_EUPI_POLY_Q24);
    uint8_t *hdr = elem0(&info, PIEZO_SECTION_EUPI_POLY_Q24) - 8;
    assert_true((uint32_t)(hdr - img) + 8u + 4u * po->count + 4u == SIL_EUPI_IMG_LEN); /* the last one */
    put32(hdr + 4, n);
    for (uint32_t k = 0; k < n; k++) {
        put32(hdr + 8 + 4u * k, (uint32_t)p[k]);
    }
    const uint32_t len = (uint32_t)(hdr - img) + 8u + 4u * n + 4u;
    put32(img + PIEZO_TABLE_HDR_PAYLOAD_LEN_OFFSET, len - PIEZO_TABLE_HDR_BYTES - 4u);
    fix_crc(img, len);
    ctl.staged_len = 0u;
    return len;
}

/* The polynomial's bound sum |p_m| < 64 (strict since round 18: eupi.h,
 * the Horner step's SMMULR needs |h| < 2^30). A table cannot state more
 * than 16 per coefficient (the section's range), so it takes four terms of
 * 16: refused at the kernel's init (out_of_range; the inverse's G2 bound,
 * 16 FS, refuses it too), the running table unchanged. The same four-term
 * section with the calibrated terms and a zero u^5 term is committed. */
static void test_poly_sum_bound_is_refused(void **state)
{
    (void)state;
    piezo_table_info_t info;
    setup_with_table();

    const int32_t at_bound[4] = {16 << 24, -(16 << 24), 16 << 24, -(16 << 24)};
    uint32_t len = eupi_with_poly(at_bound, 4u);
    assert_refused(upload(S1, img, len), PIEZO_TABLE_REASON_OUT_OF_RANGE);

    eupi_copy(&info);
    const piezo_section_t *po = piezo_table_section(&info, PIEZO_SECTION_EUPI_POLY_Q24);
    int32_t cal[PIEZO_CS_MAX_POLY] = {0};
    assert_true(po->count < 4u);
    for (uint32_t k = 0; k < po->count; k++) {
        cal[k] = (int32_t)piezo_le32(po->data + 4u * k);
    }
    len = eupi_with_poly(cal, 4u);
    assert_int_equal(upload(S1, img, len), PIEZO_TABLE_REASON_OK);
    assert_true(piezo_ctl_active_crc(&ctl) == piezo_le32(img + len - 4u));
}

/* The DCC table with its weights' sign inverted (each in range): the drive
 * falls while the reference rises. */
/* The CPI-inverse thresholds r'_i act on v = y_r - G2, up to 17 FS
 * (eupi_inv.h): their documented range is [0, 32] FS, not [0, 1). So a
 * threshold of 40000 (1.22 FS) is committed as the last threshold, refused
 * as the first (the order breaks), and the last above 32 FS is refused. */
static void test_cpi_inverse_threshold_above_full_scale(void **state)
{
    (void)state;
    piezo_table_info_t info;
    const piezo_section_t *r;
    setup_with_table();

    eupi_copy(&info);
    put32(elem0(&info, PIEZO_SECTION_EUPI_CPI_INV_R_Q15), 40000u);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_NOT_MONOTONIC);

    eupi_copy(&info);
    r = piezo_table_section(&info, PIEZO_SECTION_EUPI_CPI_INV_R_Q15);
    put32(img + (r->data - img) + 4u * (r->count - 1u), (1u << 20) + 1u);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OUT_OF_RANGE);

    eupi_copy(&info);
    r = piezo_table_section(&info, PIEZO_SECTION_EUPI_CPI_INV_R_Q15);
    put32(img + (r->data - img) + 4u * (r->count - 1u), 40000u);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_int_equal(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OK);
    assert_true(piezo_ctl_active_crc(&ctl) == piezo_le32(img + SIL_EUPI_IMG_LEN - 4u));
}

static void test_sweep_refuses_an_inverted_table(void **state)
{
    (void)state;
    piezo_table_info_t info;
    setup_with_table();
    memcpy(img, sil_dcc_img, SIL_DCC_IMG_LEN);
    assert_int_equal(piezo_table_check(img, SIL_DCC_IMG_LEN, &info), PIEZO_TABLE_REASON_OK);
    const piezo_section_t *c = piezo_table_section(&info, PIEZO_SECTION_DCC_C_Q24);
    for (uint32_t k = 0; k < c->count; k++) {
        uint8_t *p = img + (c->data - img) + 4u * k;
        put32(p, (uint32_t)-(int32_t)piezo_le32(p));
    }
    fix_crc(img, SIL_DCC_IMG_LEN);
    uint16_t r = upload(S1, img, SIL_DCC_IMG_LEN);
    printf("inverted DCC weights: %s\n", piezo_table_reason_str(r));
    assert_true(r == PIEZO_TABLE_REASON_NOT_MONOTONIC || r == PIEZO_TABLE_REASON_OUTPUT_RANGE);
    assert_true(piezo_ctl_active_crc(&ctl) == dcc_crc());
}

/* The sweep's cost: it runs at commit, outside the tick. */
static void test_sweep_time(void **state)
{
    (void)state;
    static piezo_coefset_t cs;
    static piezo_ff_state_t ff;
    const struct {
        const char *name;
        const uint8_t *img;
        uint32_t len;
    } t[] = {{"eupi_inverse", sil_eupi_img, SIL_EUPI_IMG_LEN}, {"kp_dcc", sil_dcc_img, SIL_DCC_IMG_LEN}};
    for (unsigned i = 0; i < 2; i++) {
        piezo_sweep_stats_t st;
        struct timespec a, b;
        const int reps = 20;
        assert_int_equal(piezo_coefset_load(&cs, &ff, t[i].img, t[i].len), PIEZO_TABLE_REASON_OK);
        clock_gettime(CLOCK_MONOTONIC, &a);
        for (int k = 0; k < reps; k++) {
            assert_int_equal(piezo_coefset_sweep(&cs, &ff, &st), PIEZO_TABLE_REASON_OK);
        }
        clock_gettime(CLOCK_MONOTONIC, &b);
        double us = ((double)(b.tv_sec - a.tv_sec) * 1e9 + (double)(b.tv_nsec - a.tv_nsec)) / 1e3 / reps;
        printf("sweep %s: %u kernel calls, %.0f us (%.2f us per call), worst step against the reference %d LSB\n",
               t[i].name, st.samples, us, us / st.samples, (int)st.worst_step_q15);
        assert_true(st.samples < 8000u); /* bounded */
    }
}

/* An image built for another stage or axis. */
static void test_stage_and_axis_must_match(void **state)
{
    (void)state;
    setup_with_table();
    /* the valve of the issue: drive -90..90 V, position -6..4 um */
    memcpy(img, sil_eupi_img, SIL_EUPI_IMG_LEN);
    put32(img + PIEZO_TABLE_HDR_DRIVE_MIN_MV_OFFSET, (uint32_t)-90000);
    put32(img + PIEZO_TABLE_HDR_DRIVE_MAX_MV_OFFSET, 90000u);
    put32(img + PIEZO_TABLE_HDR_POSITION_MIN_NM_OFFSET, (uint32_t)-6000);
    put32(img + PIEZO_TABLE_HDR_POSITION_MAX_NM_OFFSET, 4000u);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_WRONG_STAGE);
    /* a position range 2 nm off */
    memcpy(img, sil_eupi_img, SIL_EUPI_IMG_LEN);
    put32(img + PIEZO_TABLE_HDR_POSITION_MAX_NM_OFFSET, piezo_le32(img + PIEZO_TABLE_HDR_POSITION_MAX_NM_OFFSET) + 2u);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_WRONG_STAGE);
    /* no stage at all */
    memcpy(img, sil_eupi_img, SIL_EUPI_IMG_LEN);
    memset(img + PIEZO_TABLE_HDR_DRIVE_MIN_MV_OFFSET, 0, 16u);
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_WRONG_STAGE);
    /* the other axis */
    memcpy(img, sil_eupi_img, SIL_EUPI_IMG_LEN);
    img[PIEZO_TABLE_HDR_AXIS_OFFSET] = 1u;
    fix_crc(img, SIL_EUPI_IMG_LEN);
    assert_refused(upload(S1, img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_WRONG_AXIS);
    /* the right one */
    assert_int_equal(upload(S1, sil_eupi_img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OK);
}

/* Unlock and upload belong to a session. */
static void test_sessions_own_unlock_and_upload(void **state)
{
    (void)state;
    setup_with_table();
    /* session 2 never unlocked: it can neither write, clear nor commit */
    assert_int_equal(piezo_ctl_stage_write(&ctl, S1, 0u, sil_eupi_img, 100u), PIEZO_OK);
    assert_int_equal(piezo_ctl_stage_write(&ctl, S2, 0u, sil_eupi_img, 100u), PIEZO_EPERM);
    assert_int_equal(piezo_ctl_commit(&ctl, S2, 0u), PIEZO_TABLE_REASON_LOCKED);
    assert_int_equal(piezo_ctl_clear_staged(&ctl, S2), PIEZO_EPERM);
    /* a wrong key from session 2 does not disturb session 1's upload */
    assert_int_equal(piezo_ctl_unlock(&ctl, S2, 0x1234u, 0u), PIEZO_EKEY);
    assert_true(piezo_ctl_is_unlocked(&ctl, S1));
    assert_int_equal(ctl.staged_len, 100u);
    /* unlocked, session 2 still cannot take session 1's upload */
    assert_int_equal(piezo_ctl_unlock(&ctl, S2, TEST_UNLOCK_KEY, 0u), PIEZO_OK);
    assert_int_equal(piezo_ctl_stage_write(&ctl, S2, 100u, sil_eupi_img + 100, 8u), PIEZO_EPERM);
    assert_int_equal(piezo_ctl_commit(&ctl, S2, 0u), PIEZO_TABLE_REASON_NOT_OWNER);
    assert_int_equal(ctl.staged_len, 100u);
    assert_int_equal(piezo_ctl_stage_write(&ctl, S1, 100u, sil_eupi_img + 100, SIL_EUPI_IMG_LEN - 100u), PIEZO_OK);
    /* session 1 ends (its connection closed): its upload and unlock go */
    piezo_ctl_end_session(&ctl, S1);
    assert_false(piezo_ctl_is_unlocked(&ctl, S1));
    assert_int_equal(ctl.staged_len, 0u);
    assert_int_equal(piezo_ctl_commit(&ctl, S2, 0u), PIEZO_TABLE_REASON_NOTHING_STAGED);
    assert_true(piezo_ctl_active_crc(&ctl) == dcc_crc());
    /* session 2's own upload commits */
    assert_int_equal(upload(S2, sil_eupi_img, SIL_EUPI_IMG_LEN), PIEZO_TABLE_REASON_OK);
    piezo_ctl_lock(&ctl, S2);
    assert_false(piezo_ctl_is_unlocked(&ctl, S2));
}

/* Wrong keys: a backoff from the third, doubling, then the lockout. */
static void test_backoff_then_lockout(void **state)
{
    (void)state;
    uint32_t t = 1000u;
    setup_with_table();
    for (unsigned i = 0; i < PIEZO_UNLOCK_BACKOFF_AFTER; i++) {
        assert_int_equal(piezo_ctl_unlock(&ctl, S2, 0x1234u + i, t), PIEZO_EKEY);
    }
    /* even the right key waits out the backoff */
    assert_int_equal(piezo_ctl_unlock(&ctl, S2, TEST_UNLOCK_KEY, t + 1u), PIEZO_EBUSY);
    assert_int_equal(piezo_ctl_unlock_wait_ms(&ctl, t), PIEZO_UNLOCK_BACKOFF_BASE_MS);
    t += PIEZO_UNLOCK_BACKOFF_BASE_MS;
    assert_int_equal(piezo_ctl_unlock(&ctl, S2, TEST_UNLOCK_KEY, t), PIEZO_OK); /* and the run resets */
    assert_int_equal(piezo_ctl_unlock_wait_ms(&ctl, t), 0u);
    /* ten wrong keys in a row, each after its backoff: the lockout */
    for (unsigned i = 0; i < PIEZO_UNLOCK_LOCKOUT_AFTER; i++) {
        t += piezo_ctl_unlock_wait_ms(&ctl, t);
        assert_int_equal(piezo_ctl_unlock(&ctl, S2, 0x1234u, t), PIEZO_EKEY);
    }
    printf("after %u wrong keys: unlock refused for %u ms\n", PIEZO_UNLOCK_LOCKOUT_AFTER,
           (unsigned)piezo_ctl_unlock_wait_ms(&ctl, t));
    assert_int_equal(piezo_ctl_unlock_wait_ms(&ctl, t), PIEZO_UNLOCK_LOCKOUT_MS);
    assert_int_equal(piezo_ctl_unlock(&ctl, S1, TEST_UNLOCK_KEY, t + PIEZO_UNLOCK_LOCKOUT_MS - 1u), PIEZO_EBUSY);
    assert_int_equal(piezo_ctl_unlock(&ctl, S1, TEST_UNLOCK_KEY, t + PIEZO_UNLOCK_LOCKOUT_MS), PIEZO_OK);
    /* no key provisioned: every unlock refused */
    piezo_ctl_set_key(&ctl, 0u);
    assert_int_equal(piezo_ctl_unlock(&ctl, S1, 0u, t + PIEZO_UNLOCK_LOCKOUT_MS), PIEZO_EKEY);
    assert_true(piezo_ctl_active_crc(&ctl) == dcc_crc());
}

static void test_strerror_names_every_code(void **state)
{
    (void)state;
    for (int e = PIEZO_EIO; e <= PIEZO_OK; e++) {
        assert_true(strcmp(piezo_strerror(e), "unknown error") != 0);
    }
    assert_string_equal(piezo_table_reason_str(PIEZO_TABLE_REASON_WRONG_STAGE), "wrong_stage");
    assert_string_equal(piezo_table_reason_str(999u), "unknown reason");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_sixteen_absurd_images_are_refused),
        cmocka_unit_test(test_each_check_has_its_reason),
        cmocka_unit_test(test_poly_sum_bound_is_refused),
        cmocka_unit_test(test_cpi_inverse_threshold_above_full_scale),
        cmocka_unit_test(test_sweep_refuses_an_inverted_table),
        cmocka_unit_test(test_sweep_time),
        cmocka_unit_test(test_stage_and_axis_must_match),
        cmocka_unit_test(test_sessions_own_unlock_and_upload),
        cmocka_unit_test(test_backoff_then_lockout),
        cmocka_unit_test(test_strerror_names_every_code),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
