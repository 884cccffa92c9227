"""``Controller.wait_recorder`` counts its timeout in the controller's ticks.

An emulated controller (QEMU with ``-icount``) on a loaded host ticks several
times slower than real time; the wait must still end when the recorder fills,
and must fail at once when the controller stops ticking. A fake controller
whose tick runs on a clock this test owns.
"""

import types

import pytest

from piezoctl import device
from piezoctl.device import Controller, DeviceError


class _Clock:
    def __init__(self):
        self.t = 0.0

    def monotonic(self):
        return self.t

    def sleep(self, s):
        self.t += s


class _FakeRecorder(Controller):
    """Ticks at ``rate`` of real time (ticks per wall second / tick_hz); fills one frame per tick
    after ``trigger_after`` ticks; ``stop_at`` ticks: it stops ticking there."""

    def __init__(self, clock, rate, trigger_after=0, stop_at=None, start_tick=0):
        self.identity = types.SimpleNamespace(tick_hz=10000)
        self.clock, self.rate, self.trigger_after, self.stop_at = clock, rate, trigger_after, stop_at
        self.start_tick = start_tick

    def status(self):
        ticks = int(self.clock.t * 10000 * self.rate)
        if self.stop_at is not None:
            ticks = min(ticks, self.stop_at)
        frames = max(0, ticks - self.trigger_after)
        return {"rec_frames": frames, "rec_state": 1, "tick_count": (self.start_tick + ticks) % (1 << 32)}


@pytest.fixture
def clock(monkeypatch):
    c = _Clock()
    monkeypatch.setattr(device, "time", types.SimpleNamespace(monotonic=c.monotonic, sleep=c.sleep))
    return c


def test_a_controller_ticking_at_a_tenth_of_real_time_fills_within_its_own_time(clock):
    ctl = _FakeRecorder(clock, rate=0.1)
    ctl.wait_recorder(20000, 2 * 20000 / 10000)   # 2 s of controller time: 20 s of wall time here
    assert clock.t >= 20.0
    assert ctl.status()["rec_frames"] >= 20000


def test_a_trigger_that_never_comes_times_out_in_controller_time(clock):
    ctl = _FakeRecorder(clock, rate=0.1, trigger_after=10 ** 9)
    with pytest.raises(DeviceError, match="did not fill in 3 s of controller time"):
        ctl.wait_recorder(100, 3.0)
    assert 30.0 <= clock.t < 31.0   # 3 s at a tenth of real time, and not much more


def test_a_controller_that_stops_ticking_fails_after_the_stall_time(clock):
    ctl = _FakeRecorder(clock, rate=1.0, stop_at=500)
    with pytest.raises(DeviceError, match="did not tick for 5 s"):
        ctl.wait_recorder(10000, 1000.0)
    assert 5.0 < clock.t < 5.2


def test_the_tick_count_wrapping_at_2_to_32_does_not_end_the_wait(clock):
    ctl = _FakeRecorder(clock, rate=1.0, start_tick=(1 << 32) - 100)
    ctl.wait_recorder(5000, 1.0)
    assert ctl.status()["rec_frames"] >= 5000
