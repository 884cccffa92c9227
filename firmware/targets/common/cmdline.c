#include "cmdline.h"

#include <string.h>

#include "pacer.h"

int piezo_cli_parse(int argc, char **argv, const char *prog, const piezo_cli_opt_t *opts, size_t n,
                    void (*usage)(FILE *f))
{
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        size_t k = 0;
        if (strcmp(a, "-h") == 0 || strcmp(a, "--help") == 0) {
            usage(stdout);
            return 0;
        }
        if (v == NULL) {
            fprintf(stderr, "%s: %s needs a value\n", prog, a);
            usage(stderr);
            return 2;
        }
        while (k < n && strcmp(a, opts[k].name) != 0) {
            k++;
        }
        if (k == n) {
            fprintf(stderr, "%s: unknown option %s\n", prog, a);
            usage(stderr);
            return 2;
        }
        *opts[k].value = v;
        i++;
    }
    return PIEZO_CLI_RUN;
}

int piezo_cli_modbus_tcp(const char *prog, const char *spec, char *host, unsigned long host_len, long *port)
{
    switch (piezo_parse_host_port(spec, host, host_len, port)) {
    case 0: return 0;
    case -1:
        fprintf(stderr, "%s: --modbus-tcp wants HOST:PORT, got %s\n", prog, spec);
        return 2;
    default:
        fprintf(stderr, "%s: bad port in %s\n", prog, spec);
        return 2;
    }
}

int piezo_cli_unlock_key(const char *prog, const char *spec, unsigned long *key)
{
    const char *p = spec;
    unsigned long v = 0u;
    int n = 0;
    if (p[0] == '0' && (p[1] == 'x' || p[1] == 'X')) {
        p += 2;
    }
    for (; *p != '\0' && n <= 8; p++, n++) {
        int d = (*p >= '0' && *p <= '9') ? *p - '0'
                : (*p >= 'a' && *p <= 'f') ? *p - 'a' + 10
                : (*p >= 'A' && *p <= 'F') ? *p - 'A' + 10
                                           : -1;
        if (d < 0) {
            break;
        }
        v = (v << 4) | (unsigned long)d;
    }
    if (*p != '\0' || n != 8 || v == 0u) {
        fprintf(stderr, "%s: --unlock-key wants 8 hex digits (32 bits), got %s\n", prog, spec);
        return 2;
    }
    *key = v;
    return 0;
}
