/* Modbus RTU framer: CRC-16 vectors, timing (t1.5, t3.5, fixed timers above
 * 19200 baud), addressing, broadcast, CRC errors and malformed frames. */
#include <string.h>

#include "piezo_test.h"
#include "modbus_rtu.h"
#include "test_modbus_regs.h"

#define UNIT 1u
#define BAUD 9600u
/* 9600 baud: character 1146 us, t1.5 1719 us, t3.5 4011 us (rounded up). */
#define TCHAR 1146u
#define T15 1719u
#define T35 4011u

static tregs_t bank;
static piezo_mb_regs_t regs;
static piezo_rtu_t rtu;
static uint8_t reply[PIEZO_RTU_ADU_MAX];

static int setup(void **state)
{
    (void)state;
    regs = tregs_init(&bank);
    assert_int_equal(piezo_rtu_init(&rtu, UNIT, BAUD), 0);
    return 0;
}

/* Appends the CRC (low byte first) to f[0..n) and returns n + 2. */
static size_t add_crc(uint8_t *f, size_t n)
{
    uint16_t crc = piezo_rtu_crc16(f, n);
    f[n] = (uint8_t)crc;
    f[n + 1] = (uint8_t)(crc >> 8);
    return n + 2;
}

static size_t read_frame(uint8_t *f, uint8_t unit, uint8_t fc, uint16_t addr, uint16_t count)
{
    f[0] = unit;
    f[1] = fc;
    f[2] = (uint8_t)(addr >> 8);
    f[3] = (uint8_t)addr;
    f[4] = (uint8_t)(count >> 8);
    f[5] = (uint8_t)count;
    return add_crc(f, 6);
}

/* Feeds a frame byte by byte at the line rate starting at t0; returns the
 * time of its last byte. */
static uint32_t send_at(const uint8_t *f, size_t n, uint32_t t0)
{
    uint32_t t = t0;
    for (size_t i = 0; i < n; i++) {
        t = t0 + (uint32_t)i * TCHAR;
        piezo_rtu_rx_byte(&rtu, f[i], t);
    }
    return t;
}

static size_t poll_at(uint32_t t)
{
    return piezo_rtu_poll(&rtu, t, &regs, reply, sizeof reply);
}

static void test_crc16_known_vectors(void **state)
{
    (void)state;
    assert_int_equal(piezo_rtu_crc16((const uint8_t *)"123456789", 9), 0x4B37);
    assert_int_equal(piezo_rtu_crc16(NULL, 0), 0xFFFF);
    /* Read holding registers examples: the CRC bytes as transmitted. */
    const uint8_t a[] = {0x11, 0x03, 0x00, 0x6B, 0x00, 0x03};
    assert_int_equal(piezo_rtu_crc16(a, sizeof a), 0x8776);  /* sent 76 87 */
    const uint8_t b[] = {0x01, 0x03, 0x00, 0x00, 0x00, 0x0A};
    assert_int_equal(piezo_rtu_crc16(b, sizeof b), 0xCDC5);  /* sent C5 CD */
    const uint8_t c[] = {0x01, 0x04, 0x00, 0x00, 0x00, 0x01};
    assert_int_equal(piezo_rtu_crc16(c, sizeof c), 0xCA31);  /* sent 31 CA */
    /* A frame with its own CRC appended has CRC 0. */
    uint8_t f[8];
    memcpy(f, a, sizeof a);
    add_crc(f, sizeof a);
    assert_int_equal(f[6], 0x76);
    assert_int_equal(f[7], 0x87);
    assert_int_equal(piezo_rtu_crc16(f, 8), 0);
    /* update() byte by byte equals the block function */
    uint16_t crc = 0xFFFF;
    for (size_t i = 0; i < sizeof b; i++) {
        crc = piezo_rtu_crc16_update(crc, b[i]);
    }
    assert_int_equal(crc, 0xCDC5);
}

static void test_init_timing_and_arguments(void **state)
{
    (void)state;
    piezo_rtu_t r;
    assert_int_equal(piezo_rtu_init(&r, 1, 9600), 0);
    assert_int_equal(piezo_rtu_t35_us(&r), 4011);
    assert_int_equal(r.gap15_us, 1146 + 1719);
    assert_int_equal(piezo_rtu_init(&r, 1, 19200), 0);
    assert_int_equal(piezo_rtu_t35_us(&r), 2006);  /* 38.5 bits at 19200 */
    assert_int_equal(piezo_rtu_init(&r, 247, 19201), 0);
    assert_int_equal(piezo_rtu_t35_us(&r), 1750);  /* fixed above 19200 */
    assert_int_equal(piezo_rtu_init(&r, 1, 115200), 0);
    assert_int_equal(piezo_rtu_t35_us(&r), 1750);
    assert_int_equal(r.gap15_us, 96 + 750);
    assert_int_equal(piezo_rtu_init(&r, 0, 9600), -1);
    assert_int_equal(piezo_rtu_init(&r, 248, 9600), -1);
    assert_int_equal(piezo_rtu_init(&r, 1, 0), -1);
    assert_int_equal(piezo_rtu_init(NULL, 1, 9600), -1);
    /* an uninitialised (failed) framer ignores bytes and never answers */
    uint8_t f[8];
    size_t n = read_frame(f, 1, 0x04, 0, 1);
    piezo_rtu_rx(&r, f, n, 0);
    assert_int_equal(piezo_rtu_poll(&r, 100000, &regs, reply, sizeof reply), 0);
}

static void test_request_answered_after_t35_silence(void **state)
{
    (void)state;
    uint8_t f[8];
    size_t n = read_frame(f, UNIT, 0x04, 0x0000, 2);
    uint32_t t = send_at(f, n, 1000);
    assert_int_equal(poll_at(t), 0);
    assert_int_equal(poll_at(t + T35 - 1), 0);
    size_t r = poll_at(t + T35);
    const uint8_t want[] = {UNIT, 0x04, 0x04, 0x50, 0x5A, 0x40, 0x03};
    assert_int_equal(r, sizeof want + 2);
    assert_memory_equal(reply, want, sizeof want);
    assert_int_equal(piezo_rtu_crc16(reply, r), 0);
    assert_int_equal(poll_at(t + 2 * T35), 0);  /* answered once */
    assert_int_equal(rtu.stats.answered, 1);
    assert_int_equal(rtu.stats.frames, 1);
}

static void test_exception_reply_is_a_frame(void **state)
{
    (void)state;
    uint8_t f[8];
    size_t n = read_frame(f, UNIT, 0x03, 0x0000, 1);  /* unmapped holding */
    uint32_t t = send_at(f, n, 0);
    size_t r = poll_at(t + T35);
    assert_int_equal(r, 5);
    assert_int_equal(reply[0], UNIT);
    assert_int_equal(reply[1], 0x83);
    assert_int_equal(reply[2], 0x02);
    assert_int_equal(piezo_rtu_crc16(reply, r), 0);
}

static void test_wrong_address_is_silence(void **state)
{
    (void)state;
    uint8_t f[8];
    for (unsigned unit = 2; unit <= 255; unit++) {
        size_t n = read_frame(f, (uint8_t)unit, 0x04, 0, 1);
        uint32_t t0 = unit * 100000u;
        uint32_t t = send_at(f, n, t0);
        assert_int_equal(poll_at(t + T35), 0);
    }
    assert_int_equal(rtu.stats.not_for_us, 254);
    assert_int_equal(bank.calls_read_input, 0);
}

static void test_every_corrupted_bit_is_silence(void **state)
{
    (void)state;
    uint8_t good[8];
    size_t n = read_frame(good, UNIT, 0x06, 0x1003, 0x0101);
    uint32_t t0 = 0;
    for (size_t bit = 0; bit < 8 * n; bit++) {
        uint8_t f[8];
        memcpy(f, good, n);
        f[bit / 8] ^= (uint8_t)(1u << (bit % 8));
        uint32_t t = send_at(f, n, t0);
        assert_int_equal(poll_at(t + T35), 0);
        t0 = t + 2 * T35;
    }
    /* bits in the address byte make "another unit" with a bad CRC: all CRC errors */
    assert_int_equal(rtu.stats.crc_errors, 8 * n);
    assert_int_equal(bank.calls_write_holding, 0);
    assert_int_equal(*tregs_holding(&bank, 0x1003), 0);
    uint32_t t = send_at(good, n, t0);
    assert_int_equal(poll_at(t + T35), 8);
    assert_int_equal(*tregs_holding(&bank, 0x1003), 0x0101);
}

static void test_frame_split_by_silence_is_two_frames(void **state)
{
    (void)state;
    uint8_t f[8];
    size_t n = read_frame(f, UNIT, 0x04, 0, 1);
    /* 3 bytes, then t3.5 of silence (+ a character), then the other 5 */
    uint32_t t = send_at(f, 3, 0);
    t = send_at(&f[3], n - 3, t + TCHAR + T35);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(rtu.stats.frames, 2);
    assert_int_equal(rtu.stats.malformed, 1);   /* 3 bytes: too short */
    assert_int_equal(rtu.stats.crc_errors, 1);  /* 5 bytes: CRC of the tail is wrong */
    /* the same split by a poll that sees the silence */
    t = send_at(f, 3, t + 2 * T35);
    assert_int_equal(poll_at(t + T35), 0);
    t = send_at(&f[3], n - 3, t + T35 + 10);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(rtu.stats.frames, 4);
    assert_int_equal(bank.calls_read_input, 0);
}

static void test_two_frames_back_to_back_are_both_answered(void **state)
{
    (void)state;
    uint8_t a[8];
    uint8_t b[8];
    size_t na = read_frame(a, UNIT, 0x04, 0x0001, 1);
    size_t nb = read_frame(b, UNIT, 0x04, 0x0002, 1);
    uint32_t t = send_at(a, na, 0);
    t = send_at(b, nb, t + TCHAR + T35);  /* exactly t3.5 of silence between */
    size_t r = poll_at(t + T35);
    assert_int_equal(r, 7);
    assert_int_equal((reply[3] << 8) | reply[4], tregs_input_value(1));
    r = poll_at(t + T35 + 1);
    assert_int_equal(r, 7);
    assert_int_equal((reply[3] << 8) | reply[4], tregs_input_value(2));
    assert_int_equal(poll_at(t + T35 + 2), 0);
}

static void test_silence_just_under_t35_joins_frames(void **state)
{
    (void)state;
    uint8_t a[8];
    size_t na = read_frame(a, UNIT, 0x04, 0x0001, 1);
    /* gap of t3.5 - 1 us between the two halves: above t1.5, so one broken frame */
    uint32_t t = send_at(a, 4, 0);
    t = send_at(&a[4], na - 4, t + TCHAR + T35 - 1);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(rtu.stats.frames, 1);
    assert_int_equal(rtu.stats.malformed, 1);
}

static void test_inner_gap_above_t15_drops_frame(void **state)
{
    (void)state;
    uint8_t a[8];
    size_t na = read_frame(a, UNIT, 0x04, 0x0001, 1);
    /* a silence of t1.5 + 1 us inside: dropped */
    uint32_t t = send_at(a, 4, 0);
    t = send_at(&a[4], na - 4, t + TCHAR + T15 + 1);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(rtu.stats.malformed, 1);
    /* a silence of exactly t1.5 is allowed */
    t = send_at(a, 4, t + 10 * T35);
    t = send_at(&a[4], na - 4, t + TCHAR + T15);
    assert_int_equal(poll_at(t + T35), 7);
}

static void test_fixed_timers_above_19200(void **state)
{
    (void)state;
    assert_int_equal(piezo_rtu_init(&rtu, UNIT, 115200), 0);
    uint8_t a[8];
    size_t na = read_frame(a, UNIT, 0x04, 0x0001, 1);
    /* 96 us per character; 750 us inner gap allowed, 751 not */
    piezo_rtu_rx(&rtu, a, 4, 0);
    piezo_rtu_rx(&rtu, &a[4], na - 4, 96 + 750);
    assert_int_equal(piezo_rtu_poll(&rtu, 846 + 1749, &regs, reply, sizeof reply), 0);
    assert_int_equal(piezo_rtu_poll(&rtu, 846 + 1750, &regs, reply, sizeof reply), 7);
    piezo_rtu_rx(&rtu, a, 4, 10000);
    piezo_rtu_rx(&rtu, &a[4], na - 4, 10000 + 96 + 751);
    assert_int_equal(piezo_rtu_poll(&rtu, 20000, &regs, reply, sizeof reply), 0);
    assert_int_equal(rtu.stats.malformed, 1);
}

static void test_broadcast_writes_execute_without_reply(void **state)
{
    (void)state;
    uint8_t f[16];
    /* FC 6 broadcast */
    f[0] = 0; f[1] = 0x06; f[2] = 0x10; f[3] = 0x03; f[4] = 0x12; f[5] = 0x34;
    size_t n = add_crc(f, 6);
    uint32_t t = send_at(f, n, 0);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(*tregs_holding(&bank, 0x1003), 0x1234);
    /* FC 16 broadcast */
    const uint8_t w[] = {0, 0x10, 0x20, 0x00, 0x00, 0x02, 0x04, 0xAB, 0xCD, 0xEF, 0x01};
    memcpy(f, w, sizeof w);
    n = add_crc(f, sizeof w);
    t = send_at(f, n, t + 10 * T35);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(*tregs_holding(&bank, 0x2000), 0xABCD);
    assert_int_equal(*tregs_holding(&bank, 0x2001), 0xEF01);
    assert_int_equal(rtu.stats.broadcasts, 2);
    /* a broadcast read, and a broadcast read/write: ignored, nothing called */
    unsigned rd = bank.calls_read_input + bank.calls_read_holding;
    unsigned wr = bank.calls_write_holding;
    n = read_frame(f, 0, 0x04, 0, 1);
    t = send_at(f, n, t + 10 * T35);
    assert_int_equal(poll_at(t + T35), 0);
    const uint8_t rw[] = {0, 0x17, 0x20, 0x00, 0x00, 0x01, 0x20, 0x00, 0x00, 0x01, 0x02, 0x55, 0x55};
    memcpy(f, rw, sizeof rw);
    n = add_crc(f, sizeof rw);
    t = send_at(f, n, t + 10 * T35);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(bank.calls_read_input + bank.calls_read_holding, rd);
    assert_int_equal(bank.calls_write_holding, wr);
    assert_int_equal(*tregs_holding(&bank, 0x2000), 0xABCD);
    assert_int_equal(rtu.stats.broadcasts, 2);
    /* a refused broadcast write changes nothing and is still not answered */
    f[0] = 0; f[1] = 0x06; f[2] = 0x10; f[3] = 0x01; f[4] = 0x00; f[5] = 0x09;
    n = add_crc(f, 6);
    t = send_at(f, n, t + 10 * T35);
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(*tregs_holding(&bank, TREGS_MODE), 0);
}

/* Frames of every length 1..300 with a valid CRC over whatever they hold:
 * below 4 bytes or above 256 -> silence; 4..256 -> an answer (the PDU server
 * decides normal or exception), never silence, always a valid reply frame. */
static void test_frames_of_every_length(void **state)
{
    (void)state;
    uint8_t f[300];
    uint32_t t = 0;
    for (size_t len = 1; len <= sizeof f; len++) {
        f[0] = UNIT;
        for (size_t i = 1; i < len; i++) {
            f[i] = (uint8_t)(0x10 + 31 * i);  /* FC 0x2F first: unknown */
        }
        if (len >= 3) {
            add_crc(f, len - 2);
        }
        unsigned malformed = rtu.stats.malformed;
        t = send_at(f, len, t + 10 * T35);
        size_t r = poll_at(t + T35);
        if (len < 4 || len > 256) {
            assert_int_equal(r, 0);
            assert_int_equal(rtu.stats.malformed, malformed + 1);
        } else {
            assert_int_equal(r, 5);
            assert_int_equal(reply[1], 0x2F | 0x80);
            assert_int_equal(reply[2], 0x01);
            assert_int_equal(piezo_rtu_crc16(reply, r), 0);
        }
    }
    /* A valid FC 16 request truncated at every length: always silence. */
    uint8_t w[256];
    w[0] = UNIT; w[1] = 0x10; w[2] = 0x20; w[3] = 0x00; w[4] = 0x00; w[5] = 0x7B; w[6] = 246;
    for (int i = 0; i < 246; i++) {
        w[7 + i] = (uint8_t)i;
    }
    size_t n = add_crc(w, 253);
    assert_int_equal(n, 255);
    for (size_t len = 1; len < n; len++) {
        t = send_at(w, len, t + 10 * T35);
        assert_int_equal(poll_at(t + T35), 0);
    }
    assert_int_equal(bank.calls_write_holding, 0);
    t = send_at(w, n, t + 10 * T35);
    assert_int_equal(poll_at(t + T35), 8);
    assert_int_equal(*tregs_holding(&bank, 0x207A), 0xF4F5);
}

static void test_pdu_of_every_length_inside_valid_frames(void **state)
{
    (void)state;
    /* FC 3 frames of length 4..256: only the 8-byte one is a normal
     * response; the others are ILLEGAL DATA VALUE replies. */
    uint8_t f[256];
    uint32_t t = 0;
    for (size_t len = 4; len <= 256; len++) {
        memset(f, 0, sizeof f);
        f[0] = UNIT; f[1] = 0x03; f[2] = 0x20; f[3] = 0x00; f[4] = 0x00; f[5] = 0x01;
        add_crc(f, len - 2);
        t = send_at(f, len, t + 10 * T35);
        size_t r = poll_at(t + T35);
        if (len == 8) {
            assert_int_equal(r, 7);
            assert_int_equal(reply[1], 0x03);
        } else {
            assert_int_equal(r, 5);
            assert_int_equal(reply[1], 0x83);
            assert_int_equal(reply[2], 0x03);
        }
    }
    assert_int_equal(bank.calls_read_holding, 1);
}

static void test_overflow_then_recovery_and_timestamp_wrap(void **state)
{
    (void)state;
    uint8_t junk[400];
    memset(junk, UNIT, sizeof junk);
    uint32_t t = 0xFFFF0000u;
    for (size_t i = 0; i < sizeof junk; i++) {
        piezo_rtu_rx_byte(&rtu, junk[i], t + (uint32_t)i * 10u);
    }
    t += 4000;
    assert_int_equal(poll_at(t + T35), 0);
    assert_int_equal(rtu.stats.malformed, 1);
    /* a request that straddles the 32-bit wrap of the timestamp */
    uint8_t f[8];
    size_t n = read_frame(f, UNIT, 0x04, 0, 1);
    t = 0xFFFFFFFFu - 3u * TCHAR;
    uint32_t last = send_at(f, n, t);
    assert_true(last < t);  /* wrapped */
    assert_int_equal(poll_at(last + T35 - 1), 0);
    assert_int_equal(poll_at(last + T35), 7);
}

static void test_small_reply_buffer_answers_nothing(void **state)
{
    (void)state;
    uint8_t f[8];
    uint8_t small[PIEZO_RTU_ADU_MAX - 1];
    size_t n = read_frame(f, UNIT, 0x04, 0, 1);
    uint32_t t = send_at(f, n, 0);
    assert_int_equal(piezo_rtu_poll(&rtu, t + T35, &regs, small, sizeof small), 0);
    assert_int_equal(piezo_rtu_poll(&rtu, t + T35, &regs, NULL, 256), 0);
}

static void test_overrun_keeps_the_first_frame(void **state)
{
    (void)state;
    uint8_t a[8];
    uint8_t b[8];
    uint8_t c[8];
    size_t n = read_frame(a, UNIT, 0x04, 0x0001, 1);
    read_frame(b, UNIT, 0x04, 0x0002, 1);
    read_frame(c, UNIT, 0x04, 0x0003, 1);
    uint32_t t = send_at(a, n, 0);
    t = send_at(b, n, t + TCHAR + T35);   /* ends a: a is ready */
    t = send_at(c, n, t + TCHAR + T35);   /* ends b while a waits: b dropped */
    assert_int_equal(rtu.stats.overruns, 1);
    assert_int_equal(poll_at(t + T35), 7);
    assert_int_equal((reply[3] << 8) | reply[4], tregs_input_value(1));
    assert_int_equal(poll_at(t + T35), 7);
    assert_int_equal((reply[3] << 8) | reply[4], tregs_input_value(3));
}

/* The line is one session: it begins with every request to us and ends
 * after PIEZO_MB_RTU_SESSION_IDLE_US without one. */
static unsigned n_begin, n_end;
static void session_cb(void *ctx, uint8_t id, uint8_t event)
{
    (void)ctx;
    assert_int_equal(id, PIEZO_MB_SESSION_RTU);
    if (event == PIEZO_MB_SESSION_BEGIN) {
        n_begin++;
    } else {
        n_end++;
    }
}

static void test_line_session_ends_after_silence(void **state)
{
    (void)state;
    uint8_t f[8];
    size_t n = read_frame(f, UNIT, 4, 0, 1);
    uint32_t t;
    n_begin = n_end = 0u;
    regs.session = session_cb;
    t = send_at(f, n, 1000u);
    assert_true(piezo_rtu_poll(&rtu, t + T35, &regs, reply, sizeof reply) > 0u);
    t = send_at(f, n, t + T35 + 1000000u); /* 1 s later: the same session */
    assert_true(piezo_rtu_poll(&rtu, t + T35, &regs, reply, sizeof reply) > 0u);
    assert_int_equal(n_begin, 2);
    assert_int_equal(n_end, 0);
    t = send_at(f, n, t + T35 + PIEZO_MB_RTU_SESSION_IDLE_US); /* silent too long: a new one */
    assert_true(piezo_rtu_poll(&rtu, t + T35, &regs, reply, sizeof reply) > 0u);
    assert_int_equal(n_begin, 3);
    assert_int_equal(n_end, 1);
    regs.session = NULL;
}

/* Polled while the line is silent, the session ends at the idle time itself
 * (once), and the next request begins a new one. */
static void test_line_session_ends_while_polled_in_silence(void **state)
{
    (void)state;
    uint8_t f[8];
    size_t n = read_frame(f, UNIT, 4, 0, 1);
    uint32_t t;
    n_begin = n_end = 0u;
    regs.session = session_cb;
    t = send_at(f, n, 1000u);
    assert_true(piezo_rtu_poll(&rtu, t + T35, &regs, reply, sizeof reply) > 0u);
    assert_int_equal(piezo_rtu_poll(&rtu, t + T35 + PIEZO_MB_RTU_SESSION_IDLE_US - 1u, &regs, reply,
                                    sizeof reply), 0u);
    assert_int_equal(n_end, 0);
    assert_int_equal(piezo_rtu_poll(&rtu, t + T35 + PIEZO_MB_RTU_SESSION_IDLE_US, &regs, reply,
                                    sizeof reply), 0u);
    assert_int_equal(n_end, 1);
    assert_int_equal(piezo_rtu_poll(&rtu, t + T35 + 2u * PIEZO_MB_RTU_SESSION_IDLE_US, &regs, reply,
                                    sizeof reply), 0u);
    assert_int_equal(n_end, 1); /* once */
    t = send_at(f, n, t + T35 + 2u * PIEZO_MB_RTU_SESSION_IDLE_US + 1000u);
    assert_true(piezo_rtu_poll(&rtu, t + T35, &regs, reply, sizeof reply) > 0u);
    assert_int_equal(n_begin, 2);
    assert_int_equal(n_end, 1);
    regs.session = NULL;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_crc16_known_vectors, setup),
        cmocka_unit_test_setup(test_init_timing_and_arguments, setup),
        cmocka_unit_test_setup(test_request_answered_after_t35_silence, setup),
        cmocka_unit_test_setup(test_exception_reply_is_a_frame, setup),
        cmocka_unit_test_setup(test_wrong_address_is_silence, setup),
        cmocka_unit_test_setup(test_every_corrupted_bit_is_silence, setup),
        cmocka_unit_test_setup(test_frame_split_by_silence_is_two_frames, setup),
        cmocka_unit_test_setup(test_two_frames_back_to_back_are_both_answered, setup),
        cmocka_unit_test_setup(test_silence_just_under_t35_joins_frames, setup),
        cmocka_unit_test_setup(test_inner_gap_above_t15_drops_frame, setup),
        cmocka_unit_test_setup(test_fixed_timers_above_19200, setup),
        cmocka_unit_test_setup(test_broadcast_writes_execute_without_reply, setup),
        cmocka_unit_test_setup(test_frames_of_every_length, setup),
        cmocka_unit_test_setup(test_pdu_of_every_length_inside_valid_frames, setup),
        cmocka_unit_test_setup(test_overflow_then_recovery_and_timestamp_wrap, setup),
        cmocka_unit_test_setup(test_small_reply_buffer_answers_nothing, setup),
        cmocka_unit_test_setup(test_overrun_keeps_the_first_frame, setup),
        cmocka_unit_test_setup(test_line_session_ends_after_silence, setup),
        cmocka_unit_test_setup(test_line_session_ends_while_polled_in_silence, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
