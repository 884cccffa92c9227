/* See test_modbus_spawn.h. */
#define _POSIX_C_SOURCE 200809L

#include "test_modbus_spawn.h"

#include <stdio.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

int test_server_start(test_server_t *s, char *const argv[])
{
    int in[2];
    int out[2];
    if (pipe(in) != 0 || pipe(out) != 0) {
        return -1;
    }
    pid_t pid = fork();
    if (pid < 0) {
        return -1;
    }
    if (pid == 0) {
        dup2(in[0], STDIN_FILENO);
        dup2(out[1], STDOUT_FILENO);
        close(in[0]);
        close(in[1]);
        close(out[0]);
        close(out[1]);
        execv(argv[0], argv);
        _exit(127);
    }
    close(in[0]);
    close(out[1]);
    s->pid = pid;
    s->stdin_fd = in[1];
    size_t n = 0;
    char c;
    while (n + 1 < sizeof s->line && read(out[0], &c, 1) == 1 && c != '\n') {
        s->line[n++] = c;
    }
    s->line[n] = '\0';
    close(out[0]);
    return n > 0 ? 0 : -1;
}

int test_server_stop(test_server_t *s)
{
    close(s->stdin_fd);
    int status = 0;
    if (waitpid(s->pid, &status, 0) != s->pid) {
        return -1;
    }
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}
