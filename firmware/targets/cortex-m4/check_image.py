#!/usr/bin/env python3
"""Build-time checks of Cortex-M4 objects and images: no division and no
floating point where the tick runs.

    check_image.py core LIB.a       the core library: no object references a
                                    software division or floating-point helper,
                                    none contains a divide or an FPU instruction
    check_image.py tick IMAGE.elf   the linked image: nothing reachable through
                                    direct calls and branches from the tick
                                    handler is such a helper or holds such an
                                    instruction, and no indirect call hides a
                                    callee from this check

Exits 1 with the offending symbols or instructions named. Needs binutils for
arm-none-eabi (ARM_NM, ARM_OBJDUMP override the tool names).
"""
import os
import re
import subprocess
import sys

NM = os.environ.get("ARM_NM", "arm-none-eabi-nm")
OBJDUMP = os.environ.get("ARM_OBJDUMP", "arm-none-eabi-objdump")
ROOT = "SysTick_Handler"

# Run-time ABI helpers (ARM IHI 0043) and libgcc routines for division and
# floating point, and the C library's floating-point functions.
FORBIDDEN = re.compile(
    r"^(?:__aeabi_(?:\w*div\w*|[df][a-z]\w*|u?[il]2[df]|ul2[df])"
    r"|__(?:u?div|u?mod|udivmod|divmod)[sdt]i[34]"
    r"|__(?:add|sub|mul|div|neg)[sdt]f3|__(?:extend|trunc)\w+f2"
    r"|__float\w+|__fix\w+|__(?:eq|ne|lt|le|gt|ge|unord|cmp)[sdt]f2"
    r"|(?:sin|cos|tan|exp|log|pow|sqrt|floor|ceil|round|lround|llround|fabs|fmod)f?)$")
# Divide instructions (integer and VFP) and any instruction on FPU registers.
BAD_INSN = re.compile(
    r"^(?:[su]div|vdiv)\S*|^v\w+\.(?:f16|f32|f64|[su]32)\b|^v(?:mov|ldr|str|push|pop|ldm|stm|mrs|msr)\w*\b")
BRANCH = re.compile(r"^(?:b|bl|blx|b\.w|b\.n|cbn?z|b(?:eq|ne|cs|hs|cc|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)(?:\.[wn])?)$")


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def disassemble(path):
    """{function: [(mnemonic, operands)]} from objdump -d."""
    funcs, cur = {}, None
    for line in run([OBJDUMP, "-d", "--no-show-raw-insn", path]).splitlines():
        m = re.match(r"^[0-9a-f]+ <([^>]+)>:$", line)
        if m:
            cur = m.group(1)
            funcs[cur] = []
            continue
        m = re.match(r"^\s+[0-9a-f]+:\s+(\S+)\s*([^;@]*)", line)
        if m and cur is not None:
            funcs[cur].append((m.group(1), m.group(2).strip()))
    return funcs


def bad_instructions(insns):
    return sorted({f"{op} {args}".strip() for op, args in insns if BAD_INSN.match(op)})


def check_core(lib):
    problems = []
    member = None
    for line in run([NM, "-u", lib]).splitlines():
        if line.endswith(":"):
            member = line[:-1]
            continue
        sym = line.split()[-1] if line.strip() else ""
        if sym and FORBIDDEN.match(sym):
            problems.append(f"{member}: references {sym}")
    funcs = disassemble(lib)
    for name, insns in funcs.items():
        for insn in bad_instructions(insns):
            problems.append(f"{name}: {insn}")
    if problems:
        print(f"check_image: {lib}: division or floating point in the core:", file=sys.stderr)
        print("\n".join("  " + p for p in problems), file=sys.stderr)
        return 1
    print(f"check_image: core: {len(funcs)} functions, no division or floating-point helper or instruction")
    return 0


def check_tick(image, root=ROOT):
    funcs = disassemble(image)
    if root not in funcs:
        print(f"check_image: {image}: no {root}", file=sys.stderr)
        return 1
    seen, todo, problems = set(), [root], []
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        if FORBIDDEN.match(name):
            problems.append(f"{name} is reachable from {root}")
        insns = funcs.get(name, [])
        for insn in bad_instructions(insns):
            problems.append(f"{name}: {insn}")
        for op, args in insns:
            if BRANCH.match(op):
                m = re.search(r"<([^>+]+)(?:\+0x[0-9a-f]+)?>", args)
                if m and m.group(1) != name:
                    todo.append(m.group(1))
                elif op == "blx" and not m:
                    problems.append(f"{name}: indirect call '{op} {args}' (callee cannot be checked)")
            elif op == "bx" and args != "lr":
                problems.append(f"{name}: indirect branch '{op} {args}' (callee cannot be checked)")
    if problems:
        print(f"check_image: {image}: the tick path is not division- and float-free:", file=sys.stderr)
        print("\n".join("  " + p for p in problems), file=sys.stderr)
        return 1
    print(f"check_image: tick path from {root}: {len(seen)} functions ({', '.join(sorted(seen))}), "
          "no division or floating-point helper or instruction")
    return 0


def main(argv):
    if len(argv) < 3 or argv[1] not in ("core", "tick"):
        print(__doc__, file=sys.stderr)
        return 2
    if argv[1] == "core":
        return check_core(argv[2])
    return check_tick(argv[2], argv[3] if len(argv) > 3 else ROOT)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
