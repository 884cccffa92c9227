"""Calibrate's runs do not depend on how fast the host is (issue 15, round 10).

A loaded PC answers late. Everything a run does must be keyed to the
controller's ticks: a triangle ends by itself one period after its record, at
its offset (``wave_cycles``), never at the phase where a late ``stop_wave``
happens to arrive (a step of up to the amplitude, after a valid record, that
rang the 140 Hz stage past its sensor and got the configuration reported as
faulted: docs/calibrate.md, "Host timing"); the wait for a wave's end counts
ticks, not host seconds; a fault that latches only when the host stops a
multisine leaves the run's figures standing.
"""

import sys
import time

import numpy as np
import pytest

from piezoctl import interface
from piezoctl.calibrate import excitation, ilc, pipeline
from piezoctl.sil.stage import default_stage_path
from sil_fixture import SilStage


class TickController:
    """A controller stand-in whose wave runs a fixed number of ticks and whose
    ticks advance only ``ticks_per_poll`` at each status read: host time and
    controller time are unrelated, as on a loaded PC or a stalled link."""

    def __init__(self, wave_ticks: int, ticks_per_poll: int):
        self.tick = 0
        self.wave_end = wave_ticks
        self.per_poll = ticks_per_poll
        self.commands = []
        me = self

        class Client:
            def read_input_u32(self, addr):
                assert addr == interface.INPUT_REGISTERS["tick_count"][0]
                return me.tick & 0xFFFFFFFF

            def read_holding(self, addr, n):
                assert addr == interface.HOLDING_REGISTERS["wave_kind"][0]
                return [interface.ENUMS["wave_kind"]["triangle"]]

        self.client = Client()

    def status(self):
        self.tick += self.per_poll
        return {"wave_running": int(self.tick < self.wave_end), "faults": 0}

    def command(self, name):
        self.commands.append((name, self.tick))


def test_the_wait_for_a_wave_end_counts_ticks_not_host_seconds():
    # a controller whose ticks crawl (1 a poll: 10 ms of host time each): its 500 remaining
    # ticks take 5 s of host time, longer than the 3 s the wait used to allow; the
    # wave must still end by itself, and only then is it stopped
    ctl = TickController(wave_ticks=500, ticks_per_poll=1)
    t0 = time.monotonic()
    ilc._stop(ctl, max_ticks=10000)
    assert time.monotonic() - t0 > 3.0
    assert ctl.commands == [("stop_wave", 500)]
    # a wave that does not end is given up after max_ticks ticks, however fast the host polls
    ctl = TickController(wave_ticks=10**9, ticks_per_poll=100)
    assert not excitation.wait_wave_end(ctl, 2000, poll_s=0.0)
    assert 2000 < ctl.tick <= 2300


@pytest.fixture(scope="module")
def two_axis(tmp_path_factory):
    s = SilStage(tmp_path_factory.mktemp("timing"), "--stage", str(default_stage_path("two_axis")))
    from piezoctl.device import connect
    ctl = connect(s.spec)
    yield ctl
    s.stop()


@pytest.mark.parametrize("delay_ms", [0.0, 5.0, 10.0, 15.0])
def test_a_triangle_run_ends_on_its_tick_whatever_the_host_delay(two_axis, delay_ms, monkeypatch):
    # the 140 Hz stage in DIRECT mode (the drive is the reference), a 50 Hz triangle: the host
    # answers delay_ms late after reading the record (0 to 3/4 of a period: every phase a late
    # stop_wave would have cut the wave at)
    ctl = two_axis
    if not ctl.status()["armed"]:   # once: disarming drops the drive, which rings the mode into a fault
        ctl.command("clear_faults")
        ctl.set_mode("direct")
        ctl.arm(True)
    read = ctl.read_recording
    sent = []
    command = ctl.command

    def late_read(*a, **k):
        out = read(*a, **k)
        time.sleep(delay_ms / 1000.0)
        return out

    def spy(name, *a, **k):
        sent.append(name)
        return command(name, *a, **k)

    monkeypatch.setattr(ctl, "read_recording", late_read)
    monkeypatch.setattr(ctl, "command", spy)
    centre = 0.5 * (ctl.scale.position_min_um + ctl.scale.position_max_um)
    run = excitation.triangle_run(ctl, 50.0, centre, 5.0, periods=5)
    st = ctl.status()
    assert "stop_wave" not in sent, sent   # the host never cut the wave
    assert not run["stopped_by_host"]
    assert not st["wave_running"] and st["reference_q15"] == ctl.q15_position(centre)   # ended by itself, at its offset
    assert run["faults_in_record"] == 0 and not st["faults"]
    # the record is the wave's five periods from its first settled tick: the same for every delay
    assert run["ref"].size == 5 * 200
    tri = run["ref"] - run["ref"].mean()
    assert np.max(np.abs(tri[:200] - tri[800:])) < 1e-9


@pytest.mark.parametrize("after_ms", [3.0, 11.0, 17.0, 40.0])
def test_the_other_axis_wave_ends_at_its_offset_not_where_the_host_stops(two_axis, after_ms, monkeypatch):
    # the coupling evaluation runs the other axis' triangle endlessly while the held axis learns;
    # it used to stop it with stop_wave at whatever phase the host reached (after_ms into a 50 Hz
    # period: anywhere on the triangle). It must now end at the end of a period, at its offset.
    from piezoctl.calibrate import coupling
    ctl = two_axis
    if not ctl.status()["armed"]:
        ctl.command("clear_faults")
        ctl.set_mode("direct")
        ctl.arm(True)
    sent = []
    command = ctl.command

    def spy(name, *a, **k):
        sent.append(name)
        return command(name, *a, **k)

    monkeypatch.setattr(ctl, "command", spy)
    centre = 0.5 * (ctl.scale.position_min_um + ctl.scale.position_max_um)
    excitation.load_triangle(ctl, 50.0, centre, 5.0)      # endless (wave_cycles 0), as coupling loads it
    ctl.command("start_wave")
    time.sleep(0.06 + after_ms / 1000.0)
    assert ctl.status()["wave_running"]                    # it was still running when the host ended it
    assert coupling._end_other_wave(ctl, 200)
    st = ctl.status()
    assert sent == ["start_wave"], sent                    # no stop_wave: it ended by itself
    assert not st["wave_running"] and st["reference_q15"] == ctl.q15_position(centre)
    assert not st["faults"]


class FakeRecoverController:
    def __init__(self, faults: int):
        self.faults = faults
        self.sent = []

    def status(self):
        return {"faults": self.faults, "faults_names": ["sensor_implausible"] if self.faults else []}

    def arm(self, on):
        self.sent.append(("arm", on))

    def command(self, name):
        self.sent.append(name)
        self.faults = 0


@pytest.mark.parametrize("run, kept", [
    ({"stopped_by_host": True, "faults_in_record": 0}, True),    # latched at the host's stop: figures stand
    ({"stopped_by_host": True, "faults_in_record": 1}, False),   # latched during the record: invalid
    ({"stopped_by_host": False, "faults_in_record": 1}, False),  # a triangle that faulted by itself
    (None, False),                                               # nothing known: invalid, as before
])
def test_a_fault_at_the_host_stop_keeps_the_figures(run, kept):
    ctl = FakeRecoverController(faults=1)
    faulted, stop_faults, said = [], [], []
    pipeline._recover(ctl, faulted, "+ learned feedforward, multitone", said.append, run, stop_faults)
    assert ("clear_faults" in ctl.sent) and ctl.faults == 0          # cleared in every case
    assert (not faulted) == kept and bool(stop_faults) == kept
    assert len(said) == 1 and ("figures stand" in said[0]) == kept
    # no fault: nothing recorded, nothing sent
    ctl = FakeRecoverController(faults=0)
    pipeline._recover(ctl, faulted := [], "x", said.append, run, stop_faults := [])
    assert not faulted and not stop_faults and not ctl.sent


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
