/* libFuzzer target: the commit's checks (issue 13). An input is a table
 * image without its CRC, then a reference path; the harness appends a valid
 * CRC, so every input reaches the checks behind it. The controller (stage of
 * the default SIL stage, as the seeds) runs the calibrated-style base table;
 * the image is committed:
 *   - refused: the base table must still be the active one;
 *   - committed: the controller runs it in FEEDFORWARD over the reference
 *     path (and the sweep's own path, again), and every tick's feedforward
 *     drive, drive and DAC code must stay within the drive range (q15, the
 *     configured clamp, the DAC's code range). The sanitizers catch any
 *     integer overflow in the kernels that the ranges were meant to exclude.
 * Input: [u8 n_ref][n_ref x int16 reference][image without CRC].
 * Seeds: tests/fuzz/seed_commit.py. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "controller.h"
#include "crc32.h"
#include "ctl_test_cfg.h"
#include "piezo_interface.h"
#include "table_image.h"

static piezo_ctl_t ctl;
static uint8_t img[PIEZO_TABLE_MAX_BYTES];

static void fail(void)
{
    abort();
}

static void tick(int16_t r)
{
    int32_t in[2] = {0, 0}, dac = 0;
    const piezo_ctl_cfg_t *g = &ctl.cfg;
    ctl.setpoint_q15 = r;
    piezo_ctl_tick(&ctl, in, &dac);
    if (dac < g->dac_min || dac > g->dac_max) {
        fail();
    }
    if (ctl.sig[PIEZO_SIG_U] < g->limit.min_q15 || ctl.sig[PIEZO_SIG_U] > g->limit.max_q15) {
        fail();
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    piezo_ctl_cfg_t cfg = unit_cfg();
    /* the default SIL stage: 0..150 V, -2..22 um, axis 0 */
    piezo_ctl_stage_t stage = {1u, 0u, 0, 150000, -2000, 22000};
    uint32_t n_ref, len, c, before;
    uint16_t r;
    if (size < 1u) {
        return 0;
    }
    n_ref = data[0];
    if (size < 1u + 2u * n_ref) {
        return 0;
    }
    len = (uint32_t)(size - 1u - 2u * n_ref) + 4u;
    if (len > sizeof img || len < 8u) {
        return 0;
    }
    if (piezo_ctl_init(&ctl, &cfg) != 0) {
        fail();
    }
    piezo_ctl_set_stage(&ctl, &stage);
    memcpy(img, data + 1u + 2u * n_ref, len - 4u);
    c = piezo_crc32(0u, img, len - 4u);
    for (int k = 0; k < 4; k++) {
        img[len - 4u + (uint32_t)k] = (uint8_t)(c >> (8 * k));
    }
    if (piezo_ctl_set_mode(&ctl, PIEZO_MODE_FEEDFORWARD) != 0 || piezo_ctl_arm(&ctl, 1u) != 0) {
        fail();
    }
    before = piezo_ctl_active_crc(&ctl);
    /* over a session, as a client's upload: every check, the sweep included */
    piezo_ctl_set_key(&ctl, TEST_UNLOCK_KEY);
    if (piezo_ctl_unlock(&ctl, 1u, TEST_UNLOCK_KEY, 0u) != 0 || piezo_ctl_stage_write(&ctl, 1u, 0u, img, len) != 0) {
        fail();
    }
    r = piezo_ctl_commit(&ctl, 1u, 0u);
    tick(0);
#ifdef FUZZ_COMMIT_TRACE /* -DFUZZ_COMMIT_TRACE: the reason of each input on stderr */
    fprintf(stderr, "image of %u bytes: reason %u\n", (unsigned)len, (unsigned)r);
#endif
    if (r != PIEZO_TABLE_REASON_OK) {
        if (piezo_ctl_active_crc(&ctl) != before || r >= PIEZO_TABLE_REASON_N) {
            fail(); /* a refusal names a reason and leaves the table */
        }
        return 0;
    }
    if (piezo_ctl_active_crc(&ctl) != c) {
        fail();
    }
    /* the input's reference path, then the whole range up and down */
    for (uint32_t i = 0; i < n_ref; i++) {
        int16_t ref = (int16_t)(data[1u + 2u * i] | (data[2u + 2u * i] << 8));
        for (int k = 0; k < 4; k++) {
            tick(ref);
        }
    }
    for (int32_t x = -32768; x <= 32767; x += 512) {
        tick((int16_t)x);
    }
    for (int32_t x = 32767; x >= -32768; x -= 512) {
        tick((int16_t)x);
    }
    return 0;
}
