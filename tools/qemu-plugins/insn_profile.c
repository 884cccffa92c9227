/*
 * insn_profile.c - QEMU TCG plugin: where the instructions of one window go.
 *
 *   -plugin libinsn_profile.so,begin=ADDR,end=ADDR,window=N,out=FILE
 *
 * Windows open at `begin` and close at `end` as in insn_window.c, numbered
 * from 0 in the order they open. During window N every executed instruction
 * adds one to its address's count; at exit FILE gets one line "ADDR COUNT"
 * per executed address (hex, Thumb bit off). tools/bench-target --profile
 * sums them per function.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <qemu-plugin.h>

QEMU_PLUGIN_EXPORT int qemu_plugin_version = QEMU_PLUGIN_VERSION;

#define SLOTS (1u << 20) /* half-words of the 2 MiB from the flash base */
#define BASE ((uint64_t)0x08000000u)

static uint32_t *count;
static uint64_t opened; /* windows opened so far */
static uint64_t target;
static int in_target;
static uint64_t begin_addr, end_addr;
static const char *path;

static void on_begin(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    in_target = opened == target;
    opened++;
}

static void on_end(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    in_target = 0;
}

static void on_insn(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    if (in_target) {
        count[(uintptr_t)udata]++;
    }
}

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t vaddr = qemu_plugin_insn_vaddr(insn);
        if (vaddr == begin_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_begin, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
        if (vaddr == end_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_end, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
        if (vaddr >= BASE && (vaddr - BASE) / 2u < SLOTS) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_insn, QEMU_PLUGIN_CB_NO_REGS,
                                                   (void *)(uintptr_t)((vaddr - BASE) / 2u));
        }
    }
}

static void on_exit(qemu_plugin_id_t id, void *udata)
{
    (void)id;
    (void)udata;
    FILE *out = fopen(path, "w");
    if (out == NULL) {
        perror(path);
        return;
    }
    for (uint32_t s = 0; s < SLOTS; s++) {
        if (count[s] != 0u) {
            fprintf(out, "%08" PRIx64 " %" PRIu32 "\n", BASE + 2u * (uint64_t)s, count[s]);
        }
    }
    fclose(out);
}

QEMU_PLUGIN_EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc,
                                           char **argv)
{
    (void)info;
    int have_window = 0;
    for (int i = 0; i < argc; i++) {
        if (strncmp(argv[i], "begin=", 6) == 0) {
            begin_addr = strtoull(argv[i] + 6, NULL, 0) & ~1ull;
        } else if (strncmp(argv[i], "end=", 4) == 0) {
            end_addr = strtoull(argv[i] + 4, NULL, 0) & ~1ull;
        } else if (strncmp(argv[i], "window=", 7) == 0) {
            target = strtoull(argv[i] + 7, NULL, 0);
            have_window = 1;
        } else if (strncmp(argv[i], "out=", 4) == 0) {
            path = argv[i] + 4;
        } else {
            fprintf(stderr, "insn_profile: unknown argument %s\n", argv[i]);
            return -1;
        }
    }
    if (begin_addr == 0 || end_addr == 0 || path == NULL || !have_window) {
        fprintf(stderr, "insn_profile: needs begin=ADDR,end=ADDR,window=N,out=FILE\n");
        return -1;
    }
    count = calloc(SLOTS, sizeof *count);
    if (count == NULL) {
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_exit, NULL);
    return 0;
}
