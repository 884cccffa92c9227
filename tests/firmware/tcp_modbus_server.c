/* Test server: the libmodbus-based TCP server loop (tcp_server_libmodbus.h)
 * with the test register bank, for interop tests with libmodbus's and
 * pymodbus's TCP clients.
 *
 *   tcp_modbus_server [--port N]      (default 0: a free port)
 *
 * Listens on 127.0.0.1, prints the port on the first line of stdout and
 * serves until stdin reaches end of file or SIGTERM/SIGINT. The loop polls
 * with a zero timeout between 100 us sleeps, as a 10 kHz SIL loop would. */
#define _DEFAULT_SOURCE

#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "tcp_server_libmodbus.h"
#include "test_modbus_regs.h"

static volatile sig_atomic_t stop;

static void on_signal(int sig)
{
    (void)sig;
    stop = 1;
}

int main(int argc, char **argv)
{
    unsigned long port = 0;
    if (argc == 3 && strcmp(argv[1], "--port") == 0) {
        port = strtoul(argv[2], NULL, 10);
    } else if (argc != 1) {
        fprintf(stderr, "usage: %s [--port N]\n", argv[0]);
        return 2;
    }
    static tregs_t bank;
    piezo_mb_regs_t regs = tregs_init(&bank);
    static piezo_tcp_server_t srv;
    if (port > 65535 || piezo_tcp_server_open(&srv, NULL, (uint16_t)port, 1, &regs) != 0) {
        perror("tcp_modbus_server: open");
        return 1;
    }
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    signal(SIGPIPE, SIG_IGN);
    printf("%u\n", (unsigned)piezo_tcp_server_port(&srv));
    fflush(stdout);
    const struct timespec tick = {0, 100000};
    unsigned long loops = 0;
    while (!stop) {
        if (piezo_tcp_server_poll(&srv, 0) < 0 && errno != EINTR) {
            perror("tcp_modbus_server: poll");
            break;
        }
        if ((++loops & 63u) == 0u) {
            struct pollfd p = {STDIN_FILENO, POLLIN, 0};
            char c;
            if (poll(&p, 1, 0) > 0 && read(STDIN_FILENO, &c, 1) <= 0) {
                break;
            }
        }
        nanosleep(&tick, NULL);
    }
    fprintf(stderr, "tcp_modbus_server: answered %lu, dropped connections %lu\n",
            srv.answered, srv.dropped);
    piezo_tcp_server_close(&srv);
    return 0;
}
