"""The learned feedforward (``piezoctl.calibrate.ilc``): the update converges on a
known linear loop, a wrong learning filter is caught by the divergence guard
(no trial's correction is kept that made the error grow), the resampling to
the firmware's table is exact for a band-limited correction, and on the SIL
controller a learned table is played in sync with the wave and bad tables
are refused without changing the one played."""

import time

import numpy as np
import pytest

from piezoctl import interface
from piezoctl.calibrate import ilc
from sil_fixture import sil  # noqa: F401  (pytest fixture)

FS = 10000.0


def loop_filter(n: int, delay: int = 3, pole: float = 0.7):
    """Frequency response at the harmonics of an n-sample period of a delay of
    ``delay`` samples times a first-order low-pass of unit DC gain (a stand-in
    for the closed loop)."""
    z = np.exp(2j * np.pi * np.arange(n // 2 + 1) / n)
    return z ** -delay * (1 - pole) / (1 - pole / z)


def periodic(T, r_plus_c):
    """Steady-state periodic output of the loop T for one period of input."""
    return np.fft.irfft(T * np.fft.rfft(r_plus_c), n=r_plus_c.size)


def reference(n: int, f0: float):
    t = np.arange(n) / FS
    return (np.sin(2 * np.pi * f0 * t) + 0.3 * np.sin(2 * np.pi * 7 * f0 * t + 0.4)
            + 0.1 * np.sin(2 * np.pi * 13 * f0 * t + 1.0))


@pytest.mark.parametrize("measured_loop", [True, False])
def test_converges_on_a_known_linear_loop(measured_loop):
    n, f0 = 200, 50.0
    T = loop_filter(n)
    r = reference(n, f0)
    y0 = periodic(T, r)
    if measured_loop:   # alpha / T_hat from the first trial
        learner = ilc.ILC(n, f0, 1500.0, alpha=0.5, loop=ilc.loop_response(r, y0, f0, 1500.0))
    else:               # only the lag: a pure phase lead
        learner = ilc.ILC(n, f0, 1500.0, alpha=0.5, lag_s=ilc.lag_from_trial(r, y0, f0, 1500.0))
    res = ilc.learn(lambda c: r - periodic(T, r + c), learner, 30)
    rms = [h["rms_um"] for h in res["history"]]
    assert res["refused"] == 0
    assert all(b < a for a, b in zip(rms, rms[1:]))           # every trial better
    assert res["best_rms_um"] < 1e-3 * res["first_rms_um"]


def test_growing_error_is_refused_and_the_best_correction_kept():
    n, f0 = 200, 50.0
    T = loop_filter(n)
    r = reference(n, f0)
    wrong = -ilc.loop_response(r, periodic(T, r), f0, 1500.0)   # the loop's sign the wrong way round
    learner = ilc.ILC(n, f0, 1500.0, alpha=0.8, loop=wrong, alpha_min=0.05)
    res = ilc.learn(lambda c: r - periodic(T, r + c), learner, 30)
    assert res["refused"] >= 1 and learner.stopped
    assert learner.alpha < 0.05
    # the kept correction is the one of the lowest error measured: never worse than none
    assert res["best_rms_um"] == min(h["rms_um"] for h in res["history"]) <= res["first_rms_um"]
    e_best = r - periodic(T, r + res["best"])
    assert np.sqrt(np.mean(e_best ** 2)) <= res["first_rms_um"] * (1 + 1e-9)
    # after a refusal the next trial plays the best correction again, learning half as fast
    h = res["history"]
    k = next(i for i, x in enumerate(h) if not x["accepted"])
    assert h[k + 1]["alpha"] == pytest.approx(h[k]["alpha"] / 2)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError):
        ilc.ILC(2, 50.0, 1000.0)
    with pytest.raises(ValueError):
        ilc.ILC(200, 50.0, 40.0)          # cut below the fundamental
    with pytest.raises(ValueError):
        ilc.ILC(200, 50.0, 1000.0, alpha=1.5)
    learner = ilc.ILC(200, 50.0, 1000.0)
    with pytest.raises(ValueError):
        learner.update(np.zeros(199))
    with pytest.raises(ValueError):
        ilc.ILC(200, 50.0, 1000.0, loop=np.ones(50))


def test_nothing_is_learned_above_the_cut():
    n, f0 = 1000, 10.0
    learner = ilc.ILC(n, f0, 300.0, alpha=1.0)
    e = np.sin(2 * np.pi * 50 * np.arange(n) / n)     # 500 Hz: above the cut
    learner.update(np.sin(2 * np.pi * 3 * np.arange(n) / n) + e)
    spec = np.fft.rfft(learner.correction())
    assert abs(spec[50]) < 1e-9 and abs(spec[3]) > 100


def test_table_entries_are_the_band_limited_correction_at_their_phases():
    n = 10000
    t = np.arange(n) / n
    c = 0.2 * np.cos(2 * np.pi * 3 * t) - 0.05 * np.sin(2 * np.pi * 200 * t)
    tab = ilc.table_entries(c, 1024)
    ti = np.arange(1024) / 1024
    want = 0.2 * np.cos(2 * np.pi * 3 * ti) - 0.05 * np.sin(2 * np.pi * 200 * ti)
    assert np.max(np.abs(tab - want)) < 1e-12


# ---------------------------------------------------------------- on the SIL controller

def test_learned_table_is_played_in_sync_and_bad_tables_are_refused(sil):  # noqa: F811
    from piezoctl.device import connect
    from piezoctl.errors import ControllerRefused
    ctl = connect(sil.spec)
    live = interface.INPUT_REGISTERS["wave_ff_n_live"][0]
    ctl.arm(False)
    ctl.command("clear_faults")
    ctl.set_mode("direct")          # the drive is the (corrected) reference itself
    ctl.arm(True)
    f0 = 100.0                      # 100 ticks a period
    ctl.configure_wave("triangle", offset_q15=0, amplitude_q15=0, f_hz=f0)   # a constant 0
    q_want = np.round(1000 * np.sin(2 * np.pi * np.arange(100) / 100))
    info = ilc.upload(ctl, q_want * ctl.scale.p_half / 32768, f0)
    assert info["n"] == 100 and info["clipped"] == 0
    assert ctl.client.read_input(live, 1)[0] == 100
    ctl.configure_recorder(["ff"], trigger="software")
    ctl.command("arm_recorder")
    ctl.command("start_wave")
    while ctl.status()["rec_state"] != 3:   # the buffer full (6.5 s of one signal)
        time.sleep(0.05)
    ctl.command("stop_wave")
    ff = ctl.read_recording(1)[:300, 0]
    # one entry a tick, from the wave's first sample on: the table itself, period after period
    assert np.array_equal(ff, np.tile(q_want, 3).astype(ff.dtype))
    # refused: too many entries, a zero frequency word; the played table stays
    base = interface.HOLDING_REGISTERS["wave_ff_n"][0]
    with pytest.raises(ControllerRefused):
        ctl.client.write_holding(base, [interface.HOLDING_REGISTERS["wave_ff_levels"][2] + 1, 0, 1, 1])
    with pytest.raises(ControllerRefused):
        ctl.client.write_holding(base, [50, 0, 0, 1])
    assert ctl.client.read_input(live, 1)[0] == 100
    ilc.switch_off(ctl)
    assert ctl.client.read_input(live, 1)[0] == 0
    ctl.arm(False)
