/*
 * daq-controller: the firmware controller on Linux with a comedi board. Each
 * axis reads its position sensor on an analog input and drives its amplifier
 * from an analog output, paced at the configured rate (10 kHz), and serves
 * its register map over Modbus TCP, until SIGINT or SIGTERM.
 *
 *   daq-controller --config FILE --modbus-tcp HOST:PORT
 *
 * Axis i is served on TCP port PORT + i (PORT 0: a free port for axis 0).
 * Tables persist in the configuration's flash file (axis 1: FILE.axis2), the
 * controller parameters beside it in FILE.params (FILE.axis2.params).
 * One line on stdout says when it is ready; on exit it prints the tick
 * statistics. Exit status: 0 after a signal, 1 when the device, the network
 * or the flash file fail (an I/O error while running included), 2 for a bad
 * command line or configuration.
 *
 * Each period (firmware/targets/common/pacer.h, policy SKIP): sleep to the
 * deadline (clock_nanosleep, TIMER_ABSTIME), read the inputs, tick every
 * axis, write the outputs, then serve Modbus without blocking. A wake-up more
 * than a period late, or a tick whose work ends after the next deadline, is
 * reported to the controllers as an overrun; the deadlines missed are
 * dropped, not caught up (the hardware's samples of those periods are gone).
 * The drive's safe value (u_safe) is written right after the device is
 * opened, on exit and after any I/O error.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <inttypes.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmdline.h"
#include "daq_config.h"
#include "daq_io.h"
#include "flash_file.h"
#include "pacer.h"
#include "piezo_interface.h"
#include "regmap.h"
#include "tcp_server_libmodbus.h"

static volatile sig_atomic_t g_stop;
static piezo_ctl_t g_ctl[PIEZO_DAQ_MAX_AXES]; /* large: static */
static piezo_pacer_t g_pacer;
static piezo_daq_t g_daq;

static void on_signal(int sig)
{
    (void)sig;
    g_stop = 1;
}

static void usage(FILE *f)
{
    fprintf(f, "usage: daq-controller --config FILE --modbus-tcp HOST:PORT [--unlock-key HEX8]\n");
}

static const char *conv_name(int conv)
{
    return conv == PIEZO_DAQ_CONV_SOFTCAL ? "softcal" : (conv == PIEZO_DAQ_CONV_HARDCAL ? "hardcal" : "ideal");
}

int main(int argc, char **argv)
{
    const char *cfg_path = NULL, *tcp_spec = NULL;
    char host[64] = "127.0.0.1", errbuf[1024];
    long port = -1;
    static piezo_daq_config_t cfg;
    piezo_regmap_t map[PIEZO_DAQ_MAX_AXES];
    piezo_mb_regs_t regs[PIEZO_DAQ_MAX_AXES];
    piezo_tcp_server_t tcp[PIEZO_DAQ_MAX_AXES];
    piezo_flash_file_t flash[PIEZO_DAQ_MAX_AXES];
    piezo_storage_t store[PIEZO_DAQ_MAX_AXES];
    piezo_flash_file_t pflash[PIEZO_DAQ_MAX_AXES];
    piezo_storage_t pstore[PIEZO_DAQ_MAX_AXES];
    piezo_scale_t scale[PIEZO_DAQ_MAX_AXES];
    piezo_daq_loop_t loop;
    piezo_rt_result_t rt;
    int n_open = 0, status = 0, cli;
    const char *key_arg = NULL;
    unsigned long key = 0u; /* none: every unlock refused (tables and configuration read-only) */
    const piezo_cli_opt_t opts[] = {{"--config", &cfg_path}, {"--modbus-tcp", &tcp_spec}, {"--unlock-key", &key_arg}};

    cli = piezo_cli_parse(argc, argv, "daq-controller", opts, sizeof opts / sizeof opts[0], usage);
    if (cli != PIEZO_CLI_RUN) {
        return cli; /* 0 after --help, 2 for a bad command line */
    }
    if (cfg_path == NULL || tcp_spec == NULL) {
        fprintf(stderr, "daq-controller: --config FILE and --modbus-tcp HOST:PORT are required\n");
        usage(stderr);
        return 2;
    }
    if (piezo_cli_modbus_tcp("daq-controller", tcp_spec, host, sizeof host, &port) != 0) {
        return 2;
    }
    if (key_arg != NULL && piezo_cli_unlock_key("daq-controller", key_arg, &key) != 0) {
        return 2;
    }

    if (piezo_daq_config_load(cfg_path, &cfg, errbuf, sizeof errbuf) != 0) {
        fprintf(stderr, "daq-controller: %s\n", errbuf);
        return 2;
    }
    if (piezo_daq_open(&g_daq, &cfg, errbuf, sizeof errbuf) != 0) {
        fprintf(stderr, "daq-controller: %s\n", errbuf);
        return 1;
    }
    if (g_daq.notes[0] != '\0') {
        fprintf(stderr, "daq-controller: warning: %s\n", g_daq.notes);
    }
    for (int i = 0; i < g_daq.n_axes; i++) {
        piezo_ctl_cfg_t cc;
        int rc = piezo_daq_ctl_config(&g_daq, &cfg, i, &cc, &scale[i]);
        if (rc != 0 || piezo_ctl_init(&g_ctl[i], &cc) != 0) {
            fprintf(stderr, "daq-controller: %s: axis %d: drive.safe_v/min_v/max_v outside the drive range "
                            "%.3f..%.3f V of the output range\n",
                    cfg_path, i, scale[i].drive_min_v, scale[i].drive_max_v);
            piezo_daq_close(&g_daq);
            return 2;
        }
    }
    /* the stage rests at the safe drive from here on */
    if (piezo_daq_write_safe(&g_daq) != 0) {
        fprintf(stderr, "daq-controller: %s: cannot write the safe drive: %s\n", cfg.device,
                comedi_strerror(comedi_errno()));
        piezo_daq_close(&g_daq);
        return 1;
    }
    for (int i = 0; i < g_daq.n_axes && status == 0; i++) {
        char path[PIEZO_DAQ_PATH_MAX + 16];
        const uint32_t slot = PIEZO_STORE_RECORD_BYTES + PIEZO_TABLE_MAX_BYTES;
        piezo_regmap_init(&map[i], &g_ctl[i]);
        map[i].axis = (uint16_t)i;
        map[i].n_axes = (uint16_t)g_daq.n_axes;
        map[i].tick_hz = cfg.tick_hz;
        map[i].drive_min_mv = (int32_t)(scale[i].drive_min_v * 1000.0);
        map[i].drive_max_mv = (int32_t)(scale[i].drive_max_v * 1000.0);
        map[i].position_min_nm = (int32_t)(scale[i].position_min_um * 1000.0);
        map[i].position_max_nm = (int32_t)(scale[i].position_max_um * 1000.0);
        piezo_regmap_provision(&map[i], (uint32_t)key);
        regs[i] = piezo_regmap_regs(&map[i]);
        snprintf(path, sizeof path, "%s%s", cfg.flash, i == 0 ? "" : ".axis2");
        if (piezo_flash_file_open(&flash[i], path, 2u * slot) != 0) {
            fprintf(stderr, "daq-controller: cannot open flash file %s: %s\n", path,
                    flash[i].why[0] ? flash[i].why : strerror(errno));
            status = 1;
            break;
        }
        store[i] = piezo_flash_file_storage(&flash[i], slot);
        {
            uint16_t r = piezo_ctl_attach_store(&g_ctl[i], &store[i]);
            if (r != PIEZO_TABLE_REASON_OK) {
                fprintf(stderr, "daq-controller: stored table of axis %d not loaded (reason %u)\n", i, r);
            }
        }
        /* the controller parameters beside the tables: FILE.params (param_store.h) */
        snprintf(path, sizeof path, "%s%s.params", cfg.flash, i == 0 ? "" : ".axis2");
        if (piezo_flash_file_open_magic(&pflash[i], path, 2u * PIEZO_PARAMS_SLOT_BYTES, PIEZO_PARAMS_MAGIC) != 0) {
            fprintf(stderr, "daq-controller: cannot open parameter file %s: %s\n", path,
                    pflash[i].why[0] ? pflash[i].why : strerror(errno));
            piezo_flash_file_close(&flash[i]);
            status = 1;
            break;
        }
        pstore[i] = piezo_flash_file_storage(&pflash[i], PIEZO_PARAMS_SLOT_BYTES);
        {
            uint16_t r = piezo_regmap_attach_params(&map[i], &pstore[i]);
            if (r != PIEZO_PARAMS_REASON_OK && r != PIEZO_PARAMS_REASON_NONE_STORED) {
                fprintf(stderr, "daq-controller: stored parameters of axis %d not loaded (reason %u): defaults\n", i,
                        r);
            }
        }
        if (piezo_tcp_server_open(&tcp[i], host, port == 0 ? 0 : (uint16_t)(port + i), (uint8_t)(i + 1), &regs[i]) !=
            0) {
            fprintf(stderr, "daq-controller: cannot listen on %s:%ld: %s\n", host, port == 0 ? 0 : port + i,
                    strerror(errno));
            piezo_flash_file_close(&flash[i]);
            piezo_flash_file_close(&pflash[i]);
            status = 1;
            break;
        }
        n_open = i + 1;
    }
    if (status != 0) {
        for (int i = 0; i < n_open; i++) {
            piezo_tcp_server_close(&tcp[i]);
            piezo_flash_file_close(&flash[i]);
            piezo_flash_file_close(&pflash[i]);
        }
        piezo_daq_close(&g_daq);
        return status;
    }
    piezo_stop_signals(on_signal);
    rt = piezo_rt_setup(cfg.priority, 1);
    if (cfg.priority > 0 && !rt.fifo) {
        fprintf(stderr, "daq-controller: warning: SCHED_FIFO refused (%s): running at normal priority\n",
                strerror(rt.fifo_errno));
    }
    if (!rt.locked) {
        fprintf(stderr, "daq-controller: warning: mlockall refused (%s): page faults may delay ticks\n",
                strerror(rt.lock_errno));
    }
    if (key_arg == NULL) {
        fprintf(stderr, "daq-controller: no --unlock-key: tables and configuration cannot be written\n");
    }
    printf("daq-controller: ready tcp=%s:%u axes=%d device=%s rate=%u Hz sched=%s", host,
           (unsigned)piezo_tcp_server_port(&tcp[0]), g_daq.n_axes, cfg.device, (unsigned)cfg.tick_hz,
           rt.fifo ? "fifo" : "other");
    for (int i = 0; i < g_daq.n_axes; i++) {
        printf(" axis%d=ao%u/%u:%s,ai%u/%u:%s", i, g_daq.ao[i].subdevice, g_daq.ao[i].channel,
               conv_name(g_daq.ao[i].conv), g_daq.ai[i].subdevice, g_daq.ai[i].channel, conv_name(g_daq.ai[i].conv));
    }
    printf("\n");
    fflush(stdout);

    memset(&loop, 0, sizeof loop);
    loop.daq = &g_daq;
    for (int i = 0; i < g_daq.n_axes; i++) {
        loop.ctl[i] = &g_ctl[i];
    }
    piezo_pacer_init(&g_pacer, 1000000000LL / (int64_t)cfg.tick_hz, PIEZO_PACE_SKIP, piezo_now_ns());
    while (!g_stop) {
        int over = 0, io;
        int64_t start;
        if (piezo_pacer_sleep(&g_pacer) != 0) {
            continue; /* EINTR: look at the stop flag */
        }
        start = piezo_now_ns();
        if (piezo_pacer_wake(&g_pacer, start, &over) == 0u) {
            continue;
        }
        io = piezo_daq_loop_tick(&loop);
        if (piezo_pacer_done(&g_pacer, start, piezo_now_ns()) != 0) {
            over = 1; /* the tick ran past the next deadline */
        }
        if (io != 0) {
            fprintf(stderr, "daq-controller: %s: I/O error at tick %" PRIu64 ": %s; safe drive written, stopping\n",
                    cfg.device, g_pacer.ticks, comedi_strerror(comedi_errno()));
            status = 1;
            break;
        }
        for (int i = 0; i < g_daq.n_axes; i++) {
            if (over) {
                piezo_ctl_overrun(&g_ctl[i]);
            }
            map[i].tick_time_ns = g_pacer.tick_time_ns;
            map[i].tick_time_max_ns = g_pacer.tick_time_max_ns;
            (void)piezo_tcp_server_poll(&tcp[i], 0);
        }
    }

    if (piezo_daq_write_safe(&g_daq) != 0) {
        fprintf(stderr, "daq-controller: %s: cannot write the safe drive on exit: %s\n", cfg.device,
                comedi_strerror(comedi_errno()));
        status = 1;
    }
    printf("daq-controller: stopped after %" PRIu64 " ticks (%.1f s), overruns %" PRIu64 ", missed deadlines %" PRIu64
           ", long ticks %" PRIu64 ", tick lateness p50 %ld us, p99 %ld us, max %.1f us, tick time max %.1f us\n",
           g_pacer.ticks, (double)g_pacer.ticks / (double)cfg.tick_hz, g_pacer.overruns, g_pacer.skipped,
           g_pacer.long_ticks, piezo_pacer_percentile_us(&g_pacer, 0.50), piezo_pacer_percentile_us(&g_pacer, 0.99),
           (double)g_pacer.max_late_ns / 1000.0, (double)g_pacer.tick_time_max_ns / 1000.0);
    for (int i = 0; i < g_daq.n_axes; i++) {
        piezo_tcp_server_close(&tcp[i]);
        piezo_flash_file_close(&flash[i]);
        piezo_flash_file_close(&pflash[i]);
    }
    piezo_daq_close(&g_daq);
    return status;
}
