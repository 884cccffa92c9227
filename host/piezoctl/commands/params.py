"""``piezoctl params get|set|save|load|defaults --port PORT``: controller parameters.

The parameters are the controller's configuration registers
(``common/interface.toml``, ``access = "c"``): PID gains and output limits,
the drive clamp and slew limit, the notch, sensor plausibility, preview, the
input shaper, the cross-coupling bypass. Each is shown and set in the
physical unit the interface gives it (drive levels in V, slew in V/tick,
sensor jumps in um/tick, gains as plain numbers), converted to the register's
Q format with the project's rounding rule floor(x 2^f + 0.5); the value the
controller holds after quantization is what is reported.

``get [NAME ...]``: values, units, descriptions, and where they came from
(defaults, flash record N, changed since). ``set NAME=VALUE ...`` (or
``--from FILE.json``, the output of ``get --json``) writes them all in one
request: the controller applies all or nothing, only while disarmed.
``save`` writes the running parameters to flash (the inactive slot, then the
flip), with the wave loaded in the generator and the learned feedforward
played with it (they belong together: a correction is learned for one wave
and one configuration), where the controller's slot has room for them
(``state.wave``: ``saved``, or ``left_out`` on a target without room);
``load`` reads the saved ones back, ``defaults`` restores the target's
built-in parameters (flash and wave unchanged). The controller loads the
saved record at boot, the wave not started: ``piezoctl wave --saved`` starts
it (docs/operate.md).
"""

from __future__ import annotations

import json
import math

from ..errors import CliError, ControllerRefused
from ._options import add_output, add_port, emit

SUFFIX_FRAC = {"_q24": 24, "_q15": 15, "_q13": 13}
TYPE_RANGE = {"int16": (-2**15, 2**15 - 1), "uint16": (0, 2**16 - 1),
              "int32": (-2**31, 2**31 - 1), "uint32": (0, 2**32 - 1)}


class Param:
    """One controller parameter: its register, unit and the conversion
    between the register's integers and physical values.

    Parameters
    ----------
    register : str
        Register name in the interface (``pid_kp_q24``); the user-facing
        name drops the Q suffix (``pid_kp``).
    typ : str
        Register type (int16, uint16, int32).
    count : int
        Elements (3 for the shaper taps).
    unit : str
        ``V`` a drive level, ``V/tick`` a drive change per tick,
        ``um/tick`` a position change per tick, ``1``, ``1/tick``, ``tick``
        plain numbers (scaled by the Q format), ``bool``, ``count``.
    doc : str
        Description from the interface definition.
    scale : piezoctl.tables.from_model.Scale
        The controller's drive and position ranges.
    """

    def __init__(self, register: str, typ: str, count: int, unit: str, doc: str, scale):
        self.register, self.typ, self.count, self.unit, self.doc = register, typ, count, unit, doc
        suffix = register[-4:]
        self.frac = SUFFIX_FRAC.get(suffix, 0)
        self.name = register[:-4] if suffix in SUFFIX_FRAC else register
        sc = scale
        # physical value = raw * gain + offset
        if unit == "V":
            span = sc.drive_max_v - sc.drive_min_v
            self.gain, self.offset = span / 2 / 32768.0, sc.drive_min_v + span / 2
        elif unit == "V/tick":
            self.gain, self.offset = (sc.drive_max_v - sc.drive_min_v) / 2 / 32768.0, 0.0
        elif unit == "um/tick":
            self.gain, self.offset = sc.p_half / 32768.0, 0.0
        else:
            self.gain, self.offset = 2.0 ** -self.frac, 0.0

    @property
    def integer(self) -> bool:
        return self.frac == 0 and self.unit in ("bool", "count", "tick")

    def to_physical(self, raw):
        """Register value(s) to the physical value(s)."""
        if isinstance(raw, list):
            return [self.to_physical(r) for r in raw]
        return int(raw) if self.integer else raw * self.gain + self.offset

    def from_physical(self, x: float) -> int:
        """A physical value to the register's integer (rounding rule
        floor(x / gain + 0.5)); CliError when it does not fit the register."""
        if not math.isfinite(x):
            raise CliError(f"{self.name}: {x} is not a number")
        raw = math.floor((x - self.offset) / self.gain + 0.5)
        lo, hi = TYPE_RANGE[self.typ]
        if not lo <= raw <= hi:
            raise CliError(f"{self.name}={x:g} {self.unit}: outside what the register holds "
                           f"[{self.to_physical(lo):g}, {self.to_physical(hi):g}] {self.unit}; nothing changed")
        return raw

    def parse(self, text: str):
        """``VALUE`` (or ``V1,V2,V3`` for an array) from the command line to raw integer(s)."""
        parts = text.split(",")
        if len(parts) != self.count:
            raise CliError(f"{self.name}: want {self.count} comma-separated value(s), got {text!r}")
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise CliError(f"{self.name}: {text!r} is not a number") from None
        if self.integer and any(v != int(v) for v in vals):
            raise CliError(f"{self.name}: want an integer, got {text!r}")
        raws = [self.from_physical(v) for v in vals]
        return raws if self.count > 1 else raws[0]


def param_table(scale) -> dict:
    """User-facing name -> :class:`Param` for every controller parameter (interface order)."""
    from .. import interface
    out = {}
    for register, _addr, typ, count, unit, doc in interface.PARAMS:
        p = Param(register, typ, count, unit, doc, scale)
        out[p.name] = p
    return out


def _lookup(table: dict, name: str) -> "Param":
    for p in table.values():
        if name in (p.name, p.register):
            return p
    raise CliError(f"unknown parameter {name!r}; known: {', '.join(table)}")


def add_parser(sub) -> None:
    p = sub.add_parser("params", help="controller parameters: get, set, save to flash, load, defaults",
                       description=__doc__.splitlines()[0])
    psub = p.add_subparsers(dest="params_command", metavar="SUBCOMMAND", required=True)
    g = psub.add_parser("get", help="parameters in physical units, with where they came from")
    g.add_argument("names", nargs="*", metavar="NAME", help="only these (default: all)")
    s = psub.add_parser("set", help="set parameters (disarmed unit; all or nothing)")
    s.add_argument("assignments", nargs="*", metavar="NAME=VALUE", help="e.g. pid_kp=0.4 limit_max_step=0.05")
    s.add_argument("--from", dest="from_file", metavar="FILE.json", help="values from a 'params get --json' file")
    psub.add_parser("save", help="write the running parameters to flash (A/B, CRC)")
    psub.add_parser("load", help="replace the running parameters by the ones saved in flash")
    psub.add_parser("defaults", help="replace the running parameters by the built-in defaults (flash unchanged)")
    for sp in psub.choices.values():
        add_port(sp)
        add_output(sp)
        sp.set_defaults(func=run)


def _snapshot(ctl, table: dict, names=None) -> dict:
    raw = ctl.read_params()
    sel = [_lookup(table, n) for n in names] if names else list(table.values())
    return {p.name: {"value": p.to_physical(raw[p.register]), "unit": p.unit, "raw": raw[p.register],
                     "register": p.register, "doc": p.doc} for p in sel}


def _fmt(v) -> str:
    if isinstance(v, list):
        return ",".join(_fmt(x) for x in v)
    return str(v) if isinstance(v, int) else f"{v:.6g}"


def _lines(params: dict, state: dict) -> list[str]:
    src = {"defaults": "built-in defaults", "flash": f"flash record {state['seq']}",
           "changed": "changed since the last load or save (not saved)"}[state["source"]]
    out = [f"  {n:18s} {_fmt(v['value']):>24s} {v['unit']:8s} {v['doc']}" for n, v in params.items()]
    out.append(f"running parameters: {src}")
    if state.get("wave") == "saved":
        out.append("the flash record holds the wave and its learned feedforward (piezoctl wave --saved plays them)")
    if state["ignored"] != "ok":
        out.append(f"note: a stored record was ignored at boot: {state['ignored']}")
    return out


def run(args) -> int:
    from ..device import connect
    ctl = connect(args.port)
    table = param_table(ctl.scale)
    cmd = args.params_command
    if cmd == "get":
        params = _snapshot(ctl, table, args.names)
        state = ctl.params_state()
        emit(args, {"port": args.port, "params": params, "state": state}, _lines(params, state))
        return 0
    if cmd == "set":
        values = {}
        if args.from_file:
            try:
                with open(args.from_file, encoding="utf-8") as fh:
                    doc = json.load(fh)
                items = doc.get("params", doc)
                for name, v in items.items():
                    val = v["value"] if isinstance(v, dict) else v
                    p = _lookup(table, name)
                    txt = ",".join(str(x) for x in val) if isinstance(val, list) else str(val)
                    values[p.register] = p.parse(txt)
            except OSError as exc:
                raise CliError(f"{args.from_file}: {exc.strerror}") from None
            except (ValueError, AttributeError, KeyError, TypeError) as exc:
                raise CliError(f"{args.from_file}: not a parameter file ({exc})") from None
        for a in args.assignments:
            if "=" not in a:
                raise CliError(f"{a!r}: want NAME=VALUE")
            name, text = a.split("=", 1)
            p = _lookup(table, name.strip())
            values[p.register] = p.parse(text.strip())
        if not values:
            raise CliError("nothing to set: give NAME=VALUE ... or --from FILE.json")
        ctl.write_params(values)
        names = [n for n, p in table.items() if p.register in values]
        params = _snapshot(ctl, table, names)
        state = ctl.params_state()
        emit(args, {"port": args.port, "params": params, "state": state},
             _lines(params, state) + ["(piezoctl params save keeps them over a restart)"])
        return 0
    reason = ctl.params_command(cmd)
    state = ctl.params_state()
    if reason != "ok":
        help_ = {"none_stored": "nothing saved yet", "locked": "the unlock key was refused",
                 "armed": "parameters change only while disarmed",
                 "storage_failed": "the flash did not take it; the saved parameters are unchanged",
                 "out_of_range": "the saved record holds a value the controller refuses",
                 "bad_layout": "the saved record is of another interface definition"}.get(reason, "")
        raise ControllerRefused(f"params {cmd} refused by the controller: {reason}"
                                + (f" ({help_})" if help_ else "") + "; nothing changed")
    what = {"save": f"saved to flash as record {state['seq']}", "load": f"loaded flash record {state['seq']}",
            "defaults": "built-in defaults restored (flash and wave unchanged)"}[cmd]
    if cmd == "save":
        what += {"saved": ", with the wave and its learned feedforward",
                 "left_out": "; the wave and its learned feedforward were left out (this controller's "
                             "slot holds the parameters only)"}.get(state["wave"], "")
    elif cmd == "load" and state["wave"] == "saved":
        what += ", with the wave and its learned feedforward (not started: piezoctl wave --saved)"
    emit(args, {"port": args.port, "result": reason, "state": state}, f"params {cmd}: {what}")
    return 0
