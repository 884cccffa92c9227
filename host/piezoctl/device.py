"""A controller seen through its register map (``common/interface.toml``).

:class:`Controller` wraps a transport (:func:`piezoctl.transport.open_port`)
and speaks in the map's terms: identity, status, modes, the wave generator,
the recorder, table upload/verify/commit/rollback. Values are decoded by the
types the interface definition gives (32-bit values high word first).
"""

from __future__ import annotations

import os
import struct
import time
import zlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

from . import interface
from .errors import CliError, ControllerRefused
from .tables.from_model import Scale
from .transport import open_port
from .transport.errors import ModbusExceptionError

__all__ = ["Controller", "DeviceError", "MODES", "SIGNALS", "WAVE_KINDS", "REC_TRIGGERS", "COMMANDS",
           "TABLE_COMMANDS", "PARAMS_COMMANDS", "REASON_NAMES", "PARAMS_REASON_NAMES", "KIND_NAMES",
           "freq_word", "connect"]

# The enumerations of common/interface.toml ([enums], generated): name -> number.
MODES = interface.ENUMS["mode"]
SIGNALS = interface.ENUMS["rec_signals"]
WAVE_KINDS = interface.ENUMS["wave_kind"]
REC_TRIGGERS = interface.ENUMS["rec_trigger"]
COMMANDS = interface.ENUMS["command"]
TABLE_COMMANDS = interface.ENUMS["table_command"]
PARAMS_COMMANDS = interface.ENUMS["params_command"]
MODE_NAMES = {v: k for k, v in MODES.items()}
REASON_NAMES = {v: k for k, v in interface.TABLE_REASONS.items()}
PARAMS_REASON_NAMES = {v: k for k, v in interface.PARAMS_REASONS.items()}
PARAMS_SOURCE_NAMES = {v: k for k, v in interface.ENUMS["params_source"].items()}
PARAMS_WAVE_NAMES = {v: k for k, v in interface.ENUMS["params_wave"].items()}
KIND_NAMES = {v: k for k, v in interface.TABLE_KINDS.items()}
FAULT_NAMES = {1 << v: k for k, v in interface.FAULT_BITS.items()}
WINDOW = interface.HOLDING_REGISTERS["table_window"][2]      # registers per table chunk
REC_WINDOW = interface.HOLDING_REGISTERS["rec_window"][2]
# wall time [s] without a single tick after which a wait on the controller's
# own clock gives up: the controller is not ticking (not: it ticks slowly)
STALL_S = 5.0


class DeviceError(ControllerRefused):
    """The controller refused or reported something the user must act on (exit 4)."""


KEY_ENV = "PIEZOCTL_UNLOCK_KEY"


def unlock_key(key: int | str | None = None) -> int:
    """The controller's unlock key: ``key``, else ``$PIEZOCTL_UNLOCK_KEY`` (8 hex
    digits), else sil-stage's documented development key
    (``interface.MODBUS_UNLOCK["default_sil_key"]``)."""
    if key is None:
        key = os.environ.get(KEY_ENV)
    if key is None:
        return interface.MODBUS_UNLOCK["default_sil_key"]
    if isinstance(key, str):
        s = key[2:] if key.lower().startswith("0x") else key
        if len(s) != 8 or any(c not in "0123456789abcdefABCDEF" for c in s) or int(s, 16) == 0:
            raise CliError(f"unlock key {key!r}: want 8 hex digits (32 bits), not 0")
        return int(s, 16)
    if not 0 < int(key) < 2**32:
        raise CliError("unlock key must be a nonzero 32-bit value")
    return int(key)


def freq_word(f_hz: float, tick_hz: float = 10000.0) -> int:
    """Phase increment of the wave generator for frequency ``f_hz`` [Hz]."""
    w = int(np.floor(f_hz / tick_hz * 2.0**32 + 0.5))
    if not 0 <= w < 2**32:
        raise ValueError(f"frequency {f_hz} Hz outside [0, {tick_hz}) Hz")
    return w


def _decode(block_start: int, words: list[int], regs: dict) -> dict:
    out = {}
    for name, (addr, typ, count) in regs.items():
        off = addr - block_start
        n = (2 if typ.endswith("32") else 1)
        if off < 0 or off + n * count > len(words) or count != 1:
            continue
        w = words[off:off + n]
        if n == 2:
            v = (w[0] << 16) | w[1]
            if typ == "int32" and v >= 2**31:
                v -= 2**32
        else:
            v = w[0]
            if typ == "int16" and v >= 2**15:
                v -= 2**16
        out[name] = v
    return out


def _block(regs: dict, lo: int, hi: int) -> dict:
    return {k: v for k, v in regs.items() if lo <= v[0] < hi}


def _u16(v: int) -> int:
    return int(v) & 0xFFFF


# name -> (address, type, count, unit, doc) of every controller parameter
PARAM_SPECS = {name: (addr, typ, count, unit, doc) for name, addr, typ, count, unit, doc in interface.PARAMS}

# What a table reason means for the user (refusals of commit and rollback).
TABLE_REASON_HELP = {
    "no_previous": "there is no previous table to go back to",
    "locked": "this session is not unlocked",
    "busy": "a table change is still waiting for the tick",
    "storage_failed": "the flash did not take it; the running table is unchanged",
    "wrong_stage": "the table was built for another stage's ranges",
    "wrong_axis": "the table was built for another axis",
    "not_owner": "another session's upload is in the staged bank",
    "nothing_staged": "nothing was uploaded",
    "bad_interface_crc": "built by a tool of another interface definition",
}


def _params_from_words(words: list[int]) -> dict:
    """Decode the configuration block's words (32-bit values high word first)."""
    out, i = {}, 0
    for name, (_addr, typ, count, _unit, _doc) in PARAM_SPECS.items():
        vals = []
        for _ in range(count):
            if typ.endswith("32"):
                v = (words[i] << 16) | words[i + 1]
                i += 2
                if typ == "int32" and v >= 2**31:
                    v -= 2**32
            else:
                v = words[i]
                i += 1
                if typ == "int16" and v >= 2**15:
                    v -= 2**16
            vals.append(v)
        out[name] = vals if count > 1 else vals[0]
    return out


def _params_to_words(values: dict) -> list[int]:
    """The configuration block's words for raw values by name (every parameter)."""
    words = []
    for name, (_addr, typ, count, _unit, _doc) in PARAM_SPECS.items():
        vals = values[name] if count > 1 else [values[name]]
        for v in vals:
            if typ.endswith("32"):
                v = int(v) & 0xFFFFFFFF
                words += [v >> 16, v & 0xFFFF]
            else:
                words.append(_u16(v))
    return words


@dataclass
class Identity:
    device_id: int
    fw_version: int
    layout_version: int
    interface_crc: int
    n_axes: int
    axis: int
    tick_hz: int
    scale: Scale
    rec_capacity: int


class Controller:
    """One axis of a controller.

    Parameters
    ----------
    client : RegisterClient
        An open transport.
    check : bool
        Refuse a controller whose layout version or interface CRC differs
        from this tool's (the table layout and register map would not agree).
    """

    def __init__(self, client, *, check: bool = True, key: int | str | None = None):
        self.client = client
        self.key = unlock_key(key)
        self.identity = self.read_identity()
        if check:
            if self.identity.device_id != 0x505A:
                raise DeviceError(f"{client.name}: not a piezoctl controller (device id {self.identity.device_id:#06x})")
            if (self.identity.layout_version != interface.LAYOUT_VERSION
                    or self.identity.interface_crc != interface.INTERFACE_CRC32):
                raise DeviceError(
                    f"{client.name}: interface mismatch: controller layout {self.identity.layout_version} "
                    f"crc {self.identity.interface_crc:#010x}, this tool layout {interface.LAYOUT_VERSION} "
                    f"crc {interface.INTERFACE_CRC32:#010x}: update the firmware or the tool")

    # ------------------------------------------------------------ reading
    def read_identity(self) -> Identity:
        regs = _block(interface.INPUT_REGISTERS, 0, 0x100)
        lo = min(a for a, _, _ in regs.values())
        hi = max(a + (2 if t.endswith("32") else 1) for a, t, _ in regs.values())
        d = _decode(lo, self.client.read_input(lo, hi - lo), regs)
        scale = Scale(d["drive_min_mv"] / 1e3, d["drive_max_mv"] / 1e3,
                      d["position_min_nm"] / 1e3, d["position_max_nm"] / 1e3)
        return Identity(d["device_id"], d["fw_version"], d["layout_version"], d["interface_crc"],
                        d["n_axes"], d["axis"], d["tick_hz"], scale, d["rec_capacity"])

    @property
    def scale(self) -> Scale:
        return self.identity.scale

    def status(self) -> dict:
        """Every status register, decoded; ``faults_names`` and ``table_result_name`` added."""
        regs = _block(interface.INPUT_REGISTERS, 0x100, 0x200)
        lo = min(a for a, _, _ in regs.values())
        hi = max(a + (2 if t.endswith("32") else 1) for a, t, _ in regs.values())
        d = _decode(lo, self.client.read_input(lo, hi - lo), regs)
        d["faults_names"] = [n for bit, n in FAULT_NAMES.items() if d["faults"] & bit]
        d["table_result_name"] = REASON_NAMES.get(d["table_result"], str(d["table_result"]))
        d["position_um"] = float(self.scale.position_from_fs(d["position_q15"] / 32768.0))
        d["drive_v"] = float(self.scale.drive_from_fs(d["drive_q15"] / 32768.0))
        return d

    # ------------------------------------------------------------ writing
    def _h(self, name: str) -> int:
        return interface.HOLDING_REGISTERS[name][0]

    def write(self, name: str, value: int) -> None:
        addr, typ, _ = interface.HOLDING_REGISTERS[name]
        if typ.endswith("32"):
            v = int(value) & 0xFFFFFFFF
            self.client.write_holding(addr, [v >> 16, v & 0xFFFF])
        else:
            self.client.write_holding(addr, [_u16(value)])

    def unlock(self) -> None:
        """Unlock this connection (its session) with the provisioned key.

        Raises
        ------
        DeviceError
            A wrong key (ILLEGAL DATA VALUE) or an unlock during the
            controller's backoff or lockout after wrong keys (SERVER DEVICE BUSY).
        """
        try:
            self.write("unlock_key", self.key)
        except ModbusExceptionError as exc:
            if exc.code == 3:
                raise DeviceError(f"{self.client.name}: the controller refused the unlock key "
                                  f"(set ${KEY_ENV} to the key it was provisioned with)") from None
            if exc.code == 6:
                raise DeviceError(f"{self.client.name}: unlock refused for now: too many wrong keys "
                                  "(backoff or lockout, see docs/protocol.md)") from None
            raise

    def lock(self) -> None:
        """Give up this session's unlock."""
        self.write("unlock", 0)

    def set_mode(self, mode: str) -> None:
        self.write("mode", MODES[mode])

    def arm(self, on: bool = True) -> None:
        if on and self.status()["faults"]:
            st = self.status()
            raise DeviceError(f"cannot arm: the controller reports faults: {', '.join(st['faults_names'])} "
                              "(clear them first)")
        self.write("arm", 1 if on else 0)
        if on and not self.status()["armed"]:
            raise DeviceError("the controller did not arm (clear its faults first)")

    def command(self, name: str) -> None:
        """Issue a one-shot command (``interface.ENUMS["command"]``)."""
        self.write("command", COMMANDS[name])

    def set_setpoint_um(self, y_um: float) -> None:
        self.write("setpoint_q15", self.q15_position(y_um))
        self.write("ref_source", 0)

    def q15_position(self, y_um) -> int:
        return int(np.clip(np.floor(self.scale.position_to_fs(y_um) * 32768 + 0.5), -32768, 32767))

    def q15_drive(self, u_v) -> int:
        return int(np.clip(np.floor(self.scale.drive_to_fs(u_v) * 32768 + 0.5), -32768, 32767))

    # ------------------------------------------------------------ feedback configuration
    def configure_feedback(self, *, kp: float = 0.0, ki: float = 0.0, kd: float = 0.0,
                           notch: tuple | None = None, out_limit: float = 1.0) -> None:
        """PID gains [FS/FS, per tick] and an optional notch (b0, b1, b2, a1, a2); unit disarmed."""
        q24 = lambda x: int(np.floor(x * 2**24 + 0.5))
        self.unlock()
        lim = int(np.clip(np.floor(out_limit * 32768 + 0.5), 0, 32767))
        vals = [q24(kp), q24(ki), q24(kd)]
        regs = []
        for v in vals:
            v &= 0xFFFFFFFF
            regs += [v >> 16, v & 0xFFFF]
        regs += [_u16(-lim), _u16(lim)]
        self.client.write_holding(self._h("pid_kp_q24"), regs)
        if notch is not None:
            nregs = []
            for c in notch:
                v = q24(c) & 0xFFFFFFFF
                nregs += [v >> 16, v & 0xFFFF]
            self.write("notch_on", 1)
            self.client.write_holding(self._h("notch_b0_q24"), nregs)
        else:
            self.write("notch_on", 0)

    def configure(self, name: str, value: int) -> None:
        """Write one configuration register (unlocks; the unit must be disarmed)."""
        self.unlock()
        self.write(name, value)

    def configure_shaper(self, ticks: int = 0, taps_q15=(32768, 0, 0), preview_ticks: int = 0) -> None:
        """Input shaper (tap spacing [ticks], three q15 taps) and reference preview [ticks]."""
        self.unlock()
        self.client.write_holding(self._h("preview_ticks"), [preview_ticks, ticks] + [_u16(t) for t in taps_q15])

    def configure_dyninv(self, taps_q13=(), spacing: int = 1) -> None:
        """The dynamics-inverse FIR on the early reference: q13 taps (8192 = 1), newest sample first, spaced
        ``spacing`` ticks; no taps: off (the preview is :meth:`configure_shaper`'s). Unit disarmed."""
        n = interface.HOLDING_REGISTERS["dyninv_q13"][2]
        taps = list(taps_q13)
        if len(taps) > n:
            raise ValueError(f"at most {n} taps")
        self.unlock()
        self.client.write_holding(self._h("dyninv_taps"),
                                  [len(taps), spacing] + [_u16(t) for t in taps] + [0] * (n - len(taps)))

    # ------------------------------------------------------------ wave generator
    def configure_wave(self, kind: str, *, offset_q15: int = 0, amplitude_q15: int = 0, f_hz: float = 0.0,
                       f_end_hz: float | None = None, duration_s: float | None = None, cycles: int = 0,
                       tones: list[tuple[int, float, float]] | None = None,
                       levels_q15: list[int] | None = None, durations_ticks: list[int] | None = None,
                       hold_ticks: int = 1) -> None:
        """Load the wave generator (not started). Frequencies [Hz], amplitudes q15."""
        tick = float(self.identity.tick_hz)
        fw = freq_word(f_hz, tick)
        rate = end = 0
        if kind == "chirp":
            end = freq_word(f_end_hz, tick)
            n = max(1, int(round(duration_s * tick)))
            rate = max(1, (end - fw) // n)
        tones = tones or []
        levels = levels_q15 or []
        if len(tones) > 8 or len(levels) > interface.HOLDING_REGISTERS["wave_levels"][2]:
            raise DeviceError("too many tones or levels for the wave generator")
        head = [WAVE_KINDS[kind], _u16(offset_q15), _u16(amplitude_q15), fw >> 16, fw & 0xFFFF,
                rate >> 16, rate & 0xFFFF, end >> 16, end & 0xFFFF, cycles >> 16, cycles & 0xFFFF,
                len(tones), len(levels), hold_ticks >> 16, hold_ticks & 0xFFFF]
        self.client.write_holding(self._h("wave_kind"), head)
        if tones:
            regs = []
            for amp, f, ph in tones:
                w, p = freq_word(f, tick), int(np.floor((ph / (2 * np.pi)) % 1.0 * 2**32)) & 0xFFFFFFFF
                regs += [_u16(amp), w >> 16, w & 0xFFFF, p >> 16, p & 0xFFFF]
            self.client.write_holding(self._h("wave_tones"), regs)
        if levels:
            self.client.write_holding(self._h("wave_levels"), [_u16(v) for v in levels])
        if durations_ticks:
            regs = []
            for d in durations_ticks:
                regs += [(int(d) >> 16) & 0xFFFF, int(d) & 0xFFFF]
            self.client.write_holding(self._h("wave_durations"), regs)
        self.write("ref_source", 1)

    # ------------------------------------------------------------ recorder
    def configure_recorder(self, signals: list[str], *, decimation: int = 1, pretrigger: int = 0,
                           trigger: str = "software", trigger_signal: str = "ref", level_q15: int = 0,
                           ring: bool = False) -> None:
        """Configure the recorder (applied when it is armed).

        ``ring``: ring mode, the recorder keeps recording after the trigger
        until reset (for :meth:`stream`); needs ``pretrigger`` 0.
        """
        if not 1 <= len(signals) <= 8:
            raise DeviceError("the recorder keeps 1 to 8 signals")
        sig = [SIGNALS[s] for s in signals] + [0] * (8 - len(signals))
        # rec_n_channels .. rec_ring are contiguous: one request
        regs = [len(signals)] + sig + [decimation, pretrigger >> 16, pretrigger & 0xFFFF,
                                       REC_TRIGGERS[trigger], SIGNALS[trigger_signal], _u16(level_q15),
                                       1 if ring else 0]
        self.client.write_holding(self._h("rec_n_channels"), regs)
        self.rec_channels = len(signals)

    def read_recording(self, n_channels: int | None = None,
                       progress: Callable[[int, int], None] | None = None) -> np.ndarray:
        """The recorded frames, shape (frames, channels), q15 integers."""
        st = self.status()
        frames = st["rec_frames"]
        nch = n_channels or self.client.read_holding(self._h("rec_n_channels"))[0]
        total = frames * nch
        out = np.empty(total, dtype=np.int64)
        idx = self._h("rec_read_index")
        for start in range(0, total, REC_WINDOW):
            n = min(REC_WINDOW, total - start)
            # index and window in one FC 23 request (the write is done first)
            w = self.client.read_write(self._h("rec_window"), n, idx, [start >> 16, start & 0xFFFF])
            out[start:start + n] = np.array(w, dtype=np.int64)
            if progress:
                progress(start + n, total)
        out = np.where(out >= 32768, out - 65536, out)
        return out.reshape(frames, nch)

    def to_physical(self, signal: str, q15) -> np.ndarray:
        """A recorded signal in physical units: positions [um], drives [V], error [um]."""
        fs = np.asarray(q15, dtype=np.float64) / 32768.0
        sc = self.scale
        if signal in ("y", "ref", "y2"):
            return sc.position_from_fs(fs)
        if signal in ("u", "u2", "ff"):
            return sc.drive_from_fs(fs)
        if signal == "err":
            return fs * sc.p_half
        return fs * 0.5 * (sc.drive_max_v - sc.drive_min_v)  # fb: a drive difference

    def capture(self, signals: list[str], frames: int, *, decimation: int = 1, trigger: str = "immediate",
                level_q15: int = 0, trigger_signal: str = "ref", start_wave: bool = False,
                timeout_s: float | None = None) -> dict:
        """Record ``frames`` frames of ``signals`` and return them in physical units with ``t`` [s].

        ``trigger``: ``immediate``; ``software`` (fired by the wave start when
        ``start_wave``); ``rising``/``falling`` (``trigger_signal`` crosses
        ``level_q15``). The wave, if started here, keeps running afterwards.
        """
        tick = self.identity.tick_hz
        cap = self.identity.rec_capacity // len(signals)
        if not 1 <= frames <= cap:
            raise DeviceError(f"{frames} frames of {len(signals)} signals: the recorder holds 1..{cap}")
        self.configure_recorder(signals, decimation=decimation, trigger=trigger,
                                trigger_signal=trigger_signal, level_q15=level_q15)
        self.command("arm_recorder")
        if start_wave:
            self.command("start_wave")
        self.wait_recorder(frames, timeout_s if timeout_s is not None else frames * decimation / tick * 3 + 5)
        data = self.read_recording(len(signals))[:frames]
        cols = {"t": np.arange(data.shape[0]) * decimation / tick}
        for i, sname in enumerate(signals):
            cols[sname] = self.to_physical(sname, data[:, i])
        return cols

    def wait_recorder(self, frames: int, timeout_s: float, *, stall_s: float = STALL_S) -> None:
        """Wait until the armed recorder holds ``frames`` frames or is full.

        ``timeout_s`` [s] is counted in the controller's own time (its
        ``tick_count`` over ``tick_hz``), not on the host's clock: an
        emulated controller (QEMU with ``-icount``) or a SIL controller on a
        loaded machine ticks slower than real time, and still fills its
        recorder in the ticks it needs. The host's clock only watches that
        the controller ticks at all: no tick for ``stall_s`` [s] of wall time
        fails at once.

        Raises
        ------
        DeviceError
            ``timeout_s`` of controller time passed, or the controller did not
            tick for ``stall_s`` of wall time.
        """
        tick_hz = self.identity.tick_hz
        budget = int(np.ceil(timeout_s * tick_hz))
        first = last = None
        last_wall = time.monotonic()
        while True:
            st = self.status()
            if st["rec_frames"] >= frames or st["rec_state"] == 3:
                return
            now, tc = time.monotonic(), st["tick_count"]
            if first is None:
                first = last = tc
            if tc != last:
                last, last_wall = tc, now
            elif now - last_wall > stall_s:
                raise DeviceError(f"the recorder did not fill: the controller did not tick for {stall_s:g} s "
                                  f"(it holds {st['rec_frames']} of {frames} frames)")
            if (tc - first) % (1 << 32) > budget:   # tick_count wraps at 2^32
                raise DeviceError(f"the recorder did not fill in {timeout_s:g} s of controller time "
                                  f"({st['rec_frames']} of {frames} frames; did the trigger condition occur?)")
            time.sleep(0.02)

    def rec_frames_capacity(self, n_signals: int) -> int:
        """Frames of ``n_signals`` signals the recorder holds (``rec_capacity`` / signals)."""
        return self.identity.rec_capacity // n_signals

    def read_rec_written(self) -> int:
        """Frames recorded since the trigger (input register ``rec_written``, wraps at 2^32)."""
        hi, lo = self.client.read_input(interface.INPUT_REGISTERS["rec_written"][0], 2)
        return (hi << 16) | lo

    def stream(self, signals: list[str], frames: int, *, decimation: int = 1, trigger: str = "immediate",
               start_wave: bool = False, progress: Callable[[int, int], None] | None = None,
               stall_s: float = 3.0) -> tuple[dict, int]:
        """Record ``frames`` frames of ``signals``, reading the recorder while it runs (ring mode).

        The recorder runs as a ring (``rec_ring``): frame n (0 the first after
        the trigger) sits in buffer slot n mod capacity until frame n +
        capacity replaces it, and ``rec_written`` counts the frames. This
        reads the slots behind the writer, so a capture of any length works
        as long as the link keeps up on average; a frame the writer replaced
        before it was read (or possibly while it was being read) is lost.

        Parameters
        ----------
        signals : list of str
            Recorder signals (keys of :data:`SIGNALS`), 1 to 8.
        frames : int
            Frames to capture, >= 1 (no upper limit).
        decimation : int
            Keep every n-th tick, 1..65535.
        trigger : str
            ``immediate`` or ``software`` (fired by the wave start when ``start_wave``).
        start_wave : bool
            Start the loaded wave after arming the recorder.
        progress : callable, optional
            ``progress(frames_done, frames)`` after each batch.
        stall_s : float
            Give up [s] when the recorder stores no frame for this long.

        Returns
        -------
        cols : dict of ndarray
            ``t`` [s] of each frame received (a lost frame leaves a gap) and
            each signal in physical units (:meth:`to_physical`).
        lost : int
            Frames lost (overwritten before they were read).
        """
        nch = len(signals)
        cap = self.rec_frames_capacity(nch)
        per_req = REC_WINDOW // nch          # whole frames per FC 23 request
        batch = max(per_req, cap // 8)       # frames read between two checks of rec_written
        tick = self.identity.tick_hz
        data = np.zeros((frames, nch), dtype=np.int64)
        got = np.zeros(frames, dtype=bool)
        idx = self._h("rec_read_index")
        win = self._h("rec_window")
        self.configure_recorder(signals, decimation=decimation, trigger=trigger, ring=True)
        self.command("arm_recorder")
        try:
            if start_wave:
                self.command("start_wave")
            written, raw_prev = 0, 0          # written: rec_written unwrapped past 2^32
            nxt = 0                           # next frame to read
            unchecked = (0, 0)                # frames [a, b) read since the last rec_written
            last_change = time.monotonic()
            while True:
                raw = self.read_rec_written()
                step = (raw - raw_prev) & 0xFFFFFFFF
                raw_prev, written = raw, written + step
                if step:
                    last_change = time.monotonic()
                # a frame read before this count is good if the writer had not
                # yet replaced its slot: written - n < capacity
                a, b = unchecked
                if b > a:
                    n = np.arange(a, b)
                    got[a:b] = written - n < cap
                if nxt >= frames:
                    break
                if written - nxt >= cap:      # the writer lapped us: skip what it overwrote
                    nxt = written - cap + 1
                end = min(written, frames, nxt + batch)
                if end <= nxt:
                    if time.monotonic() - last_change > stall_s:
                        raise DeviceError(f"the recorder stopped after {written} frames "
                                          "(is the controller ticking?)")
                    time.sleep(0.002)
                    continue
                n = nxt
                while n < end:
                    slot = n % cap
                    m = min(per_req, end - n, cap - slot)
                    start = slot * nch
                    words = self.client.read_write(win, m * nch, idx, [start >> 16, start & 0xFFFF])
                    data[n:n + m] = np.asarray(words, dtype=np.int64).reshape(m, nch)
                    n += m
                unchecked = (nxt, end)
                nxt = end
                if progress:
                    progress(int(np.count_nonzero(got[:nxt])), frames)
        finally:
            self.command("reset_recorder")  # a ring records until reset
        data = np.where(data >= 32768, data - 65536, data)[got]
        cols = {"t": np.flatnonzero(got) * decimation / tick}
        for i, sname in enumerate(signals):
            cols[sname] = self.to_physical(sname, data[:, i])
        return cols, int(frames - np.count_nonzero(got))

    # ------------------------------------------------------------ tables
    def upload_table(self, img: bytes, progress: Callable[[int, int], None] | None = None) -> None:
        """Write an image to the staged bank: offset and data in one request per chunk."""
        self.unlock()
        self.write("table_command", TABLE_COMMANDS["clear_staged"])
        chunk = 2 * WINDOW
        for off in range(0, len(img), chunk):
            part = img[off:off + chunk]
            if len(part) % 2:
                part += b"\0"
            words = list(struct.unpack(f"<{len(part) // 2}H", part))
            self.client.write_holding(self._h("table_offset"), [off >> 16, off & 0xFFFF] + words)
            if progress:
                progress(min(off + chunk, len(img)), len(img))

    def read_staged(self, n: int, progress: Callable[[int, int], None] | None = None) -> bytes:
        """Read back the first n bytes of the staged bank: offset and window
        in one FC 23 request per chunk (the offset is written before the read)."""
        out = bytearray()
        chunk = 2 * WINDOW
        for off in range(0, n, chunk):
            m = min(chunk, n - off)
            words = self.client.read_write(self._h("table_window"), (m + 1) // 2,
                                           self._h("table_offset"), [off >> 16, off & 0xFFFF])
            out += struct.pack(f"<{len(words)}H", *words)[:m]
            if progress:
                progress(off + m, n)
        return bytes(out)

    def commit_table(self) -> str:
        """Commit the staged image; returns the reason name ('ok' when it runs)."""
        self.write("table_command", TABLE_COMMANDS["commit"])
        return REASON_NAMES.get(self.status()["table_result"], "unknown")

    def rollback_table(self) -> str:
        """Back to the previous table; returns the controller's reason name ('ok' when done)."""
        self.unlock()
        self.write("table_command", TABLE_COMMANDS["rollback"])
        return REASON_NAMES.get(self.status()["table_result"], "unknown")

    def flash(self, img: bytes, *, progress: Callable[[str, int, int], None] | None = None,
              timeout_s: float = 2.0) -> dict:
        """Put a table image into service: upload, verify, commit, confirm.

        The one way a table reaches a controller (``piezoctl flash``,
        ``piezoctl calibrate``). The image's framing is checked locally first
        (:func:`piezoctl.tables.image.parse_image`: magic, lengths, CRC; the
        controller checks the rest and says why it refuses); then it is written to
        the staged bank, read back and compared byte for byte and by CRC,
        committed, and the controller is polled until it reports the image's
        CRC as running (``active_table_crc``, or ``coupling_table_crc`` for a
        ``cross_coupling`` table). A refusal leaves the running table running.

        Parameters
        ----------
        img : bytes
            The table image (``piezoctl tables build``).
        progress : callable, optional
            ``progress(step, done, total)`` with step ``"upload"`` or
            ``"verify"`` and byte counts.
        timeout_s : float
            How long to wait for the committed table to run [s].

        Returns
        -------
        dict
            ``crc``, ``version``, ``kind`` (name) and ``bytes`` of the image.

        Raises
        ------
        CliError
            The image is not one the firmware would accept (nothing sent).
        ControllerRefused
            The read-back differs (not committed), the controller refused
            the commit (its reason in the message), or it does not report
            the table running in time.
        """
        from .tables.image import TableImageError, parse_image
        try:
            t = parse_image(img)
        except TableImageError as exc:
            raise CliError(f"not a valid table image: {exc}") from None
        kind = KIND_NAMES.get(t.header["kind"], str(t.header["kind"]))
        step = (lambda name: (lambda done, total: progress(name, done, total))) if progress else (lambda name: None)
        self.upload_table(img, step("upload"))
        back = self.read_staged(len(img), step("verify"))
        if back != img:
            bad = next((i for i, (a, b) in enumerate(zip(back, img)) if a != b), len(back))
            raise DeviceError(f"the staged bank differs from the image at byte {bad}: not committed")
        if zlib.crc32(back[:-4]) & 0xFFFFFFFF != t.crc:
            raise DeviceError("the staged bank's CRC does not match: not committed")
        result = self.commit_table()
        if result != "ok":
            raise DeviceError(f"the controller refused the table: {result} ({TABLE_REASON_HELP.get(result, '')}); "
                              "the table that was running keeps running")
        reg = "coupling_table_crc" if kind == "cross_coupling" else "active_table_crc"
        deadline = time.monotonic() + timeout_s
        while self.status()[reg] != t.crc:
            if time.monotonic() > deadline:
                raise DeviceError("the controller accepted the table but does not report it running")
            time.sleep(0.01)
        return {"crc": t.crc, "version": t.header["table_version"], "kind": kind, "bytes": len(img)}

    def tables(self) -> dict:
        """The tables the controller holds: ``active``, ``previous`` (the
        rollback target), ``staged`` (an upload not committed) and
        ``coupling``; each ``None`` or a dict of ``kind``, ``crc``,
        ``version`` and ``stage`` (axis and ranges). A committed table
        always matches the controller's own stage (the commit checks it), so
        active and previous carry the controller's identity; a staged
        image's header is read back from the staged bank."""
        st = self.status()
        sc, axis = self.scale.to_dict(), self.identity.axis
        own = {"axis": axis, **sc}
        out = {"active": None, "previous": None, "staged": None, "coupling": None}
        if st["active_table_crc"]:
            out["active"] = {"kind": KIND_NAMES.get(st["active_table_kind"], str(st["active_table_kind"])),
                             "crc": st["active_table_crc"], "version": st["active_table_version"], "stage": own}
        if st["previous_table_crc"]:
            out["previous"] = {"kind": KIND_NAMES.get(st["previous_table_kind"], str(st["previous_table_kind"])),
                               "crc": st["previous_table_crc"], "version": st["previous_table_version"],
                               "stage": own}
        if st["coupling_table_crc"]:
            out["coupling"] = {"kind": "cross_coupling", "crc": st["coupling_table_crc"], "version": None,
                               "stage": own}
        n = st["staged_bytes"]
        if n >= interface.TABLE_HEADER_BYTES + 4:
            head = self.read_staged(interface.TABLE_HEADER_BYTES)
            tail = self._read_staged_at(n - 4, 4)
            h = {name: struct.unpack_from({"uint16": "<H", "uint32": "<I", "int32": "<i"}[typ], head, off)[0]
                 for name, typ, off, _count in interface.TABLE_HEADER if typ != "bytes"}
            out["staged"] = {"kind": KIND_NAMES.get(h["kind"], str(h["kind"])),
                             "crc": struct.unpack("<I", tail)[0], "version": h["table_version"], "bytes": n,
                             "stage": {"axis": h["axis"], "drive_min_v": h["drive_min_mv"] / 1e3,
                                       "drive_max_v": h["drive_max_mv"] / 1e3,
                                       "position_min_um": h["position_min_nm"] / 1e3,
                                       "position_max_um": h["position_max_nm"] / 1e3}}
        elif n:
            out["staged"] = {"kind": None, "crc": None, "version": None, "bytes": n, "stage": None}
        return out

    def _read_staged_at(self, off: int, n: int) -> bytes:
        """n bytes of the staged bank from offset off (even), one FC 23 request."""
        start = off & ~1
        words = self.client.read_write(self._h("table_window"), (off - start + n + 1) // 2,
                                       self._h("table_offset"), [start >> 16, start & 0xFFFF])
        return struct.pack(f"<{len(words)}H", *words)[off - start:off - start + n]

    # ------------------------------------------------------------ operating
    def servo(self, on: bool, timeout_s: float = 1.0) -> dict:
        """Servo on (closed loop at the present position, arming a disarmed
        unit) or off (open loop holding the drive applied now); the
        controller switches at a tick boundary without a drive jump
        (docs/operate.md). Waits until the mode says it happened.

        Raises
        ------
        DeviceError
            The controller refused (faults for on; disarmed for off) or did
            not switch in time.
        """
        try:
            self.command("servo_on" if on else "servo_off")
        except ModbusExceptionError as exc:
            if exc.code != 3:
                raise
            st = self.status()
            why = (f"faults: {', '.join(st['faults_names'])} (clear them: piezoctl status shows them)"
                   if on else "the unit is disarmed")
            raise DeviceError(f"the controller refused servo {'on' if on else 'off'}: {why}") from None
        want = MODES["feedback"] if on else MODES["direct"]
        deadline = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if st["mode"] == want and st["armed"]:
                return st
            if time.monotonic() > deadline:
                raise DeviceError(f"servo {'on' if on else 'off'} not done within {timeout_s} s "
                                  f"(mode {MODE_NAMES.get(st['mode'], st['mode'])}, armed {st['armed']})")
            time.sleep(0.005)

    # ------------------------------------------------------------ parameters
    def read_params(self) -> dict:
        """The controller parameters (the configuration registers) as raw
        register values by name: int, or a list for an array."""
        words = self.client.read_holding(interface.PARAMS_FIRST, interface.PARAMS_WORDS)
        return _params_from_words(words)

    def write_params(self, values: dict) -> None:
        """Write raw parameter values (name -> int or list) in one request:
        the controller checks the whole block and applies all or nothing.
        Needs a disarmed unit; unlocks this session.

        Raises
        ------
        DeviceError
            The unit is armed, or the controller refused a value.
        """
        unknown = [k for k in values if k not in PARAM_SPECS]
        if unknown:
            raise CliError(f"unknown parameter(s): {', '.join(unknown)}")
        if self.status()["armed"]:
            raise DeviceError("parameters change only while disarmed: run piezoctl servo off --disarm first "
                              "(the drive then ramps to its safe value)")
        cur = self.read_params()
        cur.update(values)
        self.unlock()
        try:
            self.client.write_holding(interface.PARAMS_FIRST, _params_to_words(cur))
        except ModbusExceptionError as exc:
            if exc.code == 3:
                raise DeviceError("the controller refused the parameters (a value outside what it accepts: "
                                  "an unstable notch, min above max, bad_limit 0, ...); nothing changed") from None
            raise

    def params_command(self, name: str) -> str:
        """``save``, ``load`` or ``defaults`` (``interface.ENUMS["params_command"]``);
        returns the controller's reason name (``ok`` when done)."""
        self.unlock()
        self.write("params_command", PARAMS_COMMANDS[name])
        return PARAMS_REASON_NAMES.get(self.status()["params_result"], "unknown")

    def params_state(self) -> dict:
        """Where the running parameters came from: ``source`` (defaults,
        flash, changed), ``seq`` of the flash record, ``result`` of the last
        params command or boot, ``ignored`` (why a stored record was not used),
        ``wave``: whether the active record holds the wave and its learned
        feedforward (``interface.ENUMS["params_wave"]``: none, saved, left_out)."""
        st = self.status()
        return {"source": PARAMS_SOURCE_NAMES.get(st["params_source"], str(st["params_source"])),
                "seq": st["params_seq"],
                "result": PARAMS_REASON_NAMES.get(st["params_result"], str(st["params_result"])),
                "ignored": PARAMS_REASON_NAMES.get(st["params_ignored"], str(st["params_ignored"])),
                "wave": PARAMS_WAVE_NAMES.get(st["params_wave"], str(st["params_wave"]))}


def connect(port: str, *, unit: int = interface.MODBUS_UNIT_ID, timeout: float = 1.0,
            key: int | str | None = None) -> Controller:
    """Open PORT and check that a compatible controller answers; ``key``: see :func:`unlock_key`."""
    return Controller(open_port(port, unit=unit, timeout=timeout), key=key)
