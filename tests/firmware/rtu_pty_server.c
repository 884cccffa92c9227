/* Test server: the firmware's RTU framer and PDU server (with the test
 * register bank, test_modbus_regs.h) behind a pseudo-terminal, for interop
 * tests with libmodbus's and pymodbus's RTU clients.
 *
 *   rtu_pty_server [--baud N] [--unit N]
 *
 * Prints the slave device path (/dev/pts/N) on the first line of stdout and
 * serves until stdin reaches end of file or SIGTERM/SIGINT; then prints the
 * framer's counters on stderr. Bytes are timestamped when read() returns them
 * (CLOCK_MONOTONIC), so the t3.5 timing of the framer decides frame ends. */
#define _DEFAULT_SOURCE

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "modbus_rtu.h"
#include "test_modbus_regs.h"

static volatile sig_atomic_t stop;

static void on_signal(int sig)
{
    (void)sig;
    stop = 1;
}

static uint32_t now_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint32_t)((uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u);
}

static int write_all(int fd, const uint8_t *p, size_t n)
{
    while (n > 0) {
        ssize_t w = write(fd, p, n);
        if (w < 0) {
            if (errno == EINTR || errno == EAGAIN) {
                continue;
            }
            return -1;
        }
        p += w;
        n -= (size_t)w;
    }
    return 0;
}

int main(int argc, char **argv)
{
    unsigned long baud = 9600;
    unsigned long unit = 1;
    for (int i = 1; i + 1 < argc; i += 2) {
        if (strcmp(argv[i], "--baud") == 0) {
            baud = strtoul(argv[i + 1], NULL, 10);
        } else if (strcmp(argv[i], "--unit") == 0) {
            unit = strtoul(argv[i + 1], NULL, 10);
        } else {
            fprintf(stderr, "usage: %s [--baud N] [--unit N]\n", argv[0]);
            return 2;
        }
    }
    static tregs_t bank;
    piezo_mb_regs_t regs = tregs_init(&bank);
    static piezo_rtu_t rtu;
    if (unit > 255 || piezo_rtu_init(&rtu, (uint8_t)unit, (uint32_t)baud) != 0) {
        fprintf(stderr, "rtu_pty_server: bad unit %lu or baud %lu\n", unit, baud);
        return 2;
    }
    int master;
    int slave;
    char name[256];
    if (openpty(&master, &slave, name, NULL, NULL) != 0) {
        perror("rtu_pty_server: openpty");
        return 1;
    }
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);  /* no echo of our replies, no line editing */
    tcsetattr(slave, TCSANOW, &tio);
    /* The slave stays open here so the master never reads EIO between clients. */
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);
    signal(SIGPIPE, SIG_IGN);
    printf("%s\n", name);
    fflush(stdout);

    int poll_ms = (int)(piezo_rtu_t35_us(&rtu) / 2000u);
    if (poll_ms < 1) {
        poll_ms = 1;
    }
    uint8_t reply[PIEZO_RTU_ADU_MAX];
    while (!stop) {
        struct pollfd p[2] = {{master, POLLIN, 0}, {STDIN_FILENO, POLLIN, 0}};
        int rc = poll(p, 2, poll_ms);
        if (rc < 0 && errno != EINTR) {
            perror("rtu_pty_server: poll");
            break;
        }
        if (rc > 0 && (p[1].revents & (POLLIN | POLLHUP)) != 0) {
            char c;
            if (read(STDIN_FILENO, &c, 1) <= 0) {
                break;  /* the parent closed our stdin */
            }
        }
        if (rc > 0 && (p[0].revents & POLLIN) != 0) {
            uint8_t buf[512];
            ssize_t n = read(master, buf, sizeof buf);
            if (n > 0) {
                piezo_rtu_rx(&rtu, buf, (size_t)n, now_us());
            }
        }
        size_t out;
        while ((out = piezo_rtu_poll(&rtu, now_us(), &regs, reply, sizeof reply)) > 0) {
            if (write_all(master, reply, out) != 0) {
                perror("rtu_pty_server: write");
            }
        }
    }
    const piezo_rtu_stats_t *s = &rtu.stats;
    fprintf(stderr,
            "rtu_pty_server: frames %lu answered %lu broadcasts %lu crc_errors %lu "
            "malformed %lu not_for_us %lu overruns %lu\n",
            (unsigned long)s->frames, (unsigned long)s->answered, (unsigned long)s->broadcasts,
            (unsigned long)s->crc_errors, (unsigned long)s->malformed,
            (unsigned long)s->not_for_us, (unsigned long)s->overruns);
    close(slave);
    close(master);
    return 0;
}
