/* Controller parameters in flash (firmware/tables/param_store.c through the
 * register map, firmware/control/regmap.c): boot with nothing stored, save
 * and reboot, A/B alternation, a power cut at every storage operation of a
 * save, corrupt and foreign records ignored with their reason, refusals;
 * the wave and its learned feedforward saved with them (or left out where
 * the slot has no room), and an absurd wave under a valid CRC refused whole;
 * and the servo switch (controller.c) without a drive jump. */
#include <string.h>

#include "piezo_test.h"
#include "ctl_test_cfg.h"
#include "crc32.h"
#include "modbus_pdu.h"
#include "nor_flash.h"
#include "param_store.h"
#include "regmap.h"
#include "mb_request.h"

static piezo_ctl_t ctl;
static piezo_regmap_t map;
static piezo_mb_regs_t regs;
static uint8_t rsp[PIEZO_MB_PDU_MAX];
static uint8_t mem[2u * PIEZO_PARAMS_SLOT_BYTES];
static nor_flash_t nor;
static piezo_storage_t io;
static uint32_t slot_bytes = PIEZO_PARAMS_SLOT_BYTES; /* the target's slot (a small one: the minimum) */

/* A controller booting on the flash as it is (a power cycle). */
static uint16_t boot(void)
{
    piezo_ctl_cfg_t c = unit_cfg();
    assert_int_equal(piezo_ctl_init(&ctl, &c), 0);
    piezo_regmap_init(&map, &ctl);
    piezo_ctl_set_key(&ctl, TEST_UNLOCK_KEY);
    regs = piezo_regmap_regs(&map);
    nor.ops_left = -1;
    nor.dead = 0;
    io = nor_flash_storage(&nor, slot_bytes);
    return piezo_regmap_attach_params(&map, &io);
}

static void erase_all(void)
{
    slot_bytes = PIEZO_PARAMS_SLOT_BYTES;
    nor_flash_init(&nor, mem, sizeof mem);
}

static uint8_t write_regs(uint16_t addr, uint16_t n, const uint16_t *v)
{
    uint8_t req[PIEZO_MB_PDU_MAX];
    size_t len = mb_req_write_multiple(req, addr, v, n);
    assert_true(piezo_mb_pdu_process(&regs, req, len, rsp, sizeof rsp) >= 2u);
    return (rsp[0] & PIEZO_MB_EXCEPTION_BIT) ? rsp[1] : 0u;
}

static uint8_t write1(uint16_t addr, uint16_t v)
{
    return write_regs(addr, 1, &v);
}

static uint32_t read_input(uint16_t addr, uint16_t n)
{
    uint8_t req[5] = {PIEZO_MB_FC_READ_INPUT, (uint8_t)(addr >> 8), (uint8_t)addr, 0, (uint8_t)n};
    assert_true(piezo_mb_pdu_process(&regs, req, 5, rsp, sizeof rsp) >= 2u);
    assert_false(rsp[0] & PIEZO_MB_EXCEPTION_BIT);
    return n == 1 ? (uint32_t)(rsp[2] << 8 | rsp[3])
                  : ((uint32_t)rsp[2] << 24) | ((uint32_t)rsp[3] << 16) | ((uint32_t)rsp[4] << 8) | rsp[5];
}

static void unlock(void)
{
    uint16_t v[2] = {(uint16_t)(TEST_UNLOCK_KEY >> 16), (uint16_t)TEST_UNLOCK_KEY};
    assert_int_equal(write_regs(PIEZO_HOLDING_UNLOCK_KEY, 2, v), 0);
}

/* Gains and a slew limit that differ from unit_cfg()'s. */
static void set_params(int32_t kp_q24, int16_t step_q15)
{
    uint16_t v[2] = {(uint16_t)((uint32_t)kp_q24 >> 16), (uint16_t)kp_q24};
    unlock();
    assert_int_equal(write_regs(PIEZO_HOLDING_PID_KP_Q24, 2, v), 0);
    assert_int_equal(write1(PIEZO_HOLDING_LIMIT_MAX_STEP_Q15, (uint16_t)step_q15), 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SOURCE, 1), PIEZO_PARAMS_SRC_CHANGED);
}

static uint16_t save(void)
{
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_SAVE), 0);
    return (uint16_t)read_input(PIEZO_INPUT_PARAMS_RESULT, 1);
}

static void test_nothing_stored_runs_the_defaults(void **state)
{
    (void)state;
    erase_all();
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_NONE_STORED);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SOURCE, 1), PIEZO_PARAMS_SRC_DEFAULTS);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SEQ, 2), 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_IGNORED, 1), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(ctl.cfg.pid.kp_q24, 0);
}

static void test_save_survives_reboot_and_alternates_slots(void **state)
{
    (void)state;
    erase_all();
    boot();
    set_params(3 << 22, 100);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SEQ, 2), 1);
    assert_int_equal(map.pstore.active, 0);
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
    assert_int_equal(ctl.cfg.limit.max_step_q15, 100);
    assert_int_equal(ctl.limit.coef->max_step_q15, 100); /* bound, not only stored */
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SOURCE, 1), PIEZO_PARAMS_SRC_FLASH);
    set_params(5 << 22, 200);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(map.pstore.active, 1); /* the inactive slot, then the flip */
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SEQ, 2), 2);
    boot();
    assert_int_equal(ctl.cfg.pid.kp_q24, 5 << 22);
    assert_int_equal(ctl.cfg.limit.max_step_q15, 200);
}

static void test_load_and_defaults_commands(void **state)
{
    (void)state;
    erase_all();
    boot();
    set_params(3 << 22, 100);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
    set_params(7 << 22, 300);
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_LOAD), 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_RESULT, 1), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_DEFAULTS), 0);
    assert_int_equal(ctl.cfg.pid.kp_q24, 0);
    assert_int_equal(ctl.cfg.limit.max_step_q15, 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SOURCE, 1), PIEZO_PARAMS_SRC_DEFAULTS);
    boot(); /* the defaults command left the flash as it was */
    assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
}

/* One tick; the tick's cached view of the configuration and the learned
 * feedforward's slot (ref_stages) is then what they say, and is want. */
static void tick_and_check_ref_stages(uint8_t want)
{
    int32_t in[2] = {0, 0}, dac = 0;
    piezo_ctl_tick(&ctl, in, &dac);
    assert_int_equal(ctl.ref_stages, piezo_ctl_ref_stages_of(&ctl));
    assert_int_equal(ctl.ref_stages, want);
}

/* Every path that changes what ref_stages (and jump_span) caches updates it by the next
 * tick: register writes of the preview, the shaper, the dynamics inverse (and the jump limit),
 * the parameters' defaults and load commands, the boot's load, the learned
 * feedforward's commit and switch-off (the tick's swap). Each path is taken
 * once to switch the stages on or off, so one that forgets fails here. */
static void test_every_path_updates_the_ref_stages(void **state)
{
    (void)state;
    static const int16_t ff[4] = {100, -100, 50, -50};
    uint16_t fir[4] = {2, 3, 12288, (uint16_t)-4096};
    erase_all();
    boot();
    tick_and_check_ref_stages(0u);
    unlock();
    assert_int_equal(write1(PIEZO_HOLDING_PREVIEW_TICKS, 3), 0);
    tick_and_check_ref_stages(1u);
    assert_int_equal(write1(PIEZO_HOLDING_PREVIEW_TICKS, 0), 0);
    tick_and_check_ref_stages(0u);
    assert_int_equal(write1(PIEZO_HOLDING_SHAPER_TICKS, 2), 0);
    tick_and_check_ref_stages(1u);
    assert_int_equal(write1(PIEZO_HOLDING_SHAPER_TICKS, 0), 0);
    tick_and_check_ref_stages(0u);
    assert_int_equal(write_regs(PIEZO_HOLDING_DYNINV_TAPS, 4, fir), 0);
    tick_and_check_ref_stages(1u);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK); /* the dynamics inverse on, in flash */
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_DEFAULTS), 0);
    tick_and_check_ref_stages(0u);
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_LOAD), 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_RESULT, 1), PIEZO_PARAMS_REASON_OK);
    tick_and_check_ref_stages(1u);
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_DEFAULTS), 0);
    tick_and_check_ref_stages(0u);
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK); /* init with unit_cfg, then the stored parameters */
    tick_and_check_ref_stages(1u);
    unlock();
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_DEFAULTS), 0);
    tick_and_check_ref_stages(0u);
    /* the sensor's jump test (jump_span): on by a register write after good
     * samples, a jump of 1000 is then held; off by the defaults, it passes */
    {
        int32_t in[2] = {0, 0}, dac = 0;
        assert_int_equal(write1(PIEZO_HOLDING_MAX_JUMP_Q15, 100), 0);
        piezo_ctl_tick(&ctl, in, &dac);
        in[0] = 1000;
        piezo_ctl_tick(&ctl, in, &dac);
        assert_int_equal(ctl.sig[PIEZO_SIG_Y], 0);
        assert_int_equal(ctl.bad_run, 1);
        assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_DEFAULTS), 0);
        piezo_ctl_tick(&ctl, in, &dac);
        assert_int_equal(ctl.sig[PIEZO_SIG_Y], 1000);
        assert_int_equal(ctl.bad_run, 0);
    }
    /* the learned feedforward's slot */
    assert_int_equal(piezo_ctl_wave_ff_commit(&ctl, ff, 4u, 1u << 24), PIEZO_OK);
    tick_and_check_ref_stages(1u);
    assert_int_equal(piezo_ctl_wave_ff_off(&ctl), PIEZO_OK);
    tick_and_check_ref_stages(0u);
}

/* A power cut after every possible number of storage operations of a save:
 * the next boot runs the old parameters or the new ones, never a mixture,
 * and the old record survives every cut. */
static void test_power_cut_at_every_step_of_a_save(void **state)
{
    (void)state;
    for (long cut = 0; cut < 8; cut++) {
        erase_all();
        boot();
        set_params(3 << 22, 100);
        assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
        set_params(5 << 22, 200);
        nor.ops_left = cut;
        uint16_t r = save();
        assert_true(r == PIEZO_PARAMS_REASON_OK || r == PIEZO_PARAMS_REASON_STORAGE_FAILED);
        assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK);
        int old = ctl.cfg.pid.kp_q24 == (3 << 22) && ctl.cfg.limit.max_step_q15 == 100;
        int new = ctl.cfg.pid.kp_q24 == (5 << 22) && ctl.cfg.limit.max_step_q15 == 200;
        assert_true(old || new);
        assert_true(new == (r == PIEZO_PARAMS_REASON_OK));
    }
}

/* Flip one payload bit of the active record: boot ignores it (bad_crc) and
 * runs the other slot's record; both corrupt: the defaults. */
static void test_corrupt_record_is_ignored_with_its_reason(void **state)
{
    (void)state;
    erase_all();
    boot();
    set_params(3 << 22, 100);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK); /* slot A, seq 1 */
    set_params(5 << 22, 200);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK); /* slot B, seq 2 */
    mem[PIEZO_PARAMS_SLOT_BYTES + PIEZO_PSTORE_HEADER_BYTES + 12] ^= 0x10u;
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_IGNORED, 1), PIEZO_PARAMS_REASON_BAD_CRC);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_SEQ, 2), 1);
    mem[PIEZO_PSTORE_HEADER_BYTES + 9] ^= 0x01u;
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_NONE_STORED);
    assert_int_equal(ctl.cfg.pid.kp_q24, 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_IGNORED, 1), PIEZO_PARAMS_REASON_BAD_CRC);
    /* a save still works: it writes over a corrupt slot */
    set_params(3 << 22, 100);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
    /* garbage where a header should be */
    memset(mem + PIEZO_PARAMS_SLOT_BYTES, 0x00, 4);
    boot();
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_IGNORED, 1), PIEZO_PARAMS_REASON_BAD_MAGIC);
}

/* Rewrite slot A's record with a new payload and a correct CRC. */
static void forge(uint32_t iface_crc, uint16_t word_index, uint16_t word)
{
    uint8_t *s = mem, *pl = mem + PIEZO_PSTORE_HEADER_BYTES;
    uint32_t len = s[8] | (uint32_t)s[9] << 8, crc;
    pl[0] = (uint8_t)iface_crc;
    pl[1] = (uint8_t)(iface_crc >> 8);
    pl[2] = (uint8_t)(iface_crc >> 16);
    pl[3] = (uint8_t)(iface_crc >> 24);
    pl[8 + 2 * word_index] = (uint8_t)word;
    pl[9 + 2 * word_index] = (uint8_t)(word >> 8);
    crc = piezo_crc32(piezo_crc32(0u, s + 4, 8u), pl, len);
    s[12] = (uint8_t)crc;
    s[13] = (uint8_t)(crc >> 8);
    s[14] = (uint8_t)(crc >> 16);
    s[15] = (uint8_t)(crc >> 24);
}

static void test_foreign_or_out_of_range_record_runs_the_defaults(void **state)
{
    (void)state;
    erase_all();
    boot();
    set_params(3 << 22, 100);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
    forge(PIEZO_INTERFACE_CRC32 ^ 1u, 0, 0);
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_BAD_LAYOUT);
    assert_int_equal(ctl.cfg.pid.kp_q24, 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_IGNORED, 1), PIEZO_PARAMS_REASON_BAD_LAYOUT);
    /* bad_limit 0 (a register write refuses it) under a valid CRC */
    forge(PIEZO_INTERFACE_CRC32, (uint16_t)(PIEZO_HOLDING_BAD_LIMIT - PIEZO_PARAMS_FIRST), 0);
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_OUT_OF_RANGE);
    assert_int_equal(ctl.cfg.pid.kp_q24, 0);
    assert_int_equal(ctl.cfg.bad_limit, 3);
}

static void test_params_commands_refused_locked_or_armed(void **state)
{
    (void)state;
    erase_all();
    boot();
    set_params(3 << 22, 100);
    assert_int_equal(write1(PIEZO_HOLDING_UNLOCK, 0), 0);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_LOCKED);
    assert_int_equal(map.pstore.active, -1);
    unlock();
    assert_int_equal(write1(PIEZO_HOLDING_ARM, 1), 0);
    assert_int_equal(save(), PIEZO_PARAMS_REASON_ARMED);
    assert_int_equal(map.pstore.active, -1);
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, 4), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, 0), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
}

/* A steps wave of 3 levels, a tone, and a learned feedforward of 5 entries
 * committed (the tick has not taken it yet: it is what the tick plays next). */
static const int16_t wave_levels[3] = {-1000, 2500, 700};
static const uint32_t wave_durations[3] = {10, 70000, 3};
static const int16_t ff_entries[5] = {11, -22, 33, -44, 32767};

static void set_wave(void)
{
    uint16_t v[6];
    unlock();
    assert_int_equal(write1(PIEZO_HOLDING_WAVE_KIND, PIEZO_WAVE_KIND_STEPS), 0);
    assert_int_equal(write1(PIEZO_HOLDING_WAVE_N_LEVELS, 3), 0);
    assert_int_equal(write_regs(PIEZO_HOLDING_WAVE_LEVELS, 3, (const uint16_t *)wave_levels), 0);
    for (int i = 0; i < 3; i++) {
        v[2 * i] = (uint16_t)(wave_durations[i] >> 16);
        v[2 * i + 1] = (uint16_t)wave_durations[i];
    }
    assert_int_equal(write_regs(PIEZO_HOLDING_WAVE_DURATIONS, 6, v), 0);
    v[0] = 1234;   /* tone 2: amplitude, freq word 0x00012345, phase 0x40000000 */
    v[1] = 0x0001;
    v[2] = 0x2345;
    v[3] = 0x4000;
    v[4] = 0;
    assert_int_equal(write_regs(PIEZO_HOLDING_WAVE_TONES + 5, 5, v), 0);
    assert_int_equal(write_regs(PIEZO_HOLDING_WAVE_FF_LEVELS, 5, (const uint16_t *)ff_entries), 0);
    v[0] = 5;
    v[1] = 0x0006;
    v[2] = 0x8DB9; /* 10 Hz at 10 kHz: 2^32 / 1000 */
    v[3] = PIEZO_WAVE_FF_CMD_COMMIT;
    assert_int_equal(write_regs(PIEZO_HOLDING_WAVE_FF_N, 4, v), 0);
    assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 5);
}

static void assert_wave_restored(void)
{
    const piezo_ctl_wave_ff_t *ff;
    assert_int_equal(ctl.wave_cfg.kind, PIEZO_WAVE_KIND_STEPS);
    assert_int_equal(ctl.wave_cfg.n_levels, 3);
    assert_memory_equal(ctl.levels_q15, wave_levels, sizeof wave_levels);
    assert_memory_equal(ctl.durations, wave_durations, sizeof wave_durations);
    assert_int_equal(ctl.tones[1].amplitude_q15, 1234);
    assert_int_equal(ctl.tones[1].freq_word, 0x00012345u);
    assert_int_equal(ctl.tones[1].phase_word, 0x40000000u);
    assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 5); /* committed at boot: the tick plays it with the wave */
    assert_true(ctl.wave_ff_pending >= 0);
    ff = &ctl.wave_ff[ctl.wave_ff_pending];
    assert_memory_equal(ff->c_q15, ff_entries, sizeof ff_entries);
    assert_int_equal(ff->freq_word, 0x00068DB9u);
    assert_int_equal(piezo_wave_running(&ctl.wave), 0); /* loaded, not started */
}

static void test_wave_and_learned_feedforward_saved_with_the_parameters(void **state)
{
    (void)state;
    erase_all();
    boot();
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_WAVE, 1), PIEZO_PARAMS_WAVE_NONE);
    set_params(3 << 22, 100);
    set_wave();
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_WAVE, 1), PIEZO_PARAMS_WAVE_SAVED);
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
    assert_wave_restored();
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_WAVE, 1), PIEZO_PARAMS_WAVE_SAVED);
    /* the load command restores them too, over a changed wave */
    unlock();
    assert_int_equal(write1(PIEZO_HOLDING_WAVE_N_LEVELS, 1), 0);
    ctl.wave_ff_active = ctl.wave_ff_pending; /* the tick took the swap */
    ctl.wave_ff_pending = -1;
    assert_int_equal(write1(PIEZO_HOLDING_WAVE_FF_COMMAND, PIEZO_WAVE_FF_CMD_OFF), 0);
    ctl.wave_ff_active = -1;
    ctl.wave_ff_pending = -1;
    assert_int_equal(write1(PIEZO_HOLDING_PARAMS_COMMAND, PIEZO_PARAMS_CMD_LOAD), 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_RESULT, 1), PIEZO_PARAMS_REASON_OK);
    assert_wave_restored();
}

/* A target whose slot holds the parameters only: they are saved, the wave
 * is left out and said so; a boot restores the parameters alone. */
static void test_wave_left_out_where_the_slot_has_no_room(void **state)
{
    (void)state;
    erase_all();
    slot_bytes = PIEZO_PARAMS_MIN_SLOT_BYTES;
    boot();
    set_params(3 << 22, 100);
    set_wave();
    assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_WAVE, 1), PIEZO_PARAMS_WAVE_LEFT_OUT);
    assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK);
    assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
    assert_int_equal(ctl.wave_cfg.n_levels, 0);
    assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 0);
    assert_int_equal(read_input(PIEZO_INPUT_PARAMS_WAVE, 1), PIEZO_PARAMS_WAVE_NONE);
}

/* Rewrite word j of slot A's wave section with a correct CRC. */
static void forge_wave(uint16_t j, uint16_t word)
{
    uint8_t *s = mem, *pl = mem + PIEZO_PSTORE_HEADER_BYTES;
    uint32_t len = s[8] | (uint32_t)s[9] << 8, crc, at = 2u * (4u + PIEZO_PARAMS_WORDS + j);
    pl[at] = (uint8_t)word;
    pl[at + 1u] = (uint8_t)(word >> 8);
    crc = piezo_crc32(piezo_crc32(0u, s + 4, 8u), pl, len);
    for (int i = 0; i < 4; i++) {
        s[12 + i] = (uint8_t)(crc >> (8 * i));
    }
}

/* A CRC-valid record with an absurd wave changes nothing: not the
 * parameters, not the wave, not the learned feedforward. */
static void test_out_of_range_wave_refuses_the_whole_record(void **state)
{
    static const uint16_t bad[][2] = {
        {0, 99},                             /* wave_kind */
        {PIEZO_HOLDING_WAVE_N_LEVELS - PIEZO_HOLDING_WAVE_KIND, 4}, /* 4 levels: the record holds 3 */
        {PIEZO_HOLDING_WAVE_N_LEVELS - PIEZO_HOLDING_WAVE_KIND, PIEZO_CTL_WAVE_MAX_LEVELS + 1u},
        {15 + 40 + 9, PIEZO_CTL_WAVE_FF_MAX + 1u}, /* the feedforward's entries */
        {15 + 40 + 9 + 1, 0},                /* its freq word 0 (high, then low) */
    };
    (void)state;
    for (unsigned k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        erase_all();
        boot();
        set_params(3 << 22, 100);
        set_wave();
        assert_int_equal(save(), PIEZO_PARAMS_REASON_OK);
        forge_wave(bad[k][0], bad[k][1]);
        if (k == 4) {
            forge_wave(bad[k][0] + 1u, 0);
        }
        uint16_t r = boot();
        assert_true(r == PIEZO_PARAMS_REASON_OUT_OF_RANGE || r == PIEZO_PARAMS_REASON_BAD_LENGTH);
        assert_int_equal(ctl.cfg.pid.kp_q24, 0);
        assert_int_equal(ctl.wave_cfg.kind, 0);
        assert_int_equal(ctl.wave_cfg.n_levels, 0);
        assert_int_equal(ctl.tones[1].amplitude_q15, 0);
        assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 0);
        assert_int_equal(read_input(PIEZO_INPUT_PARAMS_IGNORED, 1), r);
    }
}

/* A power cut at every storage operation of a save with the wave: the old
 * record or the new one, whole. */
static void test_power_cut_during_a_save_with_the_wave(void **state)
{
    (void)state;
    for (long cut = 0;; cut++) {
        erase_all();
        boot();
        set_params(3 << 22, 100);
        assert_int_equal(save(), PIEZO_PARAMS_REASON_OK); /* parameters, no wave */
        set_params(5 << 22, 200);
        set_wave();
        nor.ops_left = cut;
        uint16_t r = save();
        assert_int_equal(boot(), PIEZO_PARAMS_REASON_OK);
        if (r == PIEZO_PARAMS_REASON_OK) {
            assert_int_equal(ctl.cfg.pid.kp_q24, 5 << 22);
            assert_wave_restored();
            assert_true(cut > 3); /* an erase, payload chunks, the header */
            break;
        }
        assert_int_equal(r, PIEZO_PARAMS_REASON_STORAGE_FAILED);
        assert_int_equal(ctl.cfg.pid.kp_q24, 3 << 22);
        assert_int_equal(ctl.wave_cfg.n_levels, 0);
        assert_int_equal(piezo_ctl_wave_ff_n(&ctl), 0);
        assert_true(cut < 100);
    }
}

/* Servo off holds the applied drive open loop; servo on closes the loop at
 * the present position with the integrator preloaded: no tick's drive jumps. */
static void test_servo_off_and_on_without_a_jump(void **state)
{
    (void)state;
    int32_t adc[2] = {0, 0}, dac = 0, prev;
    erase_all();
    boot();
    unlock();
    {
        uint16_t ki[2] = {0, 1u << 12}; /* Ki Ts = 2^-12 */
        uint16_t kp[2] = {(uint16_t)(1u << 7), 0}; /* 0.5 */
        assert_int_equal(write_regs(PIEZO_HOLDING_PID_KI_Q24, 2, ki), 0);
        assert_int_equal(write_regs(PIEZO_HOLDING_PID_KP_Q24, 2, kp), 0);
    }
    assert_int_equal(write1(PIEZO_HOLDING_COMMAND, PIEZO_CMD_SERVO_OFF), PIEZO_MB_EX_ILLEGAL_DATA_VALUE);
    assert_int_equal(write1(PIEZO_HOLDING_MODE, PIEZO_MODE_DIRECT), 0);
    assert_int_equal(write1(PIEZO_HOLDING_SETPOINT_Q15, 12000), 0);
    assert_int_equal(write1(PIEZO_HOLDING_ARM, 1), 0);
    for (int k = 0; k < 5; k++) {
        adc[0] = 9000; /* a stage that sits at 9000 whatever the drive */
        piezo_ctl_tick(&ctl, adc, &dac);
    }
    assert_int_equal(dac, 12000);
    /* servo on: FEEDBACK at y = 9000, the drive stays 12000 */
    assert_int_equal(write1(PIEZO_HOLDING_COMMAND, PIEZO_CMD_SERVO_ON), 0);
    for (int k = 0; k < 20; k++) {
        piezo_ctl_tick(&ctl, adc, &dac);
        assert_int_equal(dac, 12000);
    }
    assert_int_equal(ctl.mode, PIEZO_MODE_FEEDBACK);
    assert_int_equal(ctl.setpoint_q15, 9000);
    /* the loop is closed: the position moves, the drive follows the error */
    adc[0] = 8000;
    piezo_ctl_tick(&ctl, adc, &dac);
    assert_true(dac > 12000);
    prev = dac;
    /* servo off: the drive applied now is held, in DIRECT */
    assert_int_equal(write1(PIEZO_HOLDING_COMMAND, PIEZO_CMD_SERVO_OFF), 0);
    for (int k = 0; k < 20; k++) {
        adc[0] = 5000 + 100 * k; /* the position no longer matters */
        piezo_ctl_tick(&ctl, adc, &dac);
        assert_int_equal(dac, prev);
    }
    assert_int_equal(ctl.mode, PIEZO_MODE_DIRECT);
    /* servo on from disarmed arms, at the position, from the safe drive */
    assert_int_equal(write1(PIEZO_HOLDING_ARM, 0), 0);
    for (int k = 0; k < 3; k++) {
        piezo_ctl_tick(&ctl, adc, &dac);
    }
    assert_int_equal(dac, -32768);
    assert_int_equal(write1(PIEZO_HOLDING_COMMAND, PIEZO_CMD_SERVO_ON), 0);
    adc[0] = 7000;
    piezo_ctl_tick(&ctl, adc, &dac);
    assert_int_equal(ctl.st.armed, 1);
    assert_int_equal(ctl.mode, PIEZO_MODE_FEEDBACK);
    piezo_ctl_tick(&ctl, adc, &dac);
    assert_int_equal(dac, -32768);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_nothing_stored_runs_the_defaults),
        cmocka_unit_test(test_save_survives_reboot_and_alternates_slots),
        cmocka_unit_test(test_load_and_defaults_commands),
        cmocka_unit_test(test_every_path_updates_the_ref_stages),
        cmocka_unit_test(test_power_cut_at_every_step_of_a_save),
        cmocka_unit_test(test_corrupt_record_is_ignored_with_its_reason),
        cmocka_unit_test(test_foreign_or_out_of_range_record_runs_the_defaults),
        cmocka_unit_test(test_params_commands_refused_locked_or_armed),
        cmocka_unit_test(test_wave_and_learned_feedforward_saved_with_the_parameters),
        cmocka_unit_test(test_wave_left_out_where_the_slot_has_no_room),
        cmocka_unit_test(test_out_of_range_wave_refuses_the_whole_record),
        cmocka_unit_test(test_power_cut_during_a_save_with_the_wave),
        cmocka_unit_test(test_servo_off_and_on_without_a_jump),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
