/* The register map through the real PDU server: identity, table upload in
 * one request per chunk, read-back, commit, locks, configuration, recorder. */
#include <string.h>

#include "piezo_test.h"
#include "ctl_test_cfg.h"
#include "ctl_vectors.h"
#include "modbus_pdu.h"
#include "regmap.h"
#include "mb_request.h"

static piezo_ctl_t ctl;
static piezo_regmap_t map;
static piezo_mb_regs_t regs;
static uint8_t rsp[PIEZO_MB_PDU_MAX];

static void setup(void)
{
    piezo_ctl_cfg_t c = unit_cfg();
    assert_int_equal(piezo_ctl_init(&ctl, &c), 0);
    piezo_regmap_init(&map, &ctl);
    map.drive_min_mv = 0;
    map.drive_max_mv = 150000;
    piezo_ctl_set_key(&ctl, TEST_UNLOCK_KEY); /* the stage stays unknown: ctl images carry none */
    regs = piezo_regmap_regs(&map);
}

/* Sends a PDU; returns the response length. */
static size_t pdu(const uint8_t *req, size_t n)
{
    return piezo_mb_pdu_process(&regs, req, n, rsp, sizeof rsp);
}

static uint8_t write_regs(uint16_t addr, uint16_t n, const uint16_t *v)
{
    uint8_t req[PIEZO_MB_PDU_MAX];
    size_t r = pdu(req, mb_req_write_multiple(req, addr, v, n));
    assert_true(r >= 2u);
    return (rsp[0] & PIEZO_MB_EXCEPTION_BIT) ? rsp[1] : 0u;
}

static uint8_t write1(uint16_t addr, uint16_t v)
{
    return write_regs(addr, 1, &v);
}

/* The key into unlock_key, both registers in one request. */
static uint8_t write_key(uint32_t key)
{
    uint16_t v[2] = {(uint16_t)(key >> 16), (uint16_t)key};
    return write_regs(PIEZO_HOLDING_UNLOCK_KEY, 2, v);
}

static uint8_t read_regs(uint8_t fc, uint16_t addr, uint16_t n, uint16_t *out)
{
    uint8_t req[5] = {fc, (uint8_t)(addr >> 8), (uint8_t)addr, (uint8_t)(n >> 8), (uint8_t)n};
    assert_true(pdu(req, 5) >= 2u);
    if (rsp[0] & PIEZO_MB_EXCEPTION_BIT) {
        return rsp[1];
    }
    for (uint16_t i = 0; i < n; i++) {
        out[i] = (uint16_t)((rsp[2 + 2 * i] << 8) | rsp[3 + 2 * i]);
    }
    return 0u;
}

static uint32_t read_u32(uint8_t fc, uint16_t addr)
{
    uint16_t w[2];
    assert_int_equal(read_regs(fc, addr, 2, w), 0);
    return ((uint32_t)w[0] << 16) | w[1];
}

/* FC 23: write `wn` registers at waddr, then read `rn` at raddr. */
static uint8_t read_write(uint16_t raddr, uint16_t rn, uint16_t waddr, uint16_t wn, const uint16_t *wv, uint16_t *out)
{
    uint8_t req[PIEZO_MB_PDU_MAX];
    req[0] = PIEZO_MB_FC_READ_WRITE_MULTIPLE;
    req[1] = (uint8_t)(raddr >> 8);
    req[2] = (uint8_t)raddr;
    req[3] = (uint8_t)(rn >> 8);
    req[4] = (uint8_t)rn;
    req[5] = (uint8_t)(waddr >> 8);
    req[6] = (uint8_t)waddr;
    req[7] = (uint8_t)(wn >> 8);
    req[8] = (uint8_t)wn;
    req[9] = (uint8_t)(2u * wn);
    for (uint16_t i = 0; i < wn; i++) {
        req[10 + 2 * i] = (uint8_t)(wv[i] >> 8);
        req[11 + 2 * i] = (uint8_t)wv[i];
    }
    assert_true(pdu(req, 10u + 2u * wn) >= 2u);
    if (rsp[0] & PIEZO_MB_EXCEPTION_BIT) {
        return rsp[1];
    }
    for (uint16_t i = 0; i < rn; i++) {
        out[i] = (uint16_t)((rsp[2 + 2 * i] << 8) | rsp[3 + 2 * i]);
    }
    return 0u;
}

/* Uploads an image in 121-register chunks, each offset + data in one FC 16. */
static void upload(const uint8_t *img, uint32_t len)
{
    for (uint32_t off = 0; off < len; off += 2u * PIEZO_HOLDING_TABLE_WINDOW_COUNT) {
        uint16_t v[2 + PIEZO_HOLDING_TABLE_WINDOW_COUNT];
        uint32_t nb = len - off < 2u * PIEZO_HOLDING_TABLE_WINDOW_COUNT ? len - off : 2u * PIEZO_HOLDING_TABLE_WINDOW_COUNT;
        uint16_t nr = (uint16_t)((nb + 1u) / 2u);
        v[0] = (uint16_t)(off >> 16);
        v[1] = (uint16_t)off;
        for (uint16_t i = 0; i < nr; i++) {
            uint16_t lo = img[off + 2u * i];
            uint16_t hi = (2u * i + 1u < nb) ? img[off + 2u * i + 1u] : 0u;
            v[2 + i] = (uint16_t)(lo | (hi << 8));
        }
        assert_int_equal(write_regs(PIEZO_HOLDING_TABLE_OFFSET, (uint16_t)(2u + nr), v), 0);
    }
}

static void test_identity(void **state)
{
    (void)state;
    setup();
    uint16_t id;
    assert_int_equal(read_regs(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_DEVICE_ID, 1, &id), 0);
    assert_int_equal(id, 0x505A);
    assert_true(read_u32(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_INTERFACE_CRC) == PIEZO_INTERFACE_CRC32);
    assert_int_equal(read_u32(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_DRIVE_MAX_MV), 150000);
    assert_int_equal(read_regs(PIEZO_MB_FC_READ_INPUT, 0x0050, 1, &id), PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS);
}

static void test_table_upload_readback_commit(void **state)
{
    (void)state;
    setup();
    /* locked: the window refuses, nothing is staged */
    {
        uint16_t v[3] = {0, 0, 0x1234};
        assert_int_equal(write_regs(PIEZO_HOLDING_TABLE_OFFSET, 3, v), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
        assert_int_equal(ctl.staged_len, 0);
    }
    /* wrong key: an exception, counted */
    assert_int_equal(write_key(0x1111u), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(read_u32(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_BAD_UNLOCKS) >> 16, 1);
    assert_int_equal(write_key(TEST_UNLOCK_KEY), 0);
    upload(ctl_dcc_img, CTL_DCC_IMG_LEN);
    /* read back every chunk with FC 23 (offset written, window read) */
    for (uint32_t off = 0; off < CTL_DCC_IMG_LEN; off += 2u * PIEZO_HOLDING_TABLE_WINDOW_COUNT) {
        uint16_t o[2] = {(uint16_t)(off >> 16), (uint16_t)off}, w[PIEZO_HOLDING_TABLE_WINDOW_COUNT];
        assert_int_equal(read_write(PIEZO_HOLDING_TABLE_WINDOW, PIEZO_HOLDING_TABLE_WINDOW_COUNT,
                                    PIEZO_HOLDING_TABLE_OFFSET, 2, o, w), 0);
        for (uint32_t i = 0; i < 2u * PIEZO_HOLDING_TABLE_WINDOW_COUNT && off + i < CTL_DCC_IMG_LEN; i++) {
            uint8_t b = (uint8_t)((i & 1u) ? w[i / 2u] >> 8 : w[i / 2u]);
            assert_int_equal(b, ctl_dcc_img[off + i]);
        }
    }
    assert_int_equal(write1(PIEZO_HOLDING_TABLE_COMMAND, 1), 0);
    int32_t in[2] = {0, 0}, dac;
    piezo_ctl_tick(&ctl, in, &dac);
    uint16_t result;
    assert_int_equal(read_regs(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_TABLE_RESULT, 1, &result), 0);
    assert_int_equal(result, PIEZO_TABLE_REASON_OK);
    uint32_t crc = read_u32(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_ACTIVE_TABLE_CRC);
    assert_true(crc == ((uint32_t)ctl_dcc_img[CTL_DCC_IMG_LEN - 4] | ((uint32_t)ctl_dcc_img[CTL_DCC_IMG_LEN - 3] << 8) |
                        ((uint32_t)ctl_dcc_img[CTL_DCC_IMG_LEN - 2] << 16) |
                        ((uint32_t)ctl_dcc_img[CTL_DCC_IMG_LEN - 1] << 24)));
    /* a damaged upload is refused with its reason; the active table stays */
    upload(ctl_bad[0].img, ctl_bad[0].len);
    assert_int_equal(write1(PIEZO_HOLDING_TABLE_COMMAND, 1), 0);
    assert_int_equal(read_regs(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_TABLE_RESULT, 1, &result), 0);
    assert_int_equal(result, ctl_bad[0].reason);
    assert_true(read_u32(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_ACTIVE_TABLE_CRC) == crc);
    /* a window past the bank's end is refused whole */
    uint16_t v[4] = {0, (uint16_t)(PIEZO_TABLE_MAX_BYTES - 4u), 1, 2};
    assert_int_equal(write_regs(PIEZO_HOLDING_TABLE_OFFSET, 4, v), 0);
    v[1] = (uint16_t)(PIEZO_TABLE_MAX_BYTES - 2u);
    assert_int_equal(write_regs(PIEZO_HOLDING_TABLE_OFFSET, 4, v), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(write1(PIEZO_HOLDING_TABLE_COMMAND, 9), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
}

static void test_configuration_needs_key_and_disarm(void **state)
{
    (void)state;
    setup();
    uint16_t kp[2] = {0x0080, 0x0000}; /* 0.5 in q24 */
    assert_int_equal(write_regs(PIEZO_HOLDING_PID_KP_Q24, 2, kp), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(write_key(TEST_UNLOCK_KEY), 0);
    assert_int_equal(write_regs(PIEZO_HOLDING_PID_KP_Q24, 2, kp), 0);
    assert_int_equal(ctl.cfg.pid.kp_q24, 1 << 23);
    /* min above max: refused, nothing changed */
    uint16_t mm[2] = {1000, (uint16_t)-1000};
    assert_int_equal(write_regs(PIEZO_HOLDING_PID_OUT_MIN_Q15, 2, mm), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(ctl.cfg.pid.out_min_q15, -32768);
    /* armed: refused */
    assert_int_equal(write1(PIEZO_HOLDING_MODE, PIEZO_MODE_OPEN_LOOP), 0);
    assert_int_equal(write1(PIEZO_HOLDING_ARM, 1), 0);
    assert_int_equal(write_regs(PIEZO_HOLDING_PID_KP_Q24, 2, kp), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(write1(PIEZO_HOLDING_MODE, PIEZO_MODE_FEEDBACK), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    /* a half-written 32-bit register keeps its other half */
    assert_int_equal(write1(PIEZO_HOLDING_ARM, 0), 0);
    assert_int_equal(write1(PIEZO_HOLDING_PID_KP_Q24 + 1u, 0x0001), 0);
    assert_int_equal(ctl.cfg.pid.kp_q24, (1 << 23) | 1);
    /* the dynamics-inverse FIR: count, spacing and taps in one write; a count above 32 or a spacing
     * above 8 refuses the whole write, nothing changed */
    uint16_t fir[4] = {2, 3, 12288, (uint16_t)-4096};
    assert_int_equal(write_regs(PIEZO_HOLDING_DYNINV_TAPS, 4, fir), 0);
    assert_int_equal(ctl.cfg.dyninv.n_taps, 2);
    assert_int_equal(ctl.cfg.dyninv.spacing, 3);
    assert_int_equal(ctl.cfg.dyninv.h_q13[1], -4096);
    uint16_t fir_bad[3] = {PIEZO_HOLDING_DYNINV_Q13_COUNT + 1u, 1, 8192};
    assert_int_equal(write_regs(PIEZO_HOLDING_DYNINV_TAPS, 3, fir_bad), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    fir_bad[0] = 1;
    fir_bad[1] = 9;
    assert_int_equal(write_regs(PIEZO_HOLDING_DYNINV_TAPS, 3, fir_bad), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(ctl.cfg.dyninv.n_taps, 2);
    assert_int_equal(ctl.cfg.dyninv.spacing, 3);
    assert_int_equal(ctl.cfg.dyninv.h_q13[0], 12288);
    /* read-only and unknown registers */
    assert_int_equal(write1(PIEZO_HOLDING_REC_WINDOW, 0), PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS);
    assert_int_equal(write1(0x0FFF, 0), PIEZO_MB_EX_ILLEGAL_DATA_ADDRESS);
}

static void test_wave_and_recorder_over_registers(void **state)
{
    (void)state;
    setup();
    assert_int_equal(write1(PIEZO_HOLDING_MODE, PIEZO_MODE_OPEN_LOOP), 0);
    assert_int_equal(write1(PIEZO_HOLDING_ARM, 1), 0);
    uint16_t wave[11] = {PIEZO_WAVE_TRIANGLE, 0, 16000, 0x0400, 0x0000, 0, 0, 0, 0, 0, 2}; /* 64 ticks */
    assert_int_equal(write_regs(PIEZO_HOLDING_WAVE_KIND, 11, wave), 0);
    uint16_t rec[2] = {2, PIEZO_SIG_REF};
    assert_int_equal(write_regs(PIEZO_HOLDING_REC_N_CHANNELS, 2, rec), 0);
    assert_int_equal(write1(PIEZO_HOLDING_REC_SIGNALS + 1u, PIEZO_SIG_U), 0);
    assert_int_equal(write1(PIEZO_HOLDING_REC_TRIGGER, PIEZO_REC_SOFTWARE), 0);
    assert_int_equal(write1(PIEZO_HOLDING_COMMAND, 4), 0); /* arm recorder */
    assert_int_equal(write1(PIEZO_HOLDING_COMMAND, 2), 0); /* start wave: triggers */
    uint16_t running;
    assert_int_equal(read_regs(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_WAVE_RUNNING, 1, &running), 0);
    assert_int_equal(running, 1);
    for (int k = 0; k < 200; k++) {
        int32_t in[2] = {0, 0}, dac;
        piezo_ctl_tick(&ctl, in, &dac);
    }
    assert_int_equal(read_u32(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_REC_FRAMES), 200);
    /* frame 16 is the triangle's top: reference and drive, samples 32 and 33 */
    uint16_t idx[2] = {0, 32}, w[2];
    assert_int_equal(read_write(PIEZO_HOLDING_REC_WINDOW, 2, PIEZO_HOLDING_REC_READ_INDEX, 2, idx, w), 0);
    int16_t top = (int16_t)((16000 * 32767 + 16384) >> 15);
    assert_int_equal((int16_t)w[0], top);
    assert_int_equal((int16_t)w[1], top);
    assert_int_equal(write1(PIEZO_HOLDING_WAVE_KIND, 99), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
}

/* The other axis' drive over its register: the tick records the value written
 * before it (signal u2), a later write the next tick, and the register reads
 * it back. Round 16 keeps u2 only in sig[PIEZO_SIG_U2] (no copy per tick):
 * this fails if the register's write path or the recording misses it. */
static void test_u2_register_is_the_recorded_u2(void **state)
{
    static const int16_t u2[5] = {-12000, 0, 7, 32767, -32768};
    (void)state;
    setup();
    uint16_t rec[2] = {1, PIEZO_SIG_U2};
    assert_int_equal(write_regs(PIEZO_HOLDING_REC_N_CHANNELS, 2, rec), 0);
    assert_int_equal(write1(PIEZO_HOLDING_REC_TRIGGER, PIEZO_REC_IMMEDIATE), 0);
    assert_int_equal(write1(PIEZO_HOLDING_COMMAND, 4), 0); /* arm recorder: immediate */
    for (int k = 0; k < 5; k++) {
        int32_t in[2] = {0, 0}, dac;
        uint16_t back;
        assert_int_equal(write1(PIEZO_HOLDING_U2_Q15, (uint16_t)u2[k]), 0);
        assert_int_equal(read_regs(PIEZO_MB_FC_READ_HOLDING, PIEZO_HOLDING_U2_Q15, 1, &back), 0);
        assert_int_equal((int16_t)back, u2[k]);
        piezo_ctl_tick(&ctl, in, &dac);
    }
    assert_int_equal(read_u32(PIEZO_MB_FC_READ_INPUT, PIEZO_INPUT_REC_FRAMES), 5);
    for (uint16_t k = 0; k < 5; k++) {
        uint16_t idx[2] = {0, k}, w;
        assert_int_equal(read_write(PIEZO_HOLDING_REC_WINDOW, 1, PIEZO_HOLDING_REC_READ_INDEX, 2, idx, &w), 0);
        assert_int_equal((int16_t)w, u2[k]);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_identity),
        cmocka_unit_test(test_table_upload_readback_commit),
        cmocka_unit_test(test_configuration_needs_key_and_disarm),
        cmocka_unit_test(test_wave_and_recorder_over_registers),
        cmocka_unit_test(test_u2_register_is_the_recorded_u2),
    };
    return cmocka_run_group_tests_name("regmap", tests, NULL, NULL);
}
