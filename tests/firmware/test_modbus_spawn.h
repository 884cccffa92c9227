/* Starts a test server program (rtu_pty_server, tcp_modbus_server) with a
 * pipe on its stdin and reads the first line it prints (device path or
 * port). Closing the pipe stops the server. */
#ifndef TEST_MODBUS_SPAWN_H
#define TEST_MODBUS_SPAWN_H

#include <stddef.h>
#include <sys/types.h>

typedef struct test_server {
    pid_t pid;
    int stdin_fd;
    char line[256];
} test_server_t;

/* Returns 0, or -1 when the program could not be started or printed nothing. */
int test_server_start(test_server_t *s, char *const argv[]);

/* Closes its stdin and waits for it; returns its exit status (or -1). */
int test_server_stop(test_server_t *s);

#endif /* TEST_MODBUS_SPAWN_H */
