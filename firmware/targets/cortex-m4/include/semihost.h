/*
 * semihost.h - ARM semihosting (the "Semihosting for AArch32 and AArch64"
 * specification, v2): BKPT 0xAB with the operation in r0 and its argument in
 * r1. Test and benchmark images print through it and end with an exit status;
 * QEMU serves it with -semihosting-config enable=on,target=native. The
 * firmware image does not use it: on a board without a debugger BKPT faults.
 */
#ifndef PIEZO_SEMIHOST_H
#define PIEZO_SEMIHOST_H

#include <stddef.h>

/** Write a NUL-terminated string to the host's console. */
void piezo_sh_write0(const char *s);

/** Write n bytes to the host's console. */
void piezo_sh_write(const char *s, size_t n);

/** End the program with an exit status (SYS_EXIT_EXTENDED). */
void piezo_sh_exit(int status) __attribute__((noreturn));

#endif /* PIEZO_SEMIHOST_H */
