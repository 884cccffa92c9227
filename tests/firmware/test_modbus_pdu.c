/* Modbus PDU server: every function code, every exception, quantity limits,
 * lengths, and that a refused request calls nothing and changes nothing. */
#include <string.h>

#include "piezo_test.h"
#include "modbus_pdu.h"
#include "test_modbus_regs.h"
#include "mb_request.h"

static tregs_t bank;
static piezo_mb_regs_t regs;
static uint8_t rsp[PIEZO_MB_PDU_MAX];

static int setup(void **state)
{
    (void)state;
    regs = tregs_init(&bank);
    memset(rsp, 0xEE, sizeof rsp);
    return 0;
}

static size_t run(const uint8_t *req, size_t n)
{
    return piezo_mb_pdu_process(&regs, req, n, rsp, sizeof rsp);
}

static unsigned calls(void)
{
    return bank.calls_read_input + bank.calls_read_holding + bank.calls_write_holding;
}

static void assert_exception(size_t n, uint8_t fc, uint8_t code)
{
    assert_int_equal(n, 2);
    assert_int_equal(rsp[0], fc | 0x80u);
    assert_int_equal(rsp[1], code);
}

static uint16_t be16(const uint8_t *p)
{
    return (uint16_t)((p[0] << 8) | p[1]);
}

/* Builds fc, a16, b16 (5 bytes). */
static size_t req5(uint8_t *q, uint8_t fc, uint16_t a, uint16_t b)
{
    q[0] = fc;
    q[1] = (uint8_t)(a >> 8);
    q[2] = (uint8_t)a;
    q[3] = (uint8_t)(b >> 8);
    q[4] = (uint8_t)b;
    return 5u;
}

/* Builds an FC 16 request writing v[0..n) at addr. */
static size_t req16(uint8_t *q, uint16_t addr, const uint16_t *v, uint16_t n)
{
    return mb_req_write_multiple(q, addr, v, n);
}

/* Builds an FC 23 request. */
static size_t req23(uint8_t *q, uint16_t raddr, uint16_t rn, uint16_t waddr, const uint16_t *v,
                    uint16_t wn)
{
    req5(q, 0x17, raddr, rn);
    q[5] = (uint8_t)(waddr >> 8);
    q[6] = (uint8_t)waddr;
    q[7] = (uint8_t)(wn >> 8);
    q[8] = (uint8_t)wn;
    q[9] = (uint8_t)(2u * wn);
    for (uint16_t i = 0; i < wn; i++) {
        q[10 + 2 * i] = (uint8_t)(v[i] >> 8);
        q[11 + 2 * i] = (uint8_t)v[i];
    }
    return 10u + 2u * wn;
}

static void test_fc4_reads_input_registers(void **state)
{
    (void)state;
    uint8_t q[5];
    for (uint16_t count = 1; count <= 125; count++) {
        size_t n = run(q, req5(q, 0x04, 0x0003, count));
        assert_int_equal(n, 2u + 2u * count);
        assert_int_equal(rsp[0], 0x04);
        assert_int_equal(rsp[1], 2u * count);
        for (uint16_t i = 0; i < count; i++) {
            assert_int_equal(be16(&rsp[2 + 2 * i]), tregs_input_value((uint16_t)(3 + i)));
        }
    }
    /* Identity register at 0; the last mapped register. */
    assert_int_equal(run(q, req5(q, 0x04, 0x0000, 1)), 4);
    assert_int_equal(be16(&rsp[2]), 0x505A);
    assert_int_equal(run(q, req5(q, 0x04, 0x01FF, 1)), 4);
    assert_int_equal(be16(&rsp[2]), tregs_input_value(0x01FF));
}

static void test_fc3_reads_holding_registers(void **state)
{
    (void)state;
    for (uint16_t i = 0; i < 125; i++) {
        *tregs_holding(&bank, (uint16_t)(0x2000 + i)) = (uint16_t)(0xA000 + 7 * i);
    }
    uint8_t q[5];
    size_t n = run(q, req5(q, 0x03, 0x2000, 125));
    assert_int_equal(n, 252);
    assert_int_equal(rsp[0], 0x03);
    assert_int_equal(rsp[1], 250);
    for (uint16_t i = 0; i < 125; i++) {
        assert_int_equal(be16(&rsp[2 + 2 * i]), 0xA000 + 7 * i);
    }
    assert_int_equal(bank.calls_read_holding, 1);
    assert_int_equal(bank.calls_read_input, 0);
}

static void test_fc6_writes_one_register_and_echoes(void **state)
{
    (void)state;
    uint8_t q[5];
    req5(q, 0x06, 0x1003, 0xFFFF);
    assert_int_equal(run(q, 5), 5);
    assert_memory_equal(rsp, q, 5);
    assert_int_equal(*tregs_holding(&bank, 0x1003), 0xFFFF);
    req5(q, 0x06, 0x1003, 0x0000);
    assert_int_equal(run(q, 5), 5);
    assert_int_equal(*tregs_holding(&bank, 0x1003), 0x0000);
}

static void test_fc16_writes_up_to_123_registers(void **state)
{
    (void)state;
    uint16_t v[123];
    for (uint16_t i = 0; i < 123; i++) {
        v[i] = (uint16_t)(0x1234 + 0x0101 * i);
    }
    uint8_t q[PIEZO_MB_PDU_MAX];
    size_t len = req16(q, 0x2010, v, 123);
    assert_int_equal(len, 252);
    size_t n = run(q, len);
    assert_int_equal(n, 5);
    assert_memory_equal(rsp, q, 5);  /* fc, start, quantity */
    for (uint16_t i = 0; i < 123; i++) {
        assert_int_equal(*tregs_holding(&bank, (uint16_t)(0x2010 + i)), v[i]);
    }
    assert_null(tregs_holding(&bank, 0x2100));
}

static void test_fc23_writes_before_it_reads(void **state)
{
    (void)state;
    uint16_t w[3] = {0x1111, 0x2222, 0x3333};
    *tregs_holding(&bank, 0x1010) = 0x0AAA;
    uint8_t q[PIEZO_MB_PDU_MAX];
    /* Read 0x1010..0x1013 while writing 0x1011..0x1013: the read sees the write. */
    size_t n = run(q, req23(q, 0x1010, 4, 0x1011, w, 3));
    assert_int_equal(n, 10);
    assert_int_equal(rsp[0], 0x17);
    assert_int_equal(rsp[1], 8);
    assert_int_equal(be16(&rsp[2]), 0x0AAA);
    assert_int_equal(be16(&rsp[4]), 0x1111);
    assert_int_equal(be16(&rsp[6]), 0x2222);
    assert_int_equal(be16(&rsp[8]), 0x3333);
}

static void test_fc23_limits_are_125_read_121_write(void **state)
{
    (void)state;
    uint16_t w[122] = {0};
    uint8_t q[PIEZO_MB_PDU_MAX + 2];
    size_t len = req23(q, 0x2000, 125, 0x2000, w, 121);
    assert_int_equal(len, 252);
    assert_int_equal(run(q, len), 252);
    assert_exception(run(q, req23(q, 0x2000, 126, 0x2000, w, 1)), 0x17, 0x03);
    assert_exception(run(q, req23(q, 0x2000, 0, 0x2000, w, 1)), 0x17, 0x03);
    assert_exception(run(q, req23(q, 0x2000, 1, 0x2000, w, 0)), 0x17, 0x03);
    unsigned before = calls();
    assert_exception(run(q, req23(q, 0x2000, 1, 0x2000, w, 122)), 0x17, 0x03);
    assert_int_equal(calls(), before);
}

static void test_unsupported_functions_are_illegal_function(void **state)
{
    (void)state;
    for (unsigned fc = 0; fc <= 0xFF; fc++) {
        if (fc == 3 || fc == 4 || fc == 6 || fc == 16 || fc == 23) {
            continue;
        }
        uint8_t q[5];
        req5(q, (uint8_t)fc, 0x1000, 1);
        assert_exception(run(q, 5), (uint8_t)fc, 0x01);
        assert_exception(run(q, 1), (uint8_t)fc, 0x01);
    }
    assert_int_equal(calls(), 0);
}

static void test_null_callbacks_are_illegal_function(void **state)
{
    (void)state;
    piezo_mb_regs_t ro = regs;
    ro.write_holding = NULL;
    ro.read_input = NULL;
    uint8_t q[PIEZO_MB_PDU_MAX];
    uint16_t v[1] = {1};
    size_t n = piezo_mb_pdu_process(&ro, q, req5(q, 0x06, 0x1000, 1), rsp, sizeof rsp);
    assert_exception(n, 0x06, 0x01);
    n = piezo_mb_pdu_process(&ro, q, req16(q, 0x1000, v, 1), rsp, sizeof rsp);
    assert_exception(n, 0x10, 0x01);
    n = piezo_mb_pdu_process(&ro, q, req23(q, 0x1000, 1, 0x1000, v, 1), rsp, sizeof rsp);
    assert_exception(n, 0x17, 0x01);
    n = piezo_mb_pdu_process(&ro, q, req5(q, 0x04, 0, 1), rsp, sizeof rsp);
    assert_exception(n, 0x04, 0x01);
    n = piezo_mb_pdu_process(&ro, q, req5(q, 0x03, 0x1000, 1), rsp, sizeof rsp);
    assert_int_equal(n, 4);
}

static void test_unmapped_addresses_are_illegal_data_address(void **state)
{
    (void)state;
    uint8_t q[PIEZO_MB_PDU_MAX];
    uint16_t v[2] = {1, 2};
    assert_exception(run(q, req5(q, 0x04, 0x0200, 1)), 0x04, 0x02);
    assert_exception(run(q, req5(q, 0x04, 0x01FF, 2)), 0x04, 0x02);  /* runs past the end */
    assert_exception(run(q, req5(q, 0x03, 0x0FFF, 1)), 0x03, 0x02);
    assert_exception(run(q, req5(q, 0x03, 0x10FF, 2)), 0x03, 0x02);
    assert_exception(run(q, req5(q, 0x06, 0x3000, 5)), 0x06, 0x02);
    assert_exception(run(q, req16(q, 0x20FF, v, 2)), 0x10, 0x02);
    assert_exception(run(q, req23(q, 0x5000, 1, 0x2000, v, 1)), 0x17, 0x02);
}

static void test_address_overflow_refused_before_any_callback(void **state)
{
    (void)state;
    uint8_t q[PIEZO_MB_PDU_MAX];
    uint16_t v[2] = {1, 2};
    assert_exception(run(q, req5(q, 0x03, 0xFFFF, 2)), 0x03, 0x02);
    assert_exception(run(q, req5(q, 0x04, 0xFF84, 125)), 0x04, 0x02);
    assert_exception(run(q, req16(q, 0xFFFF, v, 2)), 0x10, 0x02);
    assert_exception(run(q, req23(q, 0xFFFF, 2, 0x2000, v, 1)), 0x17, 0x02);
    assert_exception(run(q, req23(q, 0x2000, 1, 0xFFFF, v, 2)), 0x17, 0x02);
    assert_int_equal(calls(), 0);
    /* The last address itself is in range for the protocol: the bank decides. */
    assert_exception(run(q, req5(q, 0x03, 0xFFFF, 1)), 0x03, 0x02);
    assert_int_equal(bank.calls_read_holding, 1);
}

static void test_read_quantity_limits(void **state)
{
    (void)state;
    uint8_t q[5];
    for (unsigned fc = 3; fc <= 4; fc++) {
        uint16_t base = fc == 3 ? 0x2000 : 0x0000;
        unsigned before = calls();
        assert_exception(run(q, req5(q, (uint8_t)fc, base, 0)), (uint8_t)fc, 0x03);
        assert_exception(run(q, req5(q, (uint8_t)fc, base, 126)), (uint8_t)fc, 0x03);
        assert_exception(run(q, req5(q, (uint8_t)fc, base, 0xFFFF)), (uint8_t)fc, 0x03);
        assert_int_equal(calls(), before);
        assert_int_equal(run(q, req5(q, (uint8_t)fc, base, 125)), 252);
    }
}

static void test_write_quantity_and_byte_count_limits(void **state)
{
    (void)state;
    uint16_t v[124] = {0};
    uint8_t q[PIEZO_MB_PDU_MAX + 8];
    /* 124 registers: 254-byte PDU, over the 123 limit */
    assert_exception(run(q, req16(q, 0x2000, v, 124)), 0x10, 0x03);
    /* quantity 0 with byte count 0 */
    assert_exception(run(q, req16(q, 0x2000, v, 0)), 0x10, 0x03);
    /* byte count disagrees with the quantity */
    size_t len = req16(q, 0x2000, v, 4);
    q[5] = 6;
    assert_exception(run(q, len), 0x10, 0x03);
    q[5] = 8;
    /* length disagrees with the byte count: one byte short, one too many */
    assert_exception(run(q, len - 1), 0x10, 0x03);
    q[len] = 0;
    assert_exception(run(q, len + 1), 0x10, 0x03);
    assert_int_equal(calls(), 0);
    /* FC 23 byte count disagreeing */
    len = req23(q, 0x2000, 1, 0x2000, v, 2);
    q[9] = 2;
    assert_exception(run(q, len), 0x17, 0x03);
    assert_int_equal(calls(), 0);
    assert_int_equal(run(q, req16(q, 0x2000, v, 123)), 5);
}

/* Every length 1..253 of every supported function: only the right one is
 * accepted, every other is ILLEGAL DATA VALUE without a callback. */
static void test_every_wrong_length_is_illegal_data_value(void **state)
{
    (void)state;
    uint8_t q[PIEZO_MB_PDU_MAX];
    uint16_t v[2] = {0x0001, 0x0002};
    struct { uint8_t fc; size_t good; } cases[5];
    uint8_t tmpl[5][PIEZO_MB_PDU_MAX];
    memset(tmpl, 0, sizeof tmpl);
    cases[0].fc = 3; cases[0].good = req5(tmpl[0], 0x03, 0x2000, 2);
    cases[1].fc = 4; cases[1].good = req5(tmpl[1], 0x04, 0x0000, 2);
    cases[2].fc = 6; cases[2].good = req5(tmpl[2], 0x06, 0x2000, 7);
    cases[3].fc = 16; cases[3].good = req16(tmpl[3], 0x2000, v, 2);
    cases[4].fc = 23; cases[4].good = req23(tmpl[4], 0x2000, 2, 0x2000, v, 2);
    for (int c = 0; c < 5; c++) {
        for (size_t len = 1; len <= PIEZO_MB_PDU_MAX; len++) {
            memcpy(q, tmpl[c], sizeof q);
            unsigned before = calls();
            size_t n = run(q, len);
            if (len == cases[c].good) {
                assert_int_equal(rsp[0], cases[c].fc);
                assert_true(n >= 5);
            } else {
                assert_exception(n, cases[c].fc, 0x03);
                assert_int_equal(calls(), before);
            }
        }
    }
    /* Longer than any PDU. */
    uint8_t big[PIEZO_MB_PDU_MAX + 1];
    memset(big, 0, sizeof big);
    big[0] = 0x03;
    assert_exception(run(big, sizeof big), 0x03, 0x03);
}

static void test_device_failure_is_exception_04(void **state)
{
    (void)state;
    uint8_t q[PIEZO_MB_PDU_MAX];
    uint16_t v[4] = {0};
    assert_exception(run(q, req5(q, 0x03, TREGS_FAULT, 1)), 0x03, 0x04);
    assert_exception(run(q, req5(q, 0x06, TREGS_FAULT, 1)), 0x06, 0x04);
    assert_exception(run(q, req16(q, TREGS_FAULT - 1, v, 2)), 0x10, 0x04);
    assert_exception(run(q, req23(q, TREGS_FAULT, 1, 0x2000, v, 1)), 0x17, 0x04);
}

static uint8_t odd_code(void *ctx, uint16_t addr, uint16_t count, uint16_t *out)
{
    (void)ctx; (void)addr; (void)count; (void)out;
    return 0x42;
}

static void test_unknown_callback_result_is_device_failure(void **state)
{
    (void)state;
    piezo_mb_regs_t odd = regs;
    odd.read_input = odd_code;
    uint8_t q[5];
    size_t n = piezo_mb_pdu_process(&odd, q, req5(q, 0x04, 0, 1), rsp, sizeof rsp);
    assert_exception(n, 0x04, 0x04);
}

static void test_refused_write_changes_nothing(void **state)
{
    (void)state;
    uint8_t q[PIEZO_MB_PDU_MAX];
    uint16_t v[32];
    for (int i = 0; i < 32; i++) {
        v[i] = (uint16_t)(0x5500 + i);
    }
    uint16_t snapshot[sizeof bank.hold / sizeof bank.hold[0]];
    memcpy(snapshot, bank.hold, sizeof snapshot);
    /* runs from mapped into unmapped registers */
    assert_exception(run(q, req16(q, 0x10F0, v, 32)), 0x10, 0x02);
    /* mode (0x1001) gets 4 in the middle of a block write */
    v[1] = 4;
    assert_exception(run(q, req16(q, 0x1000, v, 8)), 0x10, 0x03);
    assert_exception(run(q, req5(q, 0x06, TREGS_MODE, 4)), 0x06, 0x03);
    /* the fault register inside a block write */
    v[1] = 1;
    assert_exception(run(q, req16(q, 0x10F0, v, 15)), 0x10, 0x04);
    /* FC 23 with a refused write: the read is not attempted */
    unsigned reads = bank.calls_read_holding;
    v[0] = 9;
    assert_exception(run(q, req23(q, 0x2000, 1, TREGS_MODE, v, 1)), 0x17, 0x03);
    assert_int_equal(bank.calls_read_holding, reads);
    assert_memory_equal(bank.hold, snapshot, sizeof snapshot);
    /* and a good write right after does change it */
    v[1] = 3;
    assert_int_equal(run(q, req16(q, 0x1000, v, 8)), 5);
    assert_int_equal(*tregs_holding(&bank, TREGS_MODE), 3);
}

static void test_argument_errors_answer_nothing(void **state)
{
    (void)state;
    uint8_t q[5];
    req5(q, 0x03, 0x2000, 1);
    assert_int_equal(piezo_mb_pdu_process(&regs, q, 0, rsp, sizeof rsp), 0);
    assert_int_equal(piezo_mb_pdu_process(&regs, q, 5, rsp, PIEZO_MB_PDU_MAX - 1), 0);
    assert_int_equal(piezo_mb_pdu_process(NULL, q, 5, rsp, sizeof rsp), 0);
    assert_int_equal(piezo_mb_pdu_process(&regs, NULL, 5, rsp, sizeof rsp), 0);
    assert_int_equal(calls(), 0);
    assert_true(piezo_mb_pdu_is_broadcast_write(0x06));
    assert_true(piezo_mb_pdu_is_broadcast_write(0x10));
    assert_false(piezo_mb_pdu_is_broadcast_write(0x03));
    assert_false(piezo_mb_pdu_is_broadcast_write(0x04));
    assert_false(piezo_mb_pdu_is_broadcast_write(0x17));
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_fc4_reads_input_registers, setup),
        cmocka_unit_test_setup(test_fc3_reads_holding_registers, setup),
        cmocka_unit_test_setup(test_fc6_writes_one_register_and_echoes, setup),
        cmocka_unit_test_setup(test_fc16_writes_up_to_123_registers, setup),
        cmocka_unit_test_setup(test_fc23_writes_before_it_reads, setup),
        cmocka_unit_test_setup(test_fc23_limits_are_125_read_121_write, setup),
        cmocka_unit_test_setup(test_unsupported_functions_are_illegal_function, setup),
        cmocka_unit_test_setup(test_null_callbacks_are_illegal_function, setup),
        cmocka_unit_test_setup(test_unmapped_addresses_are_illegal_data_address, setup),
        cmocka_unit_test_setup(test_address_overflow_refused_before_any_callback, setup),
        cmocka_unit_test_setup(test_read_quantity_limits, setup),
        cmocka_unit_test_setup(test_write_quantity_and_byte_count_limits, setup),
        cmocka_unit_test_setup(test_every_wrong_length_is_illegal_data_value, setup),
        cmocka_unit_test_setup(test_device_failure_is_exception_04, setup),
        cmocka_unit_test_setup(test_unknown_callback_result_is_device_failure, setup),
        cmocka_unit_test_setup(test_refused_write_changes_nothing, setup),
        cmocka_unit_test_setup(test_argument_errors_answer_nothing, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
