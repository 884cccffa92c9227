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
    check_image.py ram IMAGE.elf ROOT...
                                    the linked image: every function reachable
                                    from each ROOT runs from RAM (0x20000000..)
                                    and loads no literal that is the address
                                    of a symbol in the flash (the code that must run while a flash
                                    sector erases: the tick, the flash driver's
                                    waits; docs/target-cortex-m4.md)

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


def disassemble(path, addrs=None):
    """{function: [(mnemonic, operands)]} from objdump -d; addrs, when given,
    gets {function: address}."""
    funcs, cur = {}, None
    for line in run([OBJDUMP, "-d", "--no-show-raw-insn", path]).splitlines():
        m = re.match(r"^([0-9a-f]+) <([^>]+)>:$", line)
        if m:
            cur = m.group(2)
            funcs[cur] = []
            if addrs is not None:
                addrs[cur] = int(m.group(1), 16)
            continue
        m = re.match(r"^\s*[0-9a-f]+:\s+(\S+)\s*([^;@]*)", line)  # RAM addresses have 8 digits, no indent
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


FLASH = (0x08000000, 0x08100000)
RAM = (0x20000000, 0x20020000)


def reachable(funcs, root):
    """Functions reached from root by direct calls and branches."""
    seen, todo = set(), [root]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for op, args in funcs.get(name, []):
            if BRANCH.match(op):
                m = re.search(r"<([^>+]+)(?:\+0x[0-9a-f]+)?>", args)
                if m and m.group(1) != name:
                    todo.append(m.group(1))
    return seen


def flash_symbols(image):
    """Addresses of the symbols that lie in the flash (Thumb bit cleared)."""
    out = set()
    for line in run([NM, image]).splitlines():
        parts = line.split()
        if len(parts) == 3:
            a = int(parts[0], 16) & ~1
            if FLASH[0] <= a < FLASH[1]:
                out.add(a)
    return out


def check_ram(image, roots):
    addrs = {}
    funcs = disassemble(image, addrs)
    in_flash = flash_symbols(image)
    problems, seen = [], set()
    for root in roots:
        if root not in funcs:
            problems.append(f"no {root}")
            continue
        seen |= reachable(funcs, root)
    for name in sorted(seen):
        a = addrs.get(name)
        if a is None or not RAM[0] <= a < RAM[1]:
            problems.append(f"{name} at {a:#010x} is not in RAM" if a is not None else f"{name}: no address")
        for op, args in funcs.get(name, []):
            if op == ".word":
                v = int(args.split()[0], 0)
                if (v & ~1) in in_flash:
                    problems.append(f"{name}: literal {v:#010x} is the address of a symbol in the flash")
    if problems:
        print(f"check_image: {image}: code that must run during a flash erase is not all in RAM:", file=sys.stderr)
        print("\n".join("  " + p for p in problems), file=sys.stderr)
        return 1
    print(f"check_image: RAM-resident from {', '.join(roots)}: {len(seen)} functions, no flash symbol's address in their literals")
    return 0


def main(argv):
    if len(argv) >= 4 and argv[1] == "ram":
        return check_ram(argv[2], argv[3:])
    if len(argv) < 3 or argv[1] not in ("core", "tick"):
        print(__doc__, file=sys.stderr)
        return 2
    if argv[1] == "core":
        return check_core(argv[2])
    return check_tick(argv[2], argv[3] if len(argv) > 3 else ROOT)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
