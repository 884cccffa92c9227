/* Interop: libmodbus 3.1.6's clients against the firmware's protocol layer.
 *
 *   test_modbus_libmodbus rtu PATH/rtu_pty_server   RTU over a pseudo-terminal
 *   test_modbus_libmodbus tcp PATH/tcp_modbus_server TCP on 127.0.0.1
 *
 * The server is started as a child (test_modbus_spawn.h) and serves the test
 * register bank (test_modbus_regs.h), whose addresses and values are shared
 * with these checks, including the ones that must fail. */
#define _POSIX_C_SOURCE 200809L

#include <errno.h>
#include <stdlib.h>
#include <string.h>

#include <modbus.h>

#include "piezo_test.h"
#include "test_modbus_regs.h"
#include "test_modbus_spawn.h"

static int is_rtu;
static char *server_path;
static test_server_t server;
static modbus_t *ctx;

static int start(void **state)
{
    (void)state;
    char *argv[] = {server_path, NULL};
    assert_int_equal(test_server_start(&server, argv), 0);
    if (is_rtu) {
        ctx = modbus_new_rtu(server.line, 9600, 'N', 8, 1);
    } else {
        ctx = modbus_new_tcp("127.0.0.1", atoi(server.line));
    }
    assert_non_null(ctx);
    assert_int_equal(modbus_set_slave(ctx, 1), 0);
    assert_int_equal(modbus_set_response_timeout(ctx, 1, 0), 0);
    assert_int_equal(modbus_connect(ctx), 0);
    return 0;
}

static int stop(void **state)
{
    (void)state;
    modbus_close(ctx);
    modbus_free(ctx);
    assert_int_equal(test_server_stop(&server), 0);
    return 0;
}

static void test_read_input_registers(void **state)
{
    (void)state;
    uint16_t v[125];
    assert_int_equal(modbus_read_input_registers(ctx, 0, 10, v), 10);
    for (int i = 0; i < 10; i++) {
        assert_int_equal(v[i], tregs_input_value((uint16_t)i));
    }
    assert_int_equal(modbus_read_input_registers(ctx, 0x0183, 125, v), 125);
    for (int i = 0; i < 125; i++) {
        assert_int_equal(v[i], tregs_input_value((uint16_t)(0x0183 + i)));
    }
}

static void test_write_multiple_then_read_back(void **state)
{
    (void)state;
    uint16_t w[123];
    uint16_t r[125];
    for (int i = 0; i < 123; i++) {
        w[i] = (uint16_t)(0xC000 + 17 * i);
    }
    assert_int_equal(modbus_write_registers(ctx, 0x2005, 123, w), 123);
    assert_int_equal(modbus_read_registers(ctx, 0x2004, 125, r), 125);
    assert_int_equal(r[0], 0);
    for (int i = 0; i < 123; i++) {
        assert_int_equal(r[1 + i], w[i]);
    }
    assert_int_equal(r[124], 0);
}

static void test_write_single_and_read_write(void **state)
{
    (void)state;
    uint16_t r[4];
    assert_int_equal(modbus_write_register(ctx, 0x1003, 0xBEEF), 1);
    assert_int_equal(modbus_read_registers(ctx, 0x1003, 1, r), 1);
    assert_int_equal(r[0], 0xBEEF);
    uint16_t w[2] = {0x0102, 0x0304};
    /* FC 23: write 0x1004..0x1005, read 0x1003..0x1006 in the same request */
    assert_int_equal(modbus_write_and_read_registers(ctx, 0x1004, 2, w, 0x1003, 4, r), 4);
    assert_int_equal(r[0], 0xBEEF);
    assert_int_equal(r[1], 0x0102);
    assert_int_equal(r[2], 0x0304);
    assert_int_equal(r[3], 0);
}

static void test_exceptions_named_by_libmodbus(void **state)
{
    (void)state;
    uint16_t r[2];
    uint8_t bits[8];
    errno = 0;
    assert_int_equal(modbus_read_registers(ctx, 0x0000, 1, r), -1);
    assert_int_equal(errno, EMBXILADD);
    assert_int_equal(modbus_write_register(ctx, TREGS_MODE, 9), -1);
    assert_int_equal(errno, EMBXILVAL);
    assert_int_equal(modbus_read_registers(ctx, TREGS_FAULT, 1, r), -1);
    assert_int_equal(errno, EMBXSFAIL);
    assert_int_equal(modbus_read_bits(ctx, 0, 8, bits), -1);  /* FC 01 */
    assert_int_equal(errno, EMBXILFUN);
    /* the refused write changed nothing */
    assert_int_equal(modbus_read_registers(ctx, TREGS_MODE, 1, r), 1);
    assert_int_equal(r[0], 0);
}

static void test_quantity_limit_answered_by_server(void **state)
{
    (void)state;
    /* libmodbus refuses 126 registers itself; send the request raw */
    uint8_t raw[] = {1, 0x03, 0x20, 0x00, 0x00, 126};
    assert_true(modbus_send_raw_request(ctx, raw, sizeof raw) > 0);
    uint8_t rsp[MODBUS_MAX_ADU_LENGTH];
    int n = modbus_receive_confirmation(ctx, rsp);
    int h = modbus_get_header_length(ctx);
    assert_true(n >= h + 2);
    assert_int_equal(rsp[h], 0x83);
    assert_int_equal(rsp[h + 1], 0x03);
    /* an FC 16 announcing 124 registers (a 124-register request would not
     * fit the 253-byte PDU, so it carries 123 registers of data) */
    uint8_t w[7 + 246];
    memset(w, 0, sizeof w);
    w[0] = 1; w[1] = 0x10; w[2] = 0x20; w[3] = 0x00; w[4] = 0x00; w[5] = 124; w[6] = 246;
    assert_true(modbus_send_raw_request(ctx, w, sizeof w) > 0);
    n = modbus_receive_confirmation(ctx, rsp);
    assert_true(n >= h + 2);
    assert_int_equal(rsp[h], 0x90);
    assert_int_equal(rsp[h + 1], 0x03);
}

static void test_unit_ids(void **state)
{
    (void)state;
    uint16_t r[1];
    if (is_rtu) {
        /* another unit: silence, the client times out; then we answer again */
        assert_int_equal(modbus_set_response_timeout(ctx, 0, 300000), 0);
        assert_int_equal(modbus_set_slave(ctx, 5), 0);
        assert_int_equal(modbus_read_input_registers(ctx, 0, 1, r), -1);
        assert_int_equal(errno, ETIMEDOUT);
        /* broadcast write: executed, not answered (sent raw: libmodbus
         * 3.1.6's modbus_write_register waits for an answer to a broadcast) */
        assert_int_equal(modbus_set_slave(ctx, 0), 0);
        uint8_t bc[] = {0, 0x06, 0x10, 0x02, 0x00, 0x77};
        assert_true(modbus_send_raw_request(ctx, bc, sizeof bc) > 0);
        uint8_t rsp[MODBUS_MAX_ADU_LENGTH];
        assert_int_equal(modbus_receive_confirmation(ctx, rsp), -1);
        assert_int_equal(errno, ETIMEDOUT);
        assert_int_equal(modbus_set_slave(ctx, 1), 0);
        assert_int_equal(modbus_read_registers(ctx, 0x1002, 1, r), 1);
        assert_int_equal(r[0], 0x0077);
    } else {
        /* TCP: 0xFF (recommended) and our own id are answered */
        assert_int_equal(modbus_set_slave(ctx, 0xFF), 0);
        assert_int_equal(modbus_read_input_registers(ctx, 0, 1, r), 1);
        assert_int_equal(r[0], 0x505A);
        assert_int_equal(modbus_set_slave(ctx, 1), 0);
    }
    assert_int_equal(modbus_read_input_registers(ctx, 0, 1, r), 1);
    assert_int_equal(r[0], 0x505A);
}

int main(int argc, char **argv)
{
    if (argc != 3 || (strcmp(argv[1], "rtu") != 0 && strcmp(argv[1], "tcp") != 0)) {
        fprintf(stderr, "usage: %s rtu|tcp SERVER\n", argv[0]);
        return 2;
    }
    is_rtu = strcmp(argv[1], "rtu") == 0;
    server_path = argv[2];
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_read_input_registers),
        cmocka_unit_test(test_write_multiple_then_read_back),
        cmocka_unit_test(test_write_single_and_read_write),
        cmocka_unit_test(test_exceptions_named_by_libmodbus),
        cmocka_unit_test(test_quantity_limit_answered_by_server),
        cmocka_unit_test(test_unit_ids),
    };
    return cmocka_run_group_tests(tests, start, stop);
}
