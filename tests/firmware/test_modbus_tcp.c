/* Modbus TCP: MBAP handling and the libmodbus-based server loop, driven
 * in-process through real sockets on 127.0.0.1. */
#define _POSIX_C_SOURCE 200809L

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdint.h>
#include <string.h>
#include <time.h>
#include <sys/socket.h>
#include <unistd.h>

#include "piezo_test.h"
#include "modbus_tcp.h"
#include "tcp_server_libmodbus.h"
#include "test_modbus_regs.h"

static tregs_t bank;
static piezo_mb_regs_t regs;
static uint8_t rsp[PIEZO_TCP_ADU_MAX];

static int setup(void **state)
{
    (void)state;
    regs = tregs_init(&bank);
    return 0;
}

static void test_frame_len(void **state)
{
    (void)state;
    uint8_t h[7] = {0x12, 0x34, 0x00, 0x00, 0x00, 0x06, 0x01};
    for (size_t have = 0; have < 6; have++) {
        assert_int_equal(piezo_mb_tcp_frame_len(h, have), 0);
    }
    assert_int_equal(piezo_mb_tcp_frame_len(h, 6), 12);
    h[5] = 2;
    assert_int_equal(piezo_mb_tcp_frame_len(h, 7), 8);
    h[5] = 1;  /* unit id only, no function code */
    assert_int_equal(piezo_mb_tcp_frame_len(h, 7), -1);
    h[4] = 0x00; h[5] = 0xFE;  /* 254: unit + 253-byte PDU */
    assert_int_equal(piezo_mb_tcp_frame_len(h, 7), 260);
    h[5] = 0xFF;
    assert_int_equal(piezo_mb_tcp_frame_len(h, 7), -1);
    h[5] = 0x06; h[3] = 0x01;  /* protocol id 1 */
    assert_int_equal(piezo_mb_tcp_frame_len(h, 7), -1);
}

static void test_process_echoes_transaction_and_unit(void **state)
{
    (void)state;
    const uint8_t req[] = {0xBE, 0xEF, 0, 0, 0, 6, 0x01, 0x04, 0x00, 0x00, 0x00, 0x01};
    size_t n = piezo_mb_tcp_process(&regs, 1, req, sizeof req, rsp, sizeof rsp);
    const uint8_t want[] = {0xBE, 0xEF, 0, 0, 0, 5, 0x01, 0x04, 0x02, 0x50, 0x5A};
    assert_int_equal(n, sizeof want);
    assert_memory_equal(rsp, want, sizeof want);
    uint8_t q[sizeof req];
    memcpy(q, req, sizeof q);
    q[6] = 0xFF;
    assert_int_equal(piezo_mb_tcp_process(&regs, 1, q, sizeof q, rsp, sizeof rsp), 11);
    assert_int_equal(rsp[6], 0xFF);
    q[6] = 0x00;
    assert_int_equal(piezo_mb_tcp_process(&regs, 1, q, sizeof q, rsp, sizeof rsp), 11);
    q[6] = 0x02;  /* another unit */
    assert_int_equal(piezo_mb_tcp_process(&regs, 1, q, sizeof q, rsp, sizeof rsp), 0);
    q[6] = 0x01;
    q[3] = 0x01;  /* protocol id */
    assert_int_equal(piezo_mb_tcp_process(&regs, 1, q, sizeof q, rsp, sizeof rsp), 0);
    q[3] = 0x00;
    assert_int_equal(piezo_mb_tcp_process(&regs, 1, q, sizeof q - 1, rsp, sizeof rsp), 0);
    assert_int_equal(piezo_mb_tcp_process(&regs, 1, q, sizeof q, rsp, sizeof rsp - 1), 0);
    assert_int_equal(bank.calls_read_input, 3);
}

static void test_process_exception(void **state)
{
    (void)state;
    const uint8_t req[] = {0, 7, 0, 0, 0, 6, 0x01, 0x03, 0x00, 0x00, 0x00, 0x7E};
    size_t n = piezo_mb_tcp_process(&regs, 1, req, sizeof req, rsp, sizeof rsp);
    const uint8_t want[] = {0, 7, 0, 0, 0, 3, 0x01, 0x83, 0x03};
    assert_int_equal(n, sizeof want);
    assert_memory_equal(rsp, want, sizeof want);
}

/* ---- the server loop over real sockets ---- */

static piezo_tcp_server_t srv;

static int connect_client(void)
{
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    assert_true(fd >= 0);
    struct sockaddr_in sa;
    memset(&sa, 0, sizeof sa);
    sa.sin_family = AF_INET;
    sa.sin_port = htons(piezo_tcp_server_port(&srv));
    sa.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    assert_int_equal(connect(fd, (struct sockaddr *)&sa, sizeof sa), 0);
    /* let the server accept it */
    for (int i = 0; i < 50; i++) {
        assert_true(piezo_tcp_server_poll(&srv, 10) >= 0);
    }
    return fd;
}

/* Polls the server until the client has n bytes or the server gives up;
 * returns what arrived (0 on EOF). */
static ssize_t exchange(int fd, uint8_t *buf, size_t n)
{
    size_t got = 0;
    for (int i = 0; i < 200 && got < n; i++) {
        (void)piezo_tcp_server_poll(&srv, 5);
        struct pollfd p = {fd, POLLIN, 0};
        if (poll(&p, 1, 5) > 0) {
            ssize_t r = recv(fd, &buf[got], n - got, 0);
            if (r <= 0) {
                return got > 0 ? (ssize_t)got : r;
            }
            got += (size_t)r;
        }
    }
    return (ssize_t)got;
}

static int server_setup(void **state)
{
    setup(state);
    assert_int_equal(piezo_tcp_server_open(&srv, NULL, 0, 1, &regs), 0);
    assert_true(piezo_tcp_server_port(&srv) > 0);
    return 0;
}

static int server_teardown(void **state)
{
    (void)state;
    piezo_tcp_server_close(&srv);
    return 0;
}

static void test_server_answers_pipelined_and_split_requests(void **state)
{
    (void)state;
    int fd = connect_client();
    /* two requests in one send */
    const uint8_t two[] = {0, 1, 0, 0, 0, 6, 1, 0x06, 0x10, 0x03, 0x12, 0x34,
                           0, 2, 0, 0, 0, 6, 1, 0x03, 0x10, 0x03, 0x00, 0x01};
    assert_int_equal(send(fd, two, sizeof two, 0), (ssize_t)sizeof two);
    uint8_t buf[64];
    const uint8_t want[] = {0, 1, 0, 0, 0, 6, 1, 0x06, 0x10, 0x03, 0x12, 0x34,
                            0, 2, 0, 0, 0, 5, 1, 0x03, 0x02, 0x12, 0x34};
    assert_int_equal(exchange(fd, buf, sizeof want), (ssize_t)sizeof want);
    assert_memory_equal(buf, want, sizeof want);
    /* one request a byte at a time, the server polled in between */
    const uint8_t one[] = {0, 3, 0, 0, 0, 6, 1, 0x04, 0x00, 0x00, 0x00, 0x01};
    for (size_t i = 0; i < sizeof one; i++) {
        assert_int_equal(send(fd, &one[i], 1, 0), 1);
        for (int k = 0; k < 3; k++) {
            assert_int_equal(piezo_tcp_server_poll(&srv, 2), i + 1 < sizeof one ? 0 : (k == 0 ? 1 : 0));
        }
    }
    assert_int_equal(recv(fd, buf, sizeof buf, 0), 11);
    assert_int_equal(buf[1], 3);
    assert_int_equal(buf[9], 0x50);
    close(fd);
}

static void test_server_survives_bad_requests(void **state)
{
    (void)state;
    int fd = connect_client();
    uint8_t buf[64];
    /* unknown function code with a body: exception 01, stream stays in sync */
    const uint8_t unk[] = {0, 9, 0, 0, 0, 6, 1, 0x2B, 0x0E, 0x01, 0x00, 0x00};
    assert_int_equal(send(fd, unk, sizeof unk, 0), (ssize_t)sizeof unk);
    assert_int_equal(exchange(fd, buf, 9), 9);
    const uint8_t ex[] = {0, 9, 0, 0, 0, 3, 1, 0xAB, 0x01};
    assert_memory_equal(buf, ex, sizeof ex);
    /* a read of 126 registers: exception 03 */
    const uint8_t big[] = {0, 10, 0, 0, 0, 6, 1, 0x03, 0x20, 0x00, 0x00, 0x7E};
    assert_int_equal(send(fd, big, sizeof big, 0), (ssize_t)sizeof big);
    assert_int_equal(exchange(fd, buf, 9), 9);
    assert_int_equal(buf[7], 0x83);
    assert_int_equal(buf[8], 0x03);
    /* another unit id: no answer, and the next request is answered */
    const uint8_t other[] = {0, 11, 0, 0, 0, 6, 7, 0x04, 0x00, 0x00, 0x00, 0x01,
                             0, 12, 0, 0, 0, 6, 1, 0x04, 0x00, 0x00, 0x00, 0x01};
    assert_int_equal(send(fd, other, sizeof other, 0), (ssize_t)sizeof other);
    assert_int_equal(exchange(fd, buf, 11), 11);
    assert_int_equal(buf[1], 12);
    /* a protocol id that is not Modbus: that connection is closed ... */
    const uint8_t notmb[] = {0, 13, 0, 1, 0, 6, 1, 0x04, 0x00, 0x00, 0x00, 0x01};
    assert_int_equal(send(fd, notmb, sizeof notmb, 0), (ssize_t)sizeof notmb);
    /* EOF, or a reset because the server closed with the frame's rest unread */
    assert_true(exchange(fd, buf, 1) <= 0);
    assert_int_equal(srv.dropped, 1);
    close(fd);
    /* ... and the server still serves a new one */
    fd = connect_client();
    const uint8_t ok[] = {0, 14, 0, 0, 0, 6, 1, 0x04, 0x00, 0x00, 0x00, 0x01};
    assert_int_equal(send(fd, ok, sizeof ok, 0), (ssize_t)sizeof ok);
    assert_int_equal(exchange(fd, buf, 11), 11);
    assert_int_equal(buf[1], 14);
    close(fd);
}

static void test_server_limits_clients_and_poll_returns_at_once(void **state)
{
    (void)state;
    int fds[PIEZO_TCP_MAX_CLIENTS + 1];
    srv.evict_ms = 600000u; /* nobody idle long enough to be replaced */
    for (int i = 0; i <= PIEZO_TCP_MAX_CLIENTS; i++) {
        fds[i] = connect_client();
    }
    uint8_t buf[16];
    const uint8_t ok[] = {0, 1, 0, 0, 0, 6, 1, 0x04, 0x00, 0x00, 0x00, 0x01};
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        assert_int_equal(send(fds[i], ok, sizeof ok, 0), (ssize_t)sizeof ok);
        assert_int_equal(exchange(fds[i], buf, 11), 11);
    }
    /* the one too many was closed by the server */
    (void)send(fds[PIEZO_TCP_MAX_CLIENTS], ok, sizeof ok, MSG_NOSIGNAL);
    assert_true(exchange(fds[PIEZO_TCP_MAX_CLIENTS], buf, 11) <= 0);
    for (int i = 0; i <= PIEZO_TCP_MAX_CLIENTS; i++) {
        close(fds[i]);
    }
    /* nothing to do: a zero-timeout poll answers nothing and does not block */
    for (int i = 0; i < 100; i++) {
        assert_true(piezo_tcp_server_poll(&srv, 0) >= 0);
    }
    assert_int_equal(piezo_tcp_server_poll(&srv, 0), 0);
}

/* Every slot taken: a new client replaces the connection idle longest. */
static void test_server_new_client_replaces_the_longest_idle(void **state)
{
    (void)state;
    int fds[PIEZO_TCP_MAX_CLIENTS + 1];
    uint8_t buf[16];
    const uint8_t ok[] = {0, 1, 0, 0, 0, 6, 1, 0x04, 0x00, 0x00, 0x00, 0x01};
    srv.evict_ms = 100u;
    for (int i = 0; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        fds[i] = connect_client(); /* 500 ms each */
    }
    /* all but the first ask something: the first is the idlest */
    for (int i = 1; i < PIEZO_TCP_MAX_CLIENTS; i++) {
        assert_int_equal(send(fds[i], ok, sizeof ok, 0), (ssize_t)sizeof ok);
        assert_int_equal(exchange(fds[i], buf, 11), 11);
    }
    fds[PIEZO_TCP_MAX_CLIENTS] = connect_client();
    assert_int_equal(srv.evicted, 1);
    assert_int_equal(srv.refused, 0);
    (void)send(fds[0], ok, sizeof ok, MSG_NOSIGNAL);
    assert_true(exchange(fds[0], buf, 11) <= 0); /* the idlest went */
    for (int i = 1; i <= PIEZO_TCP_MAX_CLIENTS; i++) {
        assert_int_equal(send(fds[i], ok, sizeof ok, 0), (ssize_t)sizeof ok);
        assert_int_equal(exchange(fds[i], buf, 11), 11); /* the others, and the new one, are served */
    }
    for (int i = 0; i <= PIEZO_TCP_MAX_CLIENTS; i++) {
        close(fds[i]);
    }
}

/* A silent connection and a half-sent request are closed after their timeouts. */
static uint64_t mono_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000u + (uint64_t)ts.tv_nsec / 1000000u;
}

/* Polls the server until `timed_out` reaches n or 20 s pass. Load on the host only lengthens the wait: each phase
 * below holds the other timeout out of reach, so a slow poll cannot make the
 * wrong timer fire. */
static void poll_until_timed_out(unsigned long n)
{
    uint64_t t0 = mono_ms();
    while (srv.timed_out < n && mono_ms() - t0 < 20000u) {
        assert_true(piezo_tcp_server_poll(&srv, 5) >= 0);
    }
}

static void test_server_times_out_idle_and_half_sent(void **state)
{
    (void)state;
    uint8_t buf[16];
    const uint8_t half[] = {0, 1, 0, 0, 0, 6, 1, 0x04}; /* 8 of 12 bytes */

    /* idle: a silent client is closed (within 20 s: only the idle timer can fire) */
    srv.idle_ms = 300u;
    srv.partial_ms = 60000u;
    int idle = connect_client();
    poll_until_timed_out(1);
    assert_int_equal(srv.timed_out, 1);
    assert_true(exchange(idle, buf, 1) <= 0);

    /* half sent: closed by the partial timeout (the idle one is out of reach) */
    srv.idle_ms = 60000u;
    srv.partial_ms = 150u;
    int part = connect_client();
    uint64_t t0 = mono_ms();
    assert_int_equal(send(part, half, sizeof half, 0), (ssize_t)sizeof half);
    poll_until_timed_out(2);
    assert_int_equal(srv.timed_out, 2); /* within 20 s: only the partial timer can fire */
    assert_true(mono_ms() - t0 >= srv.partial_ms);
    assert_true(exchange(part, buf, 1) <= 0);
    close(idle);
    close(part);
}

static void test_server_open_errors(void **state)
{
    (void)state;
    piezo_tcp_server_t s;
    assert_int_equal(piezo_tcp_server_open(&s, NULL, 0, 1, NULL), -1);
    assert_int_equal(errno, EINVAL);
    piezo_tcp_server_t a;
    assert_int_equal(piezo_tcp_server_open(&a, "127.0.0.1", 0, 1, &regs), 0);
    /* the same port twice */
    assert_int_equal(piezo_tcp_server_open(&s, "127.0.0.1", piezo_tcp_server_port(&a), 1, &regs), -1);
    piezo_tcp_server_close(&a);
    piezo_tcp_server_close(&s);  /* closing a failed server is harmless */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test_setup(test_frame_len, setup),
        cmocka_unit_test_setup(test_process_echoes_transaction_and_unit, setup),
        cmocka_unit_test_setup(test_process_exception, setup),
        cmocka_unit_test_setup_teardown(test_server_answers_pipelined_and_split_requests,
                                        server_setup, server_teardown),
        cmocka_unit_test_setup_teardown(test_server_survives_bad_requests, server_setup,
                                        server_teardown),
        cmocka_unit_test_setup_teardown(test_server_limits_clients_and_poll_returns_at_once,
                                        server_setup, server_teardown),
        cmocka_unit_test_setup_teardown(test_server_new_client_replaces_the_longest_idle, server_setup,
                                        server_teardown),
        cmocka_unit_test_setup_teardown(test_server_times_out_idle_and_half_sent, server_setup, server_teardown),
        cmocka_unit_test_setup(test_server_open_errors, setup),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
