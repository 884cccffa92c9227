/* Data recorder: triggers, pretrigger, decimation, time-ordered readout. */
#include "piezo_test.h"
#include "piezo_err.h"
#include "recorder.h"

#define NSIG 3

static void feed(piezo_rec_t *r, int16_t counter, int16_t other)
{
    int16_t sig[NSIG] = {counter, other, (int16_t)-counter};
    piezo_rec_process(r, sig);
}

static void test_immediate_capture_in_order(void **state)
{
    (void)state;
    int16_t buf[20];
    piezo_rec_t r;
    piezo_rec_cfg_t c = {.n_channels = 2, .signal = {0, 2}, .decimation = 1, .trigger = PIEZO_REC_IMMEDIATE};
    assert_int_equal(piezo_rec_init(&r, buf, 20, NSIG), PIEZO_OK);
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
    piezo_rec_arm(&r);
    for (int16_t k = 0; k < 15; k++) {
        feed(&r, k, 0);
    }
    assert_int_equal(r.state, PIEZO_REC_DONE);
    assert_int_equal(piezo_rec_frames(&r), 10);
    for (uint32_t k = 0; k < 10; k++) {
        int16_t f[2];
        assert_int_equal(piezo_rec_read(&r, k, f), PIEZO_OK);
        assert_int_equal(f[0], (int)k);
        assert_int_equal(f[1], -(int)k);
    }
    int16_t f[2];
    assert_int_equal(piezo_rec_read(&r, 10, f), PIEZO_ERANGE);
}

static void test_rising_trigger_keeps_pretrigger_frames(void **state)
{
    (void)state;
    int16_t buf[16];
    piezo_rec_t r;
    piezo_rec_cfg_t c = {.n_channels = 1, .signal = {0}, .decimation = 1, .pretrigger = 4,
                         .trigger = PIEZO_REC_RISING, .trigger_signal = 1, .trigger_level_q15 = 100};
    assert_int_equal(piezo_rec_init(&r, buf, 16, NSIG), PIEZO_OK);
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
    piezo_rec_arm(&r);
    for (int16_t k = 0; k < 100; k++) {
        feed(&r, k, k >= 50 ? 200 : 0); /* crosses 100 upward at k = 50 */
    }
    assert_int_equal(r.state, PIEZO_REC_DONE);
    assert_int_equal(piezo_rec_frames(&r), 16);
    for (uint32_t k = 0; k < 16; k++) {
        int16_t f;
        assert_int_equal(piezo_rec_read(&r, k, &f), PIEZO_OK);
        assert_int_equal(f, 46 + (int)k); /* 4 frames before the trigger sample */
    }
}

static void test_decimation_and_software_trigger(void **state)
{
    (void)state;
    int16_t buf[8];
    piezo_rec_t r;
    piezo_rec_cfg_t c = {.n_channels = 1, .signal = {0}, .decimation = 3, .trigger = PIEZO_REC_SOFTWARE};
    assert_int_equal(piezo_rec_init(&r, buf, 8, NSIG), PIEZO_OK);
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
    piezo_rec_arm(&r);
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_EORDER); /* not while armed */
    for (int16_t k = 0; k < 10; k++) {
        feed(&r, k, 0);
    }
    piezo_rec_trigger(&r);
    for (int16_t k = 10; k < 100; k++) {
        feed(&r, k, 0);
    }
    assert_int_equal(piezo_rec_frames(&r), 8);
    int16_t f;
    assert_int_equal(piezo_rec_read(&r, 0, &f), PIEZO_OK);
    assert_int_equal(f, 12);
    assert_int_equal(piezo_rec_read(&r, 7, &f), PIEZO_OK);
    assert_int_equal(f, 33);
}

static void test_bad_configuration_is_refused(void **state)
{
    (void)state;
    int16_t buf[8];
    piezo_rec_t r;
    assert_int_equal(piezo_rec_init(&r, buf, 8, NSIG), PIEZO_OK);
    piezo_rec_cfg_t c = {.n_channels = 2, .signal = {0, NSIG}, .decimation = 1};
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_EINVAL);
    c.signal[1] = 1;
    c.pretrigger = 4; /* 8 samples / 2 channels = 4 frames: no room after */
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_ERANGE);
    c.pretrigger = 0;
    c.decimation = 0;
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_EINVAL);
}

/* Ring mode: after the trigger the recorder never stops; frame n sits in slot
 * n mod capacity and `written` counts the frames, so a reader streams it. */
static void test_ring_keeps_recording_over_the_oldest_frames(void **state)
{
    (void)state;
    int16_t buf[8];
    piezo_rec_t r;
    piezo_rec_cfg_t c = {.n_channels = 2, .signal = {0, 2}, .decimation = 2,
                         .trigger = PIEZO_REC_SOFTWARE, .ring = 1};
    assert_int_equal(piezo_rec_init(&r, buf, 8, NSIG), PIEZO_OK);
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
    assert_int_equal(r.capacity, 4);
    piezo_rec_arm(&r);
    for (int16_t k = 0; k < 5; k++) {
        feed(&r, k, 0); /* before the trigger: not counted, not kept */
    }
    assert_int_equal(piezo_rec_written(&r), 0);
    piezo_rec_trigger(&r);
    int16_t f[2];
    assert_int_equal(piezo_rec_read_slot(&r, 0, f), PIEZO_ERANGE); /* nothing yet */
    /* 30 ticks at decimation 2: frames 0..14 hold ticks 100, 102, ..., 128 */
    for (int16_t k = 0; k < 30; k++) {
        feed(&r, (int16_t)(100 + k), 0);
        /* a frame is counted once whole: slot (written - 1) mod 4 holds the newest */
        uint32_t w = piezo_rec_written(&r);
        if (w > 0u) {
            assert_int_equal(piezo_rec_read_slot(&r, (w - 1u) % 4u, f), PIEZO_OK);
            assert_int_equal(f[0], 100 + 2 * (int)(w - 1u));
        }
    }
    assert_int_equal(r.state, PIEZO_REC_TRIGGERED); /* still recording */
    assert_int_equal(piezo_rec_written(&r), 15);
    assert_int_equal(piezo_rec_frames(&r), 4);
    /* frames 11..14 are still held, each in slot n mod 4 */
    for (uint32_t n = 11; n < 15; n++) {
        assert_int_equal(piezo_rec_read_slot(&r, n % 4u, f), PIEZO_OK);
        assert_int_equal(f[0], 100 + 2 * (int)n);
        assert_int_equal(f[1], -(100 + 2 * (int)n));
    }
    assert_int_equal(piezo_rec_read_slot(&r, 4, f), PIEZO_ERANGE); /* past the buffer */
    /* the time-ordered readout still works on the ring: oldest first */
    assert_int_equal(piezo_rec_read(&r, 0, f), PIEZO_OK);
    assert_int_equal(f[0], 100 + 2 * 11);
    /* reset ends the ring */
    piezo_rec_reset(&r);
    assert_int_equal(piezo_rec_written(&r), 0);
    feed(&r, 1, 0);
    assert_int_equal(piezo_rec_written(&r), 0);
}

static void test_ring_refuses_pretrigger(void **state)
{
    (void)state;
    int16_t buf[8];
    piezo_rec_t r;
    piezo_rec_cfg_t c = {.n_channels = 1, .signal = {0}, .decimation = 1, .pretrigger = 2, .ring = 1};
    assert_int_equal(piezo_rec_init(&r, buf, 8, NSIG), PIEZO_OK);
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_EINVAL);
    c.pretrigger = 0;
    c.ring = 2;
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_EINVAL);
    c.ring = 1;
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
}

/* Without ring mode `written` counts the frames after the trigger and stops. */
static void test_written_counts_a_plain_capture(void **state)
{
    (void)state;
    int16_t buf[4];
    piezo_rec_t r;
    piezo_rec_cfg_t c = {.n_channels = 1, .signal = {0}, .decimation = 1, .trigger = PIEZO_REC_IMMEDIATE};
    assert_int_equal(piezo_rec_init(&r, buf, 4, NSIG), PIEZO_OK);
    assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
    piezo_rec_arm(&r);
    for (int16_t k = 0; k < 10; k++) {
        feed(&r, k, 0);
    }
    assert_int_equal(r.state, PIEZO_REC_DONE);
    assert_int_equal(piezo_rec_written(&r), 4);
}

/* Every channel count, 1 to PIEZO_REC_MAX_CHANNELS: each channel holds its
 * own signal, frame after frame, and nothing beyond the frame is written. */
static void test_every_channel_count_stores_its_signals(void **state)
{
    (void)state;
    enum { NS = 10, FRAMES = 3 };
    for (uint8_t n = 1; n <= PIEZO_REC_MAX_CHANNELS; n++) {
        int16_t buf[FRAMES * PIEZO_REC_MAX_CHANNELS + 1];
        piezo_rec_t r;
        piezo_rec_cfg_t c = {.n_channels = n, .decimation = 1, .trigger = PIEZO_REC_IMMEDIATE};
        for (uint8_t i = 0; i < n; i++) {
            c.signal[i] = (uint8_t)((3u * i + 1u) % NS); /* a permutation of distinct signals */
        }
        for (size_t i = 0; i < sizeof buf / sizeof buf[0]; i++) {
            buf[i] = -1;
        }
        assert_int_equal(piezo_rec_init(&r, buf, (uint32_t)(FRAMES * n), NS), PIEZO_OK);
        assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
        piezo_rec_arm(&r);
        for (int16_t k = 0; k < FRAMES; k++) {
            int16_t sig[NS];
            for (int16_t s = 0; s < NS; s++) {
                sig[s] = (int16_t)(100 * k + s);
            }
            piezo_rec_process(&r, sig);
        }
        assert_int_equal(r.state, PIEZO_REC_DONE);
        for (uint32_t k = 0; k < FRAMES; k++) {
            int16_t f[PIEZO_REC_MAX_CHANNELS];
            assert_int_equal(piezo_rec_read(&r, k, f), PIEZO_OK);
            for (uint8_t i = 0; i < n; i++) {
                assert_int_equal(f[i], (int)(100 * k + c.signal[i]));
            }
        }
        assert_int_equal(buf[FRAMES * n], -1);
    }
}

/* The recorder's tick as it was written before issue 15's round 14 (the
 * decimation counted up, the state read again after the store), kept here as
 * the oracle of test_tick_matches_the_count_up_form. Only piezo_rec_trigger of
 * the library is used: it is unchanged and acts on the oracle's own copy. */
static void oracle_store(piezo_rec_t *r, const int16_t *s)
{
    int16_t *frame = r->buf_q15 + (size_t)r->write * r->cfg.n_channels;
    for (uint8_t i = 0; i < r->cfg.n_channels; i++) {
        frame[i] = s[r->cfg.signal[i]];
    }
    if (++r->write == r->capacity) {
        r->write = 0u;
    }
    if (r->filled < r->capacity) {
        r->filled++;
    }
}

static void oracle_process(piezo_rec_t *r, const int16_t *s)
{
    if (r->state != PIEZO_REC_ARMED && r->state != PIEZO_REC_TRIGGERED) {
        return;
    }
    if (r->decim_count != 0u) {
        if (++r->decim_count == r->cfg.decimation) {
            r->decim_count = 0u;
        }
        return;
    }
    if (r->cfg.decimation > 1u) {
        r->decim_count = 1u;
    }
    if (r->state == PIEZO_REC_ARMED &&
        (r->cfg.trigger == PIEZO_REC_RISING || r->cfg.trigger == PIEZO_REC_FALLING)) {
        int16_t v = s[r->cfg.trigger_signal];
        int16_t lvl = r->cfg.trigger_level_q15;
        if (r->have_last &&
            ((r->cfg.trigger == PIEZO_REC_RISING && r->last_trigger_q15 < lvl && v >= lvl) ||
             (r->cfg.trigger == PIEZO_REC_FALLING && r->last_trigger_q15 > lvl && v <= lvl))) {
            piezo_rec_trigger(r);
        }
        r->last_trigger_q15 = v;
        r->have_last = 1u;
    }
    oracle_store(r, s);
    if (r->state == PIEZO_REC_TRIGGERED) {
        r->written++;
        if (r->cfg.ring == 0u && --r->post_left == 0u) {
            r->state = PIEZO_REC_DONE;
        }
    }
}

static uint32_t lcg_next(uint32_t *x)
{
    return piezo_test_lcg(x) >> 8;
}

/* The tick (decimation by a countdown, the state kept in a register) against
 * the oracle above: random configurations (1-8 channels, decimation 1-5, every
 * trigger, pretrigger, ring), random arms, software triggers and resets
 * between ticks, a signal that crosses the trigger level both ways; after every
 * tick the state, the counters and the whole buffer must be the oracle's. */
static void test_tick_matches_the_count_up_form(void **state)
{
    (void)state;
    enum { NS = 6, LEN = 40 };
    uint32_t x = 12345u;
    for (int trial = 0; trial < 400; trial++) {
        int16_t buf[LEN], obuf[LEN];
        piezo_rec_t r, o;
        piezo_rec_cfg_t c = {0};
        c.n_channels = (uint8_t)(1u + lcg_next(&x) % 8u);
        for (uint8_t i = 0; i < c.n_channels; i++) {
            c.signal[i] = (uint8_t)(lcg_next(&x) % NS);
        }
        c.decimation = (uint16_t)(1u + lcg_next(&x) % 5u);
        c.trigger = (uint8_t)(lcg_next(&x) % 4u);
        c.trigger_signal = (uint8_t)(lcg_next(&x) % NS);
        c.trigger_level_q15 = (int16_t)((int32_t)(lcg_next(&x) % 200u) - 100);
        c.ring = (uint8_t)(lcg_next(&x) % 2u);
        c.pretrigger = c.ring ? 0u : lcg_next(&x) % 3u;
        for (int i = 0; i < LEN; i++) {
            buf[i] = obuf[i] = -7;
        }
        assert_int_equal(piezo_rec_init(&r, buf, LEN, NS), PIEZO_OK);
        assert_int_equal(piezo_rec_configure(&r, &c), PIEZO_OK);
        o = r;
        o.buf_q15 = obuf;
        for (int k = 0; k < 300; k++) {
            uint32_t ev = lcg_next(&x) % 64u;
            int16_t sig[NS];
            if (ev == 0u) {
                piezo_rec_arm(&r);
                piezo_rec_arm(&o);
            } else if (ev == 1u) {
                piezo_rec_trigger(&r);
                piezo_rec_trigger(&o);
            } else if (ev == 2u) {
                piezo_rec_reset(&r);
                piezo_rec_reset(&o);
            }
            for (int s = 0; s < NS; s++) {
                /* a triangle of period 40 ticks between -190 and 190, shifted per signal */
                int t = (k + 7 * s) % 40;
                sig[s] = (int16_t)((t < 20 ? t : 40 - t) * 19 - 190);
            }
            piezo_rec_process(&r, sig);
            oracle_process(&o, sig);
            assert_int_equal(r.state, o.state);
            assert_int_equal(r.write, o.write);
            assert_int_equal(r.filled, o.filled);
            assert_int_equal(r.written, o.written);
            assert_int_equal(r.post_left, o.post_left);
            assert_int_equal(r.have_last, o.have_last);
            assert_int_equal(r.last_trigger_q15, o.last_trigger_q15);
            assert_memory_equal(buf, obuf, sizeof buf);
        }
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_immediate_capture_in_order),
        cmocka_unit_test(test_rising_trigger_keeps_pretrigger_frames),
        cmocka_unit_test(test_decimation_and_software_trigger),
        cmocka_unit_test(test_bad_configuration_is_refused),
        cmocka_unit_test(test_ring_keeps_recording_over_the_oldest_frames),
        cmocka_unit_test(test_ring_refuses_pretrigger),
        cmocka_unit_test(test_written_counts_a_plain_capture),
        cmocka_unit_test(test_every_channel_count_stores_its_signals),
        cmocka_unit_test(test_tick_matches_the_count_up_form),
    };
    return cmocka_run_group_tests_name("recorder", tests, NULL, NULL);
}
