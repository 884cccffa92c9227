/*
 * semihost.c - semihosting console and exit for test and benchmark images,
 * and those images' exit and fault behaviour (the firmware image has its own,
 * in halt.c).
 */
#include <stdint.h>

#include "board.h"
#include "semihost.h"

#define SYS_OPEN 0x01
#define SYS_WRITE0 0x04
#define SYS_WRITE 0x05
#define SYS_EXIT_EXTENDED 0x20
#define ADP_STOPPED_APPLICATION_EXIT 0x20026u

static int sh_call(int op, const void *arg)
{
    register int r0 __asm("r0") = op;
    register const void *r1 __asm("r1") = arg;
    __asm volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void piezo_sh_write0(const char *s)
{
    (void)sh_call(SYS_WRITE0, s);
}

void piezo_sh_write(const char *s, size_t n)
{
    /* ":tt" opened for writing ("w", mode 4) is the host's standard output. */
    static int tt = -1;
    if (tt < 0) {
        const uintptr_t open_args[3] = {(uintptr_t)":tt", 4u, 3u};
        tt = sh_call(SYS_OPEN, open_args);
    }
    const uintptr_t write_args[3] = {(uintptr_t)tt, (uintptr_t)s, n};
    (void)sh_call(SYS_WRITE, write_args);
}

void piezo_sh_exit(int status)
{
    const uintptr_t args[2] = {ADP_STOPPED_APPLICATION_EXIT, (uintptr_t)status};
    (void)sh_call(SYS_EXIT_EXTENDED, args);
    for (;;) {
    }
}

void piezo_board_exit(int status)
{
    if (!piezo_board_stack_intact()) {
        piezo_sh_write0("board: stack overflow: the canary below the stack was overwritten\n");
        piezo_sh_exit(2);
    }
    /* A process exit status keeps 8 bits: never let a count wrap to 0. */
    piezo_sh_exit(status < 0 ? 1 : status > 255 ? 255 : status);
}

static void put_hex(const char *name, uint32_t v)
{
    char buf[20];
    const char *digits = "0123456789abcdef";
    size_t n = 0;
    while (*name != '\0' && n < 8u) {
        buf[n++] = *name++;
    }
    buf[n++] = '=';
    for (int shift = 28; shift >= 0; shift -= 4) {
        buf[n++] = digits[(v >> shift) & 0xFu];
    }
    buf[n++] = ' ';
    buf[n] = '\0';
    piezo_sh_write0(buf);
}

void piezo_board_fault(const char *what, const uint32_t *frame)
{
    piezo_sh_write0("board: ");
    piezo_sh_write0(what);
    piezo_sh_write0(": ");
    if (frame != 0) {
        put_hex("pc", frame[6]);
        put_hex("lr", frame[5]);
        put_hex("xpsr", frame[7]);
    }
    put_hex("cfsr", SCB_CFSR);
    put_hex("hfsr", SCB_HFSR);
    piezo_sh_write0("\n");
    piezo_sh_exit(3);
}
