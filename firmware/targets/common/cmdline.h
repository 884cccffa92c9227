/*
 * cmdline.h - the command line of the Linux targets (sil-stage, the comedi
 * DAQ controller): options that each take one value (--name VALUE), -h and
 * --help, and the Modbus TCP endpoint (--modbus-tcp HOST:PORT). Errors are
 * one line on stderr that starts with the program's name; the exit status
 * of a bad command line is 2.
 */
#ifndef PIEZO_CMDLINE_H
#define PIEZO_CMDLINE_H

#include <stddef.h>
#include <stdio.h>

/* An option and where its value goes: the argv string itself (the last
 * one given wins; the target converts numbers afterwards). */
typedef struct {
    const char *name;    /* "--config" */
    const char **value;  /* left alone when the option is not given */
} piezo_cli_opt_t;

/* piezo_cli_parse(): the command line is good, the target goes on. Any
 * other result is the exit status to return. */
#define PIEZO_CLI_RUN (-1)

/**
 * Reads argv[1..argc-1] as pairs "--name VALUE" of the options opts[0..n-1]
 * (the word after an option is its value, whatever it looks like).
 * -h or --help: the usage on stdout, returns 0. An option with no value
 * after it, or one not in opts: "PROG: --x needs a value" / "PROG: unknown
 * option --x" and the usage on stderr, returns 2. Otherwise PIEZO_CLI_RUN.
 */
int piezo_cli_parse(int argc, char **argv, const char *prog, const piezo_cli_opt_t *opts, size_t n,
                    void (*usage)(FILE *f));

/**
 * The value of --modbus-tcp (piezo_parse_host_port, pacer.h) into host and
 * *port. Returns 0; or 2 after "PROG: --modbus-tcp wants HOST:PORT, got
 * SPEC" or "PROG: bad port in SPEC" on stderr.
 */
int piezo_cli_modbus_tcp(const char *prog, const char *spec, char *host, unsigned long host_len, long *port);

/**
 * The value of --unlock-key: the controller's unlock key, exactly 8 hex
 * digits (optionally after 0x), not 0. Returns 0; or 2 after "PROG:
 * --unlock-key wants 8 hex digits (32 bits), got SPEC" on stderr.
 */
int piezo_cli_unlock_key(const char *prog, const char *spec, unsigned long *key);

#endif /* PIEZO_CMDLINE_H */
