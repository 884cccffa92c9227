#!/usr/bin/env python3
"""Generate the C and Python views of common/interface.toml (stdlib only).

Writes firmware/generated/piezo_interface.h, firmware/generated/piezo_interface.c
and host/piezoctl/interface.py. ``--check`` writes nothing and exits 1 when any
of them differs from what the definition generates.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import tomllib
import zlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
SRC = ROOT / "common" / "interface.toml"
OUT_H = ROOT / "firmware" / "generated" / "piezo_interface.h"
OUT_C = ROOT / "firmware" / "generated" / "piezo_interface.c"
OUT_PY = ROOT / "host" / "piezoctl" / "interface.py"

CTYPES = {"uint16": "uint16_t", "int16": "int16_t", "uint32": "uint32_t", "int32": "int32_t"}
SIZES = {"uint16": 2, "int16": 2, "uint32": 4, "int32": 4, "bytes": 1}
REGS = {"uint16": 1, "int16": 1, "uint32": 2, "int32": 2}


def canonical_crc(defn: dict) -> int:
    """CRC-32 of the definition's canonical JSON (sorted keys, no spaces)."""
    text = json.dumps(defn, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return zlib.crc32(text.encode("ascii")) & 0xFFFFFFFF


def gauss_lut(spec: dict, fmt: dict) -> list[int]:
    """exp(-z^2/2) samples with the project rounding rule floor(x*2^f + 0.5)."""
    one = 1 << fmt["frac"]
    top = (1 << (fmt["bits"] - 1)) - 1
    n, zmax = spec["n"], spec["zmax"]
    return [min(top, math.floor(math.exp(-0.5 * (i * zmax / (n - 1)) ** 2) * one + 0.5))
            for i in range(n)]


def sine_lut(spec: dict, fmt: dict) -> list[int]:
    """One period of sin, the last sample repeating the first, rounded and clamped."""
    one = 1 << fmt["frac"]
    top = (1 << (fmt["bits"] - 1)) - 1
    n = spec["n"]
    return [max(-top - 1, min(top, math.floor(math.sin(2.0 * math.pi * (i % (n - 1)) / (n - 1)) * one + 0.5)))
            for i in range(n)]


def check_registers(name: str, regs: list[dict]) -> None:
    used: dict[int, str] = {}
    for r in regs:
        for a in range(r["address"], r["address"] + REGS[r["type"]] * r.get("count", 1)):
            if a in used:
                raise SystemExit(f"gen-interface: {name} register {a:#06x} of {r['name']} "
                                 f"overlaps {used[a]}")
            used[a] = r["name"]


def check_enums(d: dict) -> None:
    """Every enumeration numbers its values 0..n-1 in order; every register's
    ``enum`` names one."""
    for name, e in d["enums"].items():
        if [v[1] for v in e["values"]] != list(range(len(e["values"]))):
            raise SystemExit(f"gen-interface: enum {name}: values must be 0..n-1 in order")
    for space in ("input", "holding"):
        for r in d["modbus"][space]:
            if "enum" in r and r["enum"] not in d["enums"]:
                raise SystemExit(f"gen-interface: {space} register {r['name']}: no enum {r['enum']!r}")


def param_block(d: dict) -> tuple[int, int, list[dict]]:
    """The configuration registers (access "c"): first address, words, the
    registers in address order. They must be one contiguous block, each with a unit."""
    regs = sorted((r for r in d["modbus"]["holding"] if r.get("access") == "c"), key=lambda r: r["address"])
    addr = regs[0]["address"]
    for r in regs:
        if r["address"] != addr:
            raise SystemExit(f"gen-interface: configuration register {r['name']} leaves a gap before it")
        if "unit" not in r:
            raise SystemExit(f"gen-interface: configuration register {r['name']} has no unit")
        addr += REGS[r["type"]] * r.get("count", 1)
    return regs[0]["address"], addr - regs[0]["address"], regs


def field_bytes(f: dict) -> int:
    return SIZES[f["type"]] * f.get("count", 1)


def header_offsets(fields: list[dict]) -> list[tuple[dict, int]]:
    out, off = [], 0
    for f in fields:
        out.append((f, off))
        off += field_bytes(f)
    return out


def c_int(v: int) -> str:
    """An int32 literal (INT32_MIN cannot be written as a negated constant)."""
    return "(-2147483647 - 1)" if v == -2147483648 else str(v)


def section_specs(t: dict) -> tuple[list[dict], list[tuple[str, int, int]]]:
    """Every section's id, type, kinds mask and ranges; the per-element fields."""
    specs, fields = [], []
    for name, v in t["sections"].items():
        kinds = 0
        for k in v["kinds"]:
            kinds |= 1 << t["kinds"][k]
        lim = {"int16": (-32768, 32767), "int32": (-2147483648, 2147483647)}[v["type"]]
        if ("range" in v) == ("fields" in v):
            raise SystemExit(f"gen-interface: section {name}: give either range or fields")
        if "fields" in v:
            first = len(fields)
            for f in v["fields"]:
                fields.append((f[0], int(f[1]), int(f[2])))
            lo, hi, nf = lim[0], lim[1], len(v["fields"])
        else:
            lo, hi = (int(x) for x in v["range"])
            first, nf = 0, 0
        for a, b in [(lo, hi)] + [(f[1], f[2]) for f in fields[first:first + nf] if nf]:
            if not (lim[0] <= a <= b <= lim[1]):
                raise SystemExit(f"gen-interface: section {name}: range [{a}, {b}] not inside {v['type']}")
        specs.append({"name": name, "type": v["type"], "kinds": kinds, "min": lo, "max": hi,
                      "n_fields": nf, "first_field": first})
    return specs, fields


def gen_c(d: dict, crc: int) -> tuple[str, str]:
    m = d["meta"]
    h = ["/* Generated by tools/gen-interface from common/interface.toml: do not edit. */",
         "#ifndef PIEZO_INTERFACE_H", "#define PIEZO_INTERFACE_H", "", "#include <stdint.h>", "",
         f"#define PIEZO_LAYOUT_VERSION {m['layout_version']}u",
         f"#define PIEZO_INTERFACE_CRC32 0x{crc:08X}u", ""]
    h.append("/* Q formats: value = integer / 2^FRAC */")
    for name, q in d["qformats"].items():
        h.append(f"#define PIEZO_{name.upper()}_BITS {q['bits']}  /* {q['doc']} */")
        h.append(f"#define PIEZO_{name.upper()}_FRAC {q['frac']}")
    h.append("")
    g = d["luts"]["gauss"]
    h += [f"/* {g['doc']} */",
          f"#define PIEZO_GAUSS_LUT_N {g['n']}",
          f"#define PIEZO_GAUSS_ZMAX_Q16 {int(g['zmax'] * 65536)}L",
          f"extern const int16_t piezo_gauss_lut_q15[PIEZO_GAUSS_LUT_N];", ""]
    sn = d["luts"]["sine"]
    h += [f"/* {sn['doc']} */",
          f"#define PIEZO_SINE_LUT_N {sn['n']}",
          f"extern const int16_t piezo_sine_lut_q15[PIEZO_SINE_LUT_N];", ""]
    t = d["table"]
    h += [f"/* Table image: {t['doc']} */",
          f"#define PIEZO_TABLE_MAGIC 0x{t['magic']:08X}u",
          f"#define PIEZO_TABLE_MAX_BYTES {t['max_bytes']}u"]
    for k, v in t["kinds"].items():
        h.append(f"#define PIEZO_TABLE_KIND_{k.upper()} {v}u")
    hdr = header_offsets(t["header"])
    for f, off in hdr:
        h.append(f"#define PIEZO_TABLE_HDR_{f['name'].upper()}_OFFSET {off}u  /* {f['type']}"
                 + (f" x{f['count']}" if "count" in f else "") + " */")
    h.append(f"#define PIEZO_TABLE_HDR_BYTES {sum(field_bytes(f) for f in t['header'])}u")
    for k, v in t["section_types"].items():
        h.append(f"#define PIEZO_SECTION_TYPE_{k.upper()} {v}u")
    for k, v in t["sections"].items():
        h.append(f"#define PIEZO_SECTION_{k.upper()} {v['id']}u  /* {v['type']}: {v['doc']} */")
    for k, v in t["reasons"].items():
        h.append(f"#define PIEZO_TABLE_REASON_{k.upper()} {v}u")
    reasons = sorted(t["reasons"].items(), key=lambda kv: kv[1])
    if [v for _k, v in reasons] != list(range(len(reasons))):
        raise SystemExit("gen-interface: table reasons must be 0..n-1")
    h += [f"#define PIEZO_TABLE_REASON_N {len(reasons)}u",
          "extern const char *const piezo_table_reason_names[PIEZO_TABLE_REASON_N];"]
    specs, fields = section_specs(t)
    h += ["",
          "/* Section specifications: id, element type, the kinds that need it (bit",
          " * 1 << kind), and the range of every element: one range for all, or one",
          " * per element (n_fields > 0: the section has exactly n_fields elements,",
          " * their ranges piezo_section_fields[first_field ...]). */",
          "typedef struct {",
          "    int32_t min;",
          "    int32_t max;",
          "} piezo_range_t;",
          "typedef struct {",
          "    uint16_t id;",
          "    uint16_t type;",
          "    uint32_t kinds;",
          "    piezo_range_t range;",
          "    uint16_t n_fields;",
          "    uint16_t first_field;",
          "} piezo_section_spec_t;",
          f"#define PIEZO_SECTION_SPEC_N {len(specs)}u",
          f"#define PIEZO_SECTION_FIELD_N {len(fields)}u",
          "extern const piezo_section_spec_t piezo_section_specs[PIEZO_SECTION_SPEC_N];",
          "extern const piezo_range_t piezo_section_fields[PIEZO_SECTION_FIELD_N];"]
    h.append("")
    mb = d["modbus"]
    h += ["/* Modbus register map (0-based addresses; 32-bit values high word first) */",
          f"#define PIEZO_MODBUS_UNIT_ID {mb['unit_id']}u",
          f"#define PIEZO_MODBUS_MAX_WRITE_REGISTERS {mb['max_write_registers']}u",
          f"#define PIEZO_MODBUS_MAX_READ_REGISTERS {mb['max_read_registers']}u",
          ]
    for k, v in mb["unlock"].items():
        h.append(f"#define PIEZO_UNLOCK_{k.upper()} {v:#x}u" if k.endswith("key")
                 else f"#define PIEZO_UNLOCK_{k.upper()} {v}u")
    for k, v in mb["tcp"].items():
        h.append(f"#define PIEZO_TCP_{k.upper()} {v}u")
    for space in ("input", "holding"):
        for r in mb[space]:
            base = f"PIEZO_{space.upper()}_{r['name'].upper()}"
            h.append(f"#define {base} 0x{r['address']:04X}u  /* {r['type']}"
                     + (f" x{r['count']}" if "count" in r else "") + " */")
            if "count" in r:
                h.append(f"#define {base}_COUNT {r['count']}u")
    h += ["",
          "/* Register descriptors, sorted by address: words per element (1 or 2),",
          " * elements, and flags. */",
          "#define PIEZO_REG_SIGNED 1u    /* int16 / int32 */",
          "#define PIEZO_REG_READONLY 2u  /* holding register that refuses writes */",
          "#define PIEZO_REG_CONFIG 4u    /* writes need the unlock key and a disarmed unit */",
          "typedef struct {",
          "    uint16_t addr;",
          "    uint8_t words;",
          "    uint8_t flags;",
          "    uint16_t count;",
          "    uint16_t id;",
          "} piezo_reg_desc_t;"]
    for space, short in (("input", "IREG"), ("holding", "HREG")):
        regs = sorted(mb[space], key=lambda r: r["address"])
        h.append(f"enum piezo_{space}_reg_id {{")
        for r in regs:
            h.append(f"    PIEZO_{short}_{r['name'].upper()},")
        h += [f"    PIEZO_{short}_N", "};",
              f"extern const piezo_reg_desc_t piezo_{space}_regs[PIEZO_{short}_N];"]
    h += ["", "/* Enumerations: the values of the registers that name a choice */"]
    for name, e in d["enums"].items():
        h.append(f"/* {e['doc']} */")
        h.append(f"enum piezo_enum_{name} {{")
        for vname, v, vdoc in e["values"]:
            h.append(f"    {e['c_prefix']}_{vname.upper()} = {v},  /* {vdoc} */")
        h += [f"    {e['c_prefix']}_N = {len(e['values'])}", "};"]
    pr = d["params"]
    first, words, _regs = param_block(d)
    h += ["", f"/* Controller parameters in flash: {pr['doc']} */",
          f"#define PIEZO_PARAMS_MAGIC 0x{pr['magic']:08X}u",
          f"#define PIEZO_PARAMS_SLOT_BYTES {pr['slot_bytes']}u",
          f"#define PIEZO_PARAMS_MIN_SLOT_BYTES {pr['min_slot_bytes']}u  /* the block's words only */",
          f"#define PIEZO_PARAMS_FIRST 0x{first:04X}u  /* the configuration block */",
          f"#define PIEZO_PARAMS_WORDS {words}u"]
    reasons = sorted(pr["reasons"].items(), key=lambda kv: kv[1])
    if [v for _k, v in reasons] != list(range(len(reasons))):
        raise SystemExit("gen-interface: params reasons must be 0..n-1")
    for k, v in reasons:
        h.append(f"#define PIEZO_PARAMS_REASON_{k.upper()} {v}u")
    h.append(f"#define PIEZO_PARAMS_REASON_N {len(reasons)}u")
    h.append("")
    for k, v in d["faults"].items():
        h.append(f"#define PIEZO_FAULT_{k.upper()} (1u << {v})")
    h += ["", "#endif /* PIEZO_INTERFACE_H */", ""]

    lut = gauss_lut(g, d["qformats"][g["format"]])
    c = ["/* Generated by tools/gen-interface from common/interface.toml: do not edit. */",
         '#include "piezo_interface.h"', ""]
    for space, short in (("input", "IREG"), ("holding", "HREG")):
        regs = sorted(mb[space], key=lambda r: r["address"])
        c.append(f"const piezo_reg_desc_t piezo_{space}_regs[PIEZO_{short}_N] = {{")
        for r in regs:
            flags = []
            if r["type"].startswith("int"):
                flags.append("PIEZO_REG_SIGNED")
            if r.get("access") == "r":
                flags.append("PIEZO_REG_READONLY")
            if r.get("access") == "c":
                flags.append("PIEZO_REG_CONFIG")
            c.append(f"    {{0x{r['address']:04X}u, {REGS[r['type']]}u, {' | '.join(flags) or '0u'}, "
                     f"{r.get('count', 1)}u, PIEZO_{short}_{r['name'].upper()}}},")
        c += ["};", ""]
    c.append("const char *const piezo_table_reason_names[PIEZO_TABLE_REASON_N] = {")
    for k, _v in sorted(t["reasons"].items(), key=lambda kv: kv[1]):
        c.append(f'    "{k}",')
    c += ["};", ""]
    specs, fields = section_specs(t)
    c.append("const piezo_section_spec_t piezo_section_specs[PIEZO_SECTION_SPEC_N] = {")
    for sp in specs:
        c.append(f"    {{PIEZO_SECTION_{sp['name'].upper()}, PIEZO_SECTION_TYPE_{sp['type'].upper()}, "
                 f"0x{sp['kinds']:08X}u, {{{c_int(sp['min'])}, {c_int(sp['max'])}}}, {sp['n_fields']}u, "
                 f"{sp['first_field']}u}},")
    c += ["};", "", "const piezo_range_t piezo_section_fields[PIEZO_SECTION_FIELD_N] = {"]
    for name, lo, hi in fields:
        c.append(f"    {{{c_int(lo)}, {c_int(hi)}}},  /* {name} */")
    c += ["};", ""]
    c += [
         "const int16_t piezo_gauss_lut_q15[PIEZO_GAUSS_LUT_N] = {"]
    for i in range(0, len(lut), 12):
        c.append("    " + ", ".join(str(v) for v in lut[i:i + 12]) + ",")
    c += ["};", ""]
    sine = sine_lut(d["luts"]["sine"], d["qformats"][d["luts"]["sine"]["format"]])
    c.append("const int16_t piezo_sine_lut_q15[PIEZO_SINE_LUT_N] = {")
    for i in range(0, len(sine), 12):
        c.append("    " + ", ".join(str(v) for v in sine[i:i + 12]) + ",")
    c += ["};", ""]
    return "\n".join(h), "\n".join(c)


def gen_py(d: dict, crc: int) -> str:
    g = d["luts"]["gauss"]
    hdr = header_offsets(d["table"]["header"])
    lines = [
        '"""Generated by tools/gen-interface from common/interface.toml: do not edit."""',
        "", "# fmt: off",
        f"LAYOUT_VERSION = {d['meta']['layout_version']}",
        f"INTERFACE_CRC32 = 0x{crc:08X}",
        f"QFORMATS = {json.dumps({k: {'bits': v['bits'], 'frac': v['frac']} for k, v in d['qformats'].items()})}",
        f"GAUSS_LUT_N = {g['n']}",
        f"GAUSS_ZMAX = {g['zmax']!r}",
        f"GAUSS_LUT_Q15 = {gauss_lut(g, d['qformats'][g['format']])}",
        f"SINE_LUT_N = {d['luts']['sine']['n']}",
        f"SINE_LUT_Q15 = {sine_lut(d['luts']['sine'], d['qformats'][d['luts']['sine']['format']])}",
        f"TABLE_MAGIC = 0x{d['table']['magic']:08X}",
        f"TABLE_MAX_BYTES = {d['table']['max_bytes']}",
        f"TABLE_KINDS = {json.dumps(d['table']['kinds'])}",
        "# (name, type, byte offset, count) of the table header fields, little-endian",
        f"TABLE_HEADER = {[(f['name'], f['type'], off, f.get('count', 1)) for f, off in hdr]!r}",
        f"TABLE_HEADER_BYTES = {sum(field_bytes(f) for f in d['table']['header'])}",
        f"SECTION_TYPES = {json.dumps(d['table']['section_types'])}",
        f"TABLE_REASONS = {json.dumps(d['table']['reasons'])}",
        "# section name -> (id, type, kinds)",
        f"TABLE_SECTIONS = {({k: (v['id'], v['type'], v['kinds']) for k, v in d['table']['sections'].items()})!r}",
        f"MODBUS_UNIT_ID = {d['modbus']['unit_id']}",
        f"MODBUS_MAX_WRITE_REGISTERS = {d['modbus']['max_write_registers']}",
        f"MODBUS_MAX_READ_REGISTERS = {d['modbus']['max_read_registers']}",
        f"MODBUS_UNLOCK = {json.dumps(d['modbus']['unlock'])}",
        f"MODBUS_TCP = {json.dumps(d['modbus']['tcp'])}",
        "# section name -> [(field, min, max)] per element, or [(None, min, max)] for every element",
        f"TABLE_SECTION_RANGES = {({k: ([tuple(f) for f in v['fields']] if 'fields' in v else [(None, *v['range'])]) for k, v in d['table']['sections'].items()})!r}",
        "# name -> (address, type, count)",
    ]
    for space in ("input", "holding"):
        regs = {r["name"]: (r["address"], r["type"], r.get("count", 1)) for r in d["modbus"][space]}
        lines.append(f"{space.upper()}_REGISTERS = {regs!r}")
    acc = {r["name"]: r["access"] for r in d["modbus"]["holding"] if "access" in r}
    lines.append("# holding registers that are read-only (r) or configuration (c)")
    lines.append(f"HOLDING_ACCESS = {acc!r}")
    lines.append(f"FAULT_BITS = {json.dumps(d['faults'])}")
    lines.append("# enumeration -> {value name: number}")
    lines.append(f"ENUMS = {({k: {v[0]: v[1] for v in e['values']} for k, e in d['enums'].items()})!r}")
    lines.append("# enumeration -> {value name: description}")
    lines.append(f"ENUM_DOCS = {({k: {v[0]: v[2] for v in e['values']} for k, e in d['enums'].items()})!r}")
    lines.append("# register name -> enumeration it holds")
    lines.append(f"REGISTER_ENUMS = {({r['name']: r['enum'] for sp in ('input', 'holding') for r in d['modbus'][sp] if 'enum' in r})!r}")
    pr = d["params"]
    first, words, regs = param_block(d)
    lines.append(f"PARAMS_MAGIC = 0x{pr['magic']:08X}")
    lines.append(f"PARAMS_SLOT_BYTES = {pr['slot_bytes']}")
    lines.append(f"PARAMS_MIN_SLOT_BYTES = {pr['min_slot_bytes']}")
    lines.append(f"PARAMS_FIRST = 0x{first:04X}")
    lines.append(f"PARAMS_WORDS = {words}")
    lines.append(f"PARAMS_REASONS = {json.dumps(pr['reasons'])}")
    lines.append("# the controller parameters: (name, address, type, count, unit, doc), in address order")
    lines.append(f"PARAMS = {[(r['name'], r['address'], r['type'], r.get('count', 1), r['unit'], r.get('doc', '')) for r in regs]!r}")
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="tools/gen-interface", description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="fail if generated files are stale")
    args = ap.parse_args(argv)
    with open(SRC, "rb") as fh:
        d = tomllib.load(fh)
    for space in ("input", "holding"):
        check_registers(space, d["modbus"][space])
    check_enums(d)
    ids = [v["id"] for v in d["table"]["sections"].values()]
    if len(set(ids)) != len(ids):
        raise SystemExit("gen-interface: duplicate table section id")
    crc = canonical_crc(d)
    h, c = gen_c(d, crc)
    outputs = {OUT_H: h, OUT_C: c, OUT_PY: gen_py(d, crc)}
    stale = [p for p, text in outputs.items()
             if not p.exists() or p.read_text(encoding="ascii") != text]
    if args.check:
        for p in stale:
            print(f"gen-interface: stale: {p.relative_to(ROOT)} (run tools/gen-interface)")
        if not stale:
            print(f"gen-interface: generated files match the definition "
                  f"(layout {d['meta']['layout_version']}, crc 0x{crc:08X})")
        return 1 if stale else 0
    for p in stale:
        p.write_text(outputs[p], encoding="ascii")
        print(f"gen-interface: wrote {p.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
