/*
 * insn_window.c - QEMU TCG plugin: exact instruction counts between two
 * marker addresses.
 *
 *   -plugin libinsn_window.so,begin=ADDR,end=ADDR,out=FILE
 *
 * Every executed guest instruction adds one to a counter (an inline add, so
 * the count is exact whatever the translation blocks look like). When the
 * instruction at `begin` executes, a window opens; when the one at `end`
 * executes, the window closes and its count, the instructions executed from
 * `begin` up to but not including `end`, is appended to FILE as one line.
 * Windows are written in the order they close; the guest names them (see
 * firmware/targets/cortex-m4/bench). Built against QEMU's own qemu-plugin.h
 * of the installed version (tools/qemu-plugins/build).
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <qemu-plugin.h>

QEMU_PLUGIN_EXPORT int qemu_plugin_version = QEMU_PLUGIN_VERSION;

static uint64_t executed;  /* all guest instructions so far */
static uint64_t opened_at; /* `executed` when the window opened */
static int window_open;
static uint64_t windows;
static uint64_t begin_addr, end_addr;
static FILE *out;

static void on_begin(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    opened_at = executed;
    window_open = 1;
}

static void on_end(unsigned int vcpu, void *udata)
{
    (void)vcpu;
    (void)udata;
    if (window_open) {
        fprintf(out, "%" PRIu64 "\n", executed - opened_at);
        window_open = 0;
        windows++;
    }
}

static void on_translate(qemu_plugin_id_t id, struct qemu_plugin_tb *tb)
{
    (void)id;
    size_t n = qemu_plugin_tb_n_insns(tb);
    for (size_t i = 0; i < n; i++) {
        struct qemu_plugin_insn *insn = qemu_plugin_tb_get_insn(tb, i);
        uint64_t vaddr = qemu_plugin_insn_vaddr(insn);
        /* The markers read the counter before this instruction's own add
         * (or after, the same for both): their difference is exact. */
        if (vaddr == begin_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_begin, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
        if (vaddr == end_addr) {
            qemu_plugin_register_vcpu_insn_exec_cb(insn, on_end, QEMU_PLUGIN_CB_NO_REGS, NULL);
        }
        qemu_plugin_register_vcpu_insn_exec_inline(insn, QEMU_PLUGIN_INLINE_ADD_U64, &executed, 1);
    }
}

static void on_exit(qemu_plugin_id_t id, void *udata)
{
    (void)id;
    (void)udata;
    fprintf(out, "# windows %" PRIu64 " instructions %" PRIu64 "\n", windows, executed);
    fclose(out);
}

QEMU_PLUGIN_EXPORT int qemu_plugin_install(qemu_plugin_id_t id, const qemu_info_t *info, int argc,
                                           char **argv)
{
    (void)info;
    const char *path = NULL;
    for (int i = 0; i < argc; i++) {
        if (strncmp(argv[i], "begin=", 6) == 0) {
            begin_addr = strtoull(argv[i] + 6, NULL, 0) & ~1ull; /* Thumb bit off */
        } else if (strncmp(argv[i], "end=", 4) == 0) {
            end_addr = strtoull(argv[i] + 4, NULL, 0) & ~1ull;
        } else if (strncmp(argv[i], "out=", 4) == 0) {
            path = argv[i] + 4;
        } else {
            fprintf(stderr, "insn_window: unknown argument %s\n", argv[i]);
            return -1;
        }
    }
    if (begin_addr == 0 || end_addr == 0 || path == NULL) {
        fprintf(stderr, "insn_window: needs begin=ADDR,end=ADDR,out=FILE\n");
        return -1;
    }
    out = fopen(path, "w");
    if (out == NULL) {
        perror(path);
        return -1;
    }
    qemu_plugin_register_vcpu_tb_trans_cb(id, on_translate);
    qemu_plugin_register_atexit_cb(id, on_exit, NULL);
    return 0;
}
