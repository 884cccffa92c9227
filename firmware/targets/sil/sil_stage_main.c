/*
 * sil-stage: a virtual controller. The firmware controller runs against the C
 * stage model, paced at 10 kHz of wall time, and serves its register map over
 * Modbus TCP (libmodbus, 127.0.0.1 unless told otherwise) and Modbus RTU on a
 * pseudo-terminal, until SIGINT or SIGTERM.
 *
 *   sil-stage --modbus-tcp HOST:PORT [--modbus-rtu-pty LINK] [--stage PARAMS.json]
 *             [--flash FILE] [--seed N] [--rtu-baud BAUD]
 *
 * PORT 0 picks a free port for axis 0. Axis i (two-axis stages) is served on
 * TCP port PORT + i (the picked port + i) and on RTU unit id i + 1. Tables persist in FILE (a flash
 * emulation; default $TMPDIR/piezoctl-sil-<port>.flash; a missing or empty FILE is created
 * erased, an existing one is used only if it is a flash image of this build's layout, and
 * anything else, a truncated image included, is refused with exit status 1 and left untouched:
 * flash_file.h). The controller parameters persist beside it in FILE.params (two slots of
 * PIEZO_PARAMS_SLOT_BYTES, param_store.h), loaded at start. One line on stdout
 * says when it is ready and where; on exit it prints the tick statistics, as
 * a sentence and as a `sil-stage: stats key=value ...` line.
 *
 * Each period: sleep to the deadline (clock_nanosleep, TIMER_ABSTIME), tick
 * every axis and the stage, then serve the protocol without blocking. A tick
 * that starts more than one period late is an overrun: the missed ticks run
 * at once so that the stage's time keeps up with the wall clock (the pacer's
 * CATCH_UP policy, firmware/targets/common/pacer.h).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <pty.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "cmdline.h"
#include "flash_file.h"
#include "modbus_rtu.h"
#include "pacer.h"
#include "piezo_interface.h"
#include "regmap.h"
#include "sil_loop.h"
#include "tcp_server_libmodbus.h"

#define PERIOD_NS 100000L

static volatile sig_atomic_t g_stop;
static piezo_sil_t g_sil; /* large: static */
static piezo_pacer_t g_pacer;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static void usage(FILE *f)
{
    fprintf(f, "usage: sil-stage --modbus-tcp HOST:PORT [--modbus-rtu-pty LINK] [--stage PARAMS.json]\n"
               "                 [--flash FILE] [--seed N] [--rtu-baud BAUD] [--unlock-key HEX8]\n");
}

static int open_pty(const char *link, int *slave_keep)
{
    int m;
    char name[128];
    struct termios t;
    if (openpty(&m, slave_keep, name, NULL, NULL) != 0) {
        return -1;
    }
    /* raw line; the slave stays open so a client closing it does not hang up the line */
    if (tcgetattr(*slave_keep, &t) == 0) {
        cfmakeraw(&t);
        (void)tcsetattr(*slave_keep, TCSANOW, &t);
    }
    (void)fcntl(m, F_SETFL, fcntl(m, F_GETFL) | O_NONBLOCK);
    (void)unlink(link);
    if (symlink(name, link) != 0) {
        close(m);
        return -1;
    }
    return m;
}

int main(int argc, char **argv)
{
    const char *tcp_spec = NULL, *pty_link = NULL, *stage_path = NULL, *flash_path = NULL;
    const char *seed_arg = NULL, *baud_arg = NULL, *key_arg = NULL;
    unsigned long key = PIEZO_UNLOCK_DEFAULT_SIL_KEY; /* a development stage: documented default */
    const piezo_cli_opt_t opts[] = {
        {"--modbus-tcp", &tcp_spec}, {"--modbus-rtu-pty", &pty_link}, {"--stage", &stage_path},
        {"--flash", &flash_path},    {"--seed", &seed_arg},           {"--rtu-baud", &baud_arg},
        {"--unlock-key", &key_arg},
    };
    uint64_t seed = 1;
    uint32_t baud = 115200;
    char host[64] = "127.0.0.1", errbuf[256], flash_default[512];
    long port = -1;
    stage_params params;
    piezo_regmap_t map[STAGE_MAX_AXES];
    piezo_mb_regs_t regs[STAGE_MAX_AXES];
    piezo_tcp_server_t tcp[STAGE_MAX_AXES];
    piezo_rtu_t rtu[STAGE_MAX_AXES];
    piezo_flash_file_t flash[STAGE_MAX_AXES];
    piezo_storage_t store[STAGE_MAX_AXES];
    piezo_flash_file_t pflash[STAGE_MAX_AXES];
    piezo_storage_t pstore[STAGE_MAX_AXES];
    int pty = -1, pty_slave = -1, cli;

    cli = piezo_cli_parse(argc, argv, "sil-stage", opts, sizeof opts / sizeof opts[0], usage);
    if (cli != PIEZO_CLI_RUN) {
        return cli; /* 0 after --help, 2 for a bad command line */
    }
    if (key_arg != NULL && piezo_cli_unlock_key("sil-stage", key_arg, &key) != 0) {
        return 2;
    }
    if (seed_arg != NULL) {
        seed = strtoull(seed_arg, NULL, 10);
    }
    if (baud_arg != NULL) {
        baud = (uint32_t)strtoul(baud_arg, NULL, 10);
    }
    if (tcp_spec == NULL) {
        fprintf(stderr, "sil-stage: --modbus-tcp HOST:PORT is required\n");
        usage(stderr);
        return 2;
    }
    if (piezo_cli_modbus_tcp("sil-stage", tcp_spec, host, sizeof host, &port) != 0) {
        return 2;
    }
    if (stage_path != NULL) {
        if (stage_params_load_json(stage_path, &params, errbuf, sizeof errbuf) != STAGE_OK) {
            fprintf(stderr, "sil-stage: %s\n", errbuf);
            return 2;
        }
    } else {
        params = stage_params_default();
    }
    if (piezo_sil_init(&g_sil, &params, seed) != 0) {
        fprintf(stderr, "sil-stage: the stage parameters cannot drive a controller\n");
        return 2;
    }
    for (int i = 0; i < g_sil.n_axes; i++) {
        const piezo_scale_t *sc = &g_sil.scale[i];
        piezo_regmap_init(&map[i], &g_sil.ctl[i]);
        map[i].axis = (uint16_t)i;
        map[i].n_axes = (uint16_t)g_sil.n_axes;
        map[i].tick_hz = (uint32_t)params.sample_rate_hz;
        map[i].drive_min_mv = (int32_t)(sc->drive_min_v * 1000.0);
        map[i].drive_max_mv = (int32_t)(sc->drive_max_v * 1000.0);
        map[i].position_min_nm = (int32_t)(sc->position_min_um * 1000.0);
        map[i].position_max_nm = (int32_t)(sc->position_max_um * 1000.0);
        /* the stage and the key before the stored table is loaded (checked against both) */
        piezo_regmap_provision(&map[i], (uint32_t)key);
        regs[i] = piezo_regmap_regs(&map[i]);
        /* PORT 0: axis 1 on a free port, axis i on that port + i (as for a given PORT) */
        long p_i = port == 0 ? (i == 0 ? 0 : (long)piezo_tcp_server_port(&tcp[0]) + i) : port + i;
        if (piezo_tcp_server_open(&tcp[i], host, (uint16_t)p_i, (uint8_t)(i + 1), &regs[i]) != 0) {
            fprintf(stderr, "sil-stage: cannot listen on %s:%ld: %s\n", host, port + i, strerror(errno));
            return 1;
        }
        if (piezo_rtu_init(&rtu[i], (uint8_t)(i + 1), baud) != 0) {
            fprintf(stderr, "sil-stage: bad RTU baud rate %u\n", baud);
            return 2;
        }
        if (flash_path == NULL) {
            const char *tmp = getenv("TMPDIR");
            snprintf(flash_default, sizeof flash_default, "%s/piezoctl-sil-%u.flash", tmp ? tmp : "/tmp",
                     (unsigned)piezo_tcp_server_port(&tcp[0]));
        }
        {
            char path[600];
            snprintf(path, sizeof path, "%s%s", flash_path ? flash_path : flash_default,
                     i == 0 ? "" : ".axis2");
            uint32_t slot = PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES;
            if (piezo_flash_file_open(&flash[i], path, 2u * slot) != 0) {
                fprintf(stderr, "sil-stage: cannot open flash file %s: %s\n", path,
                        flash[i].why[0] ? flash[i].why : strerror(errno));
                return 1;
            }
            store[i] = piezo_flash_file_storage(&flash[i], slot);
            uint16_t r = piezo_ctl_attach_store(&g_sil.ctl[i], &store[i]);
            if (r != PIEZO_TABLE_REASON_OK) {
                fprintf(stderr, "sil-stage: stored table of axis %d not loaded (reason %u)\n", i + 1, r);
            }
            /* the controller parameters beside it: FILE.params */
            snprintf(path, sizeof path, "%s%s.params", flash_path ? flash_path : flash_default,
                     i == 0 ? "" : ".axis2");
            if (piezo_flash_file_open_magic(&pflash[i], path, 2u * PIEZO_PARAMS_SLOT_BYTES, PIEZO_PARAMS_MAGIC) != 0) {
                fprintf(stderr, "sil-stage: cannot open parameter file %s: %s\n", path,
                        pflash[i].why[0] ? pflash[i].why : strerror(errno));
                return 1;
            }
            pstore[i] = piezo_flash_file_storage(&pflash[i], PIEZO_PARAMS_SLOT_BYTES);
            r = piezo_regmap_attach_params(&map[i], &pstore[i]);
            if (r != PIEZO_PARAMS_REASON_OK && r != PIEZO_PARAMS_REASON_NONE_STORED) {
                fprintf(stderr, "sil-stage: stored parameters of axis %d not loaded (reason %u): defaults\n", i + 1,
                        r);
            }
        }
    }
    if (pty_link != NULL && (pty = open_pty(pty_link, &pty_slave)) < 0) {
        fprintf(stderr, "sil-stage: cannot make the pseudo-terminal %s: %s\n", pty_link, strerror(errno));
        return 1;
    }
    piezo_stop_signals(on_signal);
    (void)piezo_rt_setup(50, 0); /* SCHED_FIFO where permitted, timer slack 1 ns */
    printf("sil-stage: ready tcp=%s:%u axes=%d rtu=%s\n", host, (unsigned)piezo_tcp_server_port(&tcp[0]),
           g_sil.n_axes, pty_link ? pty_link : "-");
    fflush(stdout);

    piezo_pacer_init(&g_pacer, PERIOD_NS, PIEZO_PACE_CATCH_UP, piezo_now_ns());
    while (!g_stop) {
        if (piezo_pacer_sleep(&g_pacer) == EINTR) {
            continue;
        }
        int64_t start = piezo_now_ns();
        int over = 0;
        /* the ticks due by now: one, or more after a stall */
        uint32_t due = piezo_pacer_wake(&g_pacer, start, &over);
        for (uint32_t k = 0; k < due; k++) {
            piezo_sil_tick(&g_sil);
            if (over) {
                for (int i = 0; i < g_sil.n_axes; i++) {
                    piezo_ctl_overrun(&g_sil.ctl[i]);
                }
            }
        }
        (void)piezo_pacer_done(&g_pacer, start, piezo_now_ns());
        for (int i = 0; i < g_sil.n_axes; i++) {
            map[i].tick_time_ns = g_pacer.tick_time_ns;
            map[i].tick_time_max_ns = g_pacer.tick_time_max_ns;
            (void)piezo_tcp_server_poll(&tcp[i], 0);
        }
        if (pty >= 0) {
            uint8_t buf[256], reply[PIEZO_RTU_ADU_MAX];
            uint32_t us = (uint32_t)(piezo_now_ns() / 1000);
            ssize_t n = read(pty, buf, sizeof buf);
            for (int i = 0; i < g_sil.n_axes; i++) {
                if (n > 0) {
                    piezo_rtu_rx(&rtu[i], buf, (size_t)n, us);
                }
                size_t r = piezo_rtu_poll(&rtu[i], us, &regs[i], reply, sizeof reply);
                if (r > 0 && write(pty, reply, r) != (ssize_t)r) {
                    /* a client that went away: nothing to do */
                }
            }
        }
    }

    printf("sil-stage: stopped after %" PRIu64 " ticks (%.1f s), overruns %" PRIu64 ", "
           "tick lateness p50 %ld us, p99 %ld us, max %.1f us\n",
           g_pacer.ticks, (double)g_pacer.ticks / 10000.0, g_pacer.overruns, piezo_pacer_percentile_us(&g_pacer, 0.50),
           piezo_pacer_percentile_us(&g_pacer, 0.99), (double)g_pacer.max_late_ns / 1000.0);
    /* the same, machine-readable (tools/bench-sil): key=value, lateness in us */
    printf("sil-stage: stats ticks=%" PRIu64 " wakeups=%" PRIu64 " overruns=%" PRIu64 " long_ticks=%" PRIu64
           " late_p50_us=%ld late_p99_us=%ld late_p999_us=%ld late_max_us=%.1f tick_time_max_us=%.1f\n",
           g_pacer.ticks, g_pacer.wakeups, g_pacer.overruns, g_pacer.long_ticks,
           piezo_pacer_percentile_us(&g_pacer, 0.50), piezo_pacer_percentile_us(&g_pacer, 0.99),
           piezo_pacer_percentile_us(&g_pacer, 0.999), (double)g_pacer.max_late_ns / 1000.0,
           (double)g_pacer.tick_time_max_ns / 1000.0);
    for (int i = 0; i < g_sil.n_axes; i++) {
        piezo_tcp_server_close(&tcp[i]);
        piezo_flash_file_close(&flash[i]);
        piezo_flash_file_close(&pflash[i]);
    }
    if (pty >= 0) {
        close(pty);
        if (pty_slave >= 0) {
            close(pty_slave);
        }
        (void)unlink(pty_link);
    }
    return 0;
}
