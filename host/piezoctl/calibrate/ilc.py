"""Iterative learning control (ILC) of a periodic reference, played by the firmware.

For a reference of period ``N`` ticks the controller adds a learned position
correction ``c`` to its loop's reference, in sync with the wave (the wave's
learned feedforward, ``wave_ff_*`` registers, ``firmware/control/controller.h``):
the feedforward sees ``r + c``, the feedback the error ``(r + c) - y``, the
recorder the true error ``e = r - y``. Then ``y = T (r + c)`` with ``T`` the
closed loop (feedforward inverse, preview, shaper, PI + notch), close to 1
where the learning acts, and trial ``j`` to ``j + 1`` does, per harmonic ``k``
of the period (the signals are periodic, so the filters are exact and
zero-phase in the period's DFT)::

    C[k] <- Q[k] (C[k] + alpha E[k] / T_hat[k])

- ``L = alpha / T_hat``: the learning gain times the inverse of the closed
  loop as measured in the first trial (``Y / R`` at the reference's own
  harmonics; between them interpolated, beyond them a pure lag fitted to
  their phase), ``|1 / T_hat|`` limited to ``gain_max``: a non-causal,
  phase-leading filter that only a periodic, recorded error allows. Or
  ``T_hat`` measured at every harmonic by playing a flat multisine as the
  correction (:func:`probe`, :func:`loop_from_probe`, the held axis of a
  two-axis stage), with its uncertainty ``sigma``: then the inverse is
  regularized, ``conj(T_hat) / (|T_hat|^2 + 4 sigma^2)``;
- ``Q``: a zero-phase low-pass, 1 up to ``0.8 f_cut`` and a raised cosine to 0
  at ``f_cut``, so the learning stays away from the resonance where ``T`` is
  not close to a delay; the correction has no content above ``f_cut``.

The error then shrinks by ``|1 - alpha T / T_hat|`` per trial at each
harmonic below ``f_cut``. Divergence guard: a trial whose RMS error (or the
caller's score, e.g. :func:`periodic_score`, within its uncertainty) grows more
than ``grow`` times the best so far is refused, the correction goes back to
the best one and ``alpha`` is halved; below ``alpha_min`` the learning stops.
The best correction is what is kept.
"""

from __future__ import annotations

import numpy as np

from .. import interface

__all__ = ["ILC", "learn", "probe", "loop_from_probe", "periodic_score", "loop_response", "lag_from_trial", "table_entries", "upload", "switch_off", "periodic_trial", "learn_on_controller"]

FF_MAX = interface.HOLDING_REGISTERS["wave_ff_levels"][2]   # the register map's; a target may hold fewer


def capacity(ctl) -> int:
    """Entries of the learned feedforward this controller holds (input ``wave_ff_capacity``)."""
    return int(ctl.client.read_input(interface.INPUT_REGISTERS["wave_ff_capacity"][0], 1)[0])


class ILC:
    """The learning state of one periodic reference.

    Parameters
    ----------
    n_samples : int
        Samples of one period in the recorded error (``N / decimation``).
    f0_hz : float
        The period's fundamental frequency [Hz].
    f_cut_hz : float
        Upper edge of the robustness filter ``Q`` [Hz]; nothing above is learned.
    alpha : float
        Learning gain, 0 < alpha <= 1 (1: the whole error per trial on ``T = 1``).
    lag_s : float
        Phase lead of the learning filter [s] (the closed loop's residual lag),
        where ``loop`` is not given.
    loop : array of complex, optional
        The closed loop ``T_hat`` at every harmonic ``0 .. n_samples // 2``
        (:func:`loop_response` or :func:`loop_from_probe`); the learning filter
        is ``alpha / T_hat``.
    loop_sigma : array of float, optional
        The standard deviation of each ``T_hat`` (:func:`loop_from_probe`): the
        inverse is regularized, ``conj(T_hat) / (|T_hat|^2 + 4 sigma^2)``, so a
        harmonic whose loop is not known better than its own size (near an
        antiresonance) is learned slowly instead of with a wrong phase.
    gain_max : float
        Largest ``|1 / T_hat|`` the learning filter applies.
    grow : float
        A trial whose RMS error exceeds ``grow`` times the best one is refused.
    alpha_min : float
        The learning stops once refusals halved ``alpha`` below this.
    """

    def __init__(self, n_samples: int, f0_hz: float, f_cut_hz: float, *, alpha: float = 0.5,
                 lag_s: float = 0.0, loop=None, loop_sigma=None, gain_max: float = 10.0, grow: float = 1.05,
                 alpha_min: float = 0.05):
        if n_samples < 4 or f0_hz <= 0 or f_cut_hz <= f0_hz or not 0 < alpha <= 1:
            raise ValueError("ILC needs >= 4 samples a period, f_cut above f0 and 0 < alpha <= 1")
        self.n = int(n_samples)
        self.f_hz = np.arange(self.n // 2 + 1) * f0_hz
        self.f_cut_hz = float(f_cut_hz)
        self.alpha = float(alpha)
        self.lag_s = float(lag_s)
        self.grow = float(grow)
        self.alpha_min = float(alpha_min)
        x = np.clip((self.f_hz - 0.8 * f_cut_hz) / (0.2 * f_cut_hz), 0.0, 1.0)
        self.q = np.where(self.f_hz < f_cut_hz, 0.5 * (1 + np.cos(np.pi * x)), 0.0)
        self.q[self.n // 2:] = 0.0   # no Nyquist line: it has no phase to lead
        if loop is None:
            self.inv = np.exp(2j * np.pi * self.f_hz * self.lag_s)
        else:
            loop = np.asarray(loop, dtype=complex)
            if loop.shape != self.f_hz.shape:
                raise ValueError(f"the loop response needs {self.f_hz.size} harmonics, not {loop.shape}")
            sig2 = 0.0 if loop_sigma is None else 4.0 * np.asarray(loop_sigma, dtype=float) ** 2
            mag = np.maximum((np.abs(loop) ** 2 + sig2) / np.maximum(np.abs(loop), 1e-300), 1.0 / gain_max)
            self.inv = np.exp(-1j * np.angle(loop)) / mag
        self.c_spec = np.zeros(self.n // 2 + 1, dtype=complex)
        self.best_spec = self.c_spec.copy()
        self.best_rms = np.inf
        self.best_se = 0.0
        self.history: list[dict] = []
        self.stopped = False

    def correction(self) -> np.ndarray:
        """The correction to play next, one sample per error sample [um]."""
        return np.fft.irfft(self.c_spec, n=self.n)

    def best(self) -> np.ndarray:
        """The correction of the lowest RMS error measured [um]."""
        return np.fft.irfft(self.best_spec, n=self.n)

    def update(self, e: np.ndarray, score: float | None = None, score_se: float = 0.0) -> bool:
        """Take the error ``e`` [um] measured with :meth:`correction` played; False if the trial is refused.

        ``score`` [um] is what the trials are compared by (default the RMS of
        ``e``; a caller whose ``e`` still carries noise passes the RMS of the
        part that repeats, :func:`periodic_score`), ``score_se`` the standard
        error of its square [um^2]: a trial is refused only when
        ``score^2 > grow^2 best^2 + 3 hypot(score_se, best's score_se)`` (near
        convergence a noisy score moves by more than ``grow`` from the noise alone).
        """
        e = np.asarray(e, dtype=np.float64)
        if e.shape != (self.n,):
            raise ValueError(f"the error must have {self.n} samples a period, not {e.shape}")
        rms = float(np.sqrt(np.mean(e ** 2)))
        score = rms if score is None else float(score)
        margin = 3.0 * float(np.hypot(score_se, self.best_se))
        accepted = score ** 2 <= (self.grow * self.best_rms) ** 2 + margin or not np.isfinite(self.best_rms)
        self.history.append({"rms_um": rms, "score_um": score, "alpha": self.alpha, "accepted": accepted})
        if not accepted:
            # the error grew: back to the best correction, learn more gently
            self.c_spec = self.best_spec.copy()
            self.alpha *= 0.5
            self.stopped = self.alpha < self.alpha_min
            return False
        if score < self.best_rms:
            self.best_rms, self.best_se, self.best_spec = score, float(score_se), self.c_spec.copy()
        self.c_spec = self.q * (self.c_spec + self.alpha * self.inv * np.fft.rfft(e))
        return True


def periodic_score(e_periods: np.ndarray) -> tuple[float, float]:
    """The RMS of what repeats in a record of whole periods (``P x n``, [um]) without
    the noise's bias, and the standard error of its square [um^2].

    The period mean's mean square holds the noise variance over ``P``; that is
    subtracted (the variance from the spread across periods). The standard
    error is the jackknife's over the periods (leave one out), which needs no
    assumption about the noise's spectrum.
    """
    e = np.asarray(e_periods, dtype=float)
    p = e.shape[0]
    if e.ndim != 2 or p < 3:
        raise ValueError(f"a periodic score needs at least 3 periods, not {e.shape}")

    def ms(x):
        k = x.shape[0]
        return float(np.mean(x.mean(axis=0) ** 2) - np.mean(np.var(x, axis=0, ddof=1)) / k)

    full = ms(e)
    jack = np.array([ms(np.delete(e, i, axis=0)) for i in range(p)])
    se_ms = float(np.sqrt((p - 1) / p * np.sum((jack - jack.mean()) ** 2)))
    return float(np.sqrt(max(full, 0.0))), se_ms


def lag_from_trial(r: np.ndarray, y: np.ndarray, f0_hz: float, f_max_hz: float) -> float:
    """The closed loop's lag [s]: the phase of ``Y / R`` against frequency at the
    reference's strong harmonics below ``f_max_hz``, fitted through the origin
    (weights ``|R|^2``); 0 when the reference has no such harmonics."""
    rs, ys = np.fft.rfft(r - np.mean(r)), np.fft.rfft(y - np.mean(y))
    f = np.arange(rs.size) * f0_hz
    w = np.abs(rs) ** 2
    sel = (f > 0) & (f <= f_max_hz) & (w > 1e-6 * w.max())
    if not np.any(sel):
        return 0.0
    phase = np.angle(ys[sel] / rs[sel])
    om = 2 * np.pi * f[sel]
    return float(max(0.0, -np.sum(w[sel] * phase * om) / np.sum(w[sel] * om ** 2)))


def loop_response(r: np.ndarray, y: np.ndarray, f0_hz: float, f_max_hz: float, *, rel: float = 1e-4):
    """The closed loop ``T = Y / R`` at every harmonic of one period (``r``, ``y``
    one period each, no correction played).

    Measured where the reference has a harmonic above ``rel`` of its largest
    (a triangle: the odd ones) and up to ``f_max_hz``; in between interpolated
    (magnitude, unwrapped phase); outside them a unit magnitude and the pure lag
    :func:`lag_from_trial` fits (a multitone's three tones say little beyond).
    """
    rs, ys = np.fft.rfft(r - np.mean(r)), np.fft.rfft(y - np.mean(y))
    f = np.arange(rs.size) * f0_hz
    lag = lag_from_trial(r, y, f0_hz, f_max_hz)
    model = np.exp(-2j * np.pi * f * lag)
    w = np.abs(rs)
    sel = (f > 0) & (f <= f_max_hz) & (w > rel * w.max())
    if np.count_nonzero(sel) < 2:
        return model
    ratio = ys[sel] / rs[sel] / model[sel]   # what the pure lag misses, interpolated between measured lines
    mag = np.interp(f, f[sel], np.abs(ratio))
    ph = np.interp(f, f[sel], np.unwrap(np.angle(ratio)))
    return model * mag * np.exp(1j * ph)


def probe(n_samples: int, f0_hz: float, f_max_hz: float, rms_um: float) -> np.ndarray:
    """One period of a flat multisine: every harmonic of ``f0_hz`` up to ``f_max_hz``
    (the odd and the even ones, Nyquist excluded) with one amplitude, total RMS
    ``rms_um`` [um], Schroeder's phases (``-pi k (k - 1) / K``: a low crest factor).

    Played as the learned correction, it measures the loop the correction goes
    through at every harmonic the learning acts on (:func:`loop_from_probe`);
    a triangle's harmonics fall as ``1 / k^2`` and leave the even ones out.
    """
    k = np.arange(1, (n_samples - 1) // 2 + 1)
    k = k[k * f0_hz <= f_max_hz]
    if k.size == 0:
        raise ValueError(f"no harmonic of {f0_hz:g} Hz up to {f_max_hz:g} Hz in {n_samples} samples")
    spec = np.zeros(n_samples // 2 + 1, dtype=complex)
    amp = rms_um * np.sqrt(2.0 / k.size)
    spec[k] = 0.5 * n_samples * amp * np.exp(-1j * np.pi * k * (k - 1) / k.size)
    return np.fft.irfft(spec, n=n_samples)


def loop_from_probe(e_periods: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The loop ``T`` (correction -> position) at every harmonic, and its standard
    deviation, from the error ``e = r - y`` [um] recorded over whole periods
    (``P x n``, indexed by the wave's sample) while the correction ``c`` (one
    period, [um], :func:`probe`) played and nothing else repeated: ``E = -T C``.

    Harmonics ``c`` has no content at get ``T = 0`` and an infinite deviation
    (the learning filter then leaves them alone).
    """
    e_periods = np.atleast_2d(np.asarray(e_periods, dtype=float))
    p, n = e_periods.shape
    if p < 2 or n != len(c):
        raise ValueError(f"need at least 2 periods of {len(c)} samples, not {e_periods.shape}")
    ep = np.fft.rfft(e_periods, axis=1)
    cs = np.fft.rfft(np.asarray(c, dtype=float))
    ok = np.abs(cs) > 1e-9 * np.abs(cs).max()
    t = np.zeros(cs.size, dtype=complex)
    sigma = np.full(cs.size, np.inf)
    t[ok] = -ep.mean(axis=0)[ok] / cs[ok]
    # the spread across periods: the noise of their mean
    sigma[ok] = np.sqrt(np.var(ep[:, ok], axis=0, ddof=1) / p) / np.abs(cs[ok])
    return t, sigma


def learn(trial, ilc: ILC, iterations: int) -> dict:
    """Run ``iterations`` trials: ``trial(c)`` plays the correction ``c`` [um, one
    value per error sample] and returns the error ``e = r - y`` [um] over one period,
    or ``(e, score, score_se)`` (:meth:`ILC.update`).

    Returns ``history`` (RMS [um], alpha, accepted per trial), ``best_rms_um``,
    ``first_rms_um``, ``best`` (the kept correction [um]) and ``refused`` (trials refused).
    """
    for _ in range(iterations):
        if ilc.stopped:
            break
        res = trial(ilc.correction())
        ilc.update(*res) if isinstance(res, tuple) else ilc.update(res)
    return {"history": ilc.history, "best_rms_um": ilc.best_rms, "first_rms_um": ilc.history[0]["rms_um"],
            "best": ilc.best(), "refused": sum(not h["accepted"] for h in ilc.history)}


# ---------------------------------------------------------------- on the controller

def table_entries(c_um: np.ndarray, n_entries: int) -> np.ndarray:
    """Resample one period of the band-limited correction ``c_um`` to ``n_entries``
    evenly spaced values (the firmware interpolates linearly between them) [um]."""
    spec = np.fft.rfft(c_um) * (n_entries / len(c_um))
    keep = n_entries // 2 + 1
    out = np.zeros(keep, dtype=complex)
    m = min(keep, spec.size)
    out[:m] = spec[:m]
    if n_entries % 2 == 0:
        out[-1] = out[-1].real
    return np.fft.irfft(out, n=n_entries)


def upload(ctl, c_um: np.ndarray, f_hz: float) -> dict:
    """Stage the correction (one period, [um]) in ``wave_ff_levels`` and commit it.

    At most the controller's :func:`capacity` entries: a longer period is
    resampled (:func:`table_entries`). Returns ``n`` (entries), ``clipped``
    (entries beyond the q15 range) and ``freq_word``.
    """
    from ..device import freq_word
    n = min(len(c_um), capacity(ctl))
    c = np.asarray(c_um, dtype=np.float64) if n == len(c_um) else table_entries(c_um, n)
    q = np.floor(c / ctl.scale.p_half * 32768.0 + 0.5)
    clipped = int(np.count_nonzero((q < -32768) | (q > 32767)))
    q = np.clip(q, -32768, 32767).astype(np.int64) & 0xFFFF
    base = interface.HOLDING_REGISTERS["wave_ff_levels"][0]
    step = 120   # registers a request (Modbus allows 123 in one FC 16)
    for k in range(0, n, step):
        ctl.client.write_holding(base + k, [int(v) for v in q[k:k + step]])
    fw = freq_word(f_hz, float(ctl.identity.tick_hz))
    # count, frequency word and the commit in one request (the firmware commits last)
    ctl.client.write_holding(interface.HOLDING_REGISTERS["wave_ff_n"][0],
                             [n, fw >> 16, fw & 0xFFFF, _FF_COMMIT])
    return {"n": n, "clipped": clipped, "freq_word": fw}


_FF_COMMIT = 1
_FF_OFF = 2


def switch_off(ctl) -> None:
    """Stop playing the learned feedforward."""
    ctl.client.write_holding(interface.HOLDING_REGISTERS["wave_ff_command"][0], [_FF_OFF])


def _decimation(n_ticks: int, frames_max: int) -> int:
    """The smallest divisor of the period [ticks] that fits one period in ``frames_max`` frames."""
    for d in range(1, n_ticks + 1):
        if n_ticks % d == 0 and n_ticks // d <= frames_max:
            return d
    return n_ticks


def _end_after(ctl, periods: int) -> None:
    """Let a triangle or sine end by itself one period after ``periods``: at the
    end of a period it is back at its offset, where ``stop_wave`` at a random
    phase steps the reference by up to its amplitude (on the 140 Hz stage a
    step that rang the mode into a sensor fault)."""
    ctl.write("wave_cycles", periods + 1)


def _stop(ctl, max_ticks: int = 30000) -> None:
    """Wait for a wave that ends by itself (cycles), then stop it anyway (a
    multisine has no cycles). The wait is counted in the controller's ticks
    (:func:`excitation.wait_wave_end`): until 2026-11-26 it was 3 s of the
    host's time, which a loaded host could spend before the wave's last period
    was played, and the stop then came at a random phase."""
    from .excitation import wait_wave_end
    kind = ctl.client.read_holding(interface.HOLDING_REGISTERS["wave_kind"][0], 1)[0]
    if kind in (interface.ENUMS["wave_kind"]["sine"], interface.ENUMS["wave_kind"]["triangle"]):
        wait_wave_end(ctl, max_ticks)
    ctl.command("stop_wave")


def periodic_trial(ctl, n_ticks: int, *, periods: int, settle_periods: int = 1, decimation: int = 1,
                   preview_ticks: int = 0, rms_all: list | None = None) -> np.ndarray:
    """Start the loaded wave, record ``ref`` and ``y``; the error ``r - y`` [um]
    averaged over ``periods`` whole periods after ``settle_periods``, indexed by
    the wave's own sample (the recorder sees the reference ``preview_ticks`` late)."""
    m = n_ticks // decimation
    frames = m * (periods + settle_periods)
    _end_after(ctl, periods + settle_periods)
    cols = ctl.capture(["ref", "y"], frames, decimation=decimation, trigger="software", start_wave=True)
    _stop(ctl)
    e_all = (cols["ref"] - cols["y"])[settle_periods * m:].reshape(periods, m)
    if rms_all is not None:
        rms_all.append(float(np.sqrt(np.mean(e_all ** 2))))
    e = e_all.mean(axis=0)
    # recorded sample i is wave sample i - preview: shift back (exactly, in the period's DFT)
    spec = np.fft.rfft(e) * np.exp(2j * np.pi * np.arange(m // 2 + 1) * preview_ticks / n_ticks)
    return np.fft.irfft(spec, n=m)


def learn_on_controller(ctl, f0_hz: float, *, preview_ticks: int, f_cut_hz: float, iterations: int = 8,
                        alpha: float = 0.5, periods: int = 1, say=None) -> dict:
    """Learn the correction of the wave loaded in ``ctl`` (armed, its mode and
    feedback set), period ``1 / f0_hz``, and leave the best one committed.

    ``f_cut_hz`` is lowered to 0.4 x the controller's table entries x ``f0_hz``
    (the table's own band). Returns :func:`learn`'s result plus ``lag_s``,
    ``decimation``, ``n_entries``, ``f_cut_hz``.
    """
    tick = float(ctl.identity.tick_hz)
    f_cut_hz = min(f_cut_hz, 0.4 * capacity(ctl) * f0_hz)
    n_ticks = int(round(tick / f0_hz))
    from .excitation import settle_periods
    settle = settle_periods(f0_hz)
    dec = _decimation(n_ticks, ctl.identity.rec_capacity // 2 // (periods + settle))
    m = n_ticks // dec
    switch_off(ctl)
    # the first trial without correction also gives the loop's response at the wave's harmonics
    _end_after(ctl, periods + settle)
    cols = ctl.capture(["ref", "y"], m * (periods + settle), decimation=dec, trigger="software", start_wave=True)
    _stop(ctl)
    r = cols["ref"][settle * m:].reshape(periods, m).mean(axis=0)
    y = cols["y"][settle * m:].reshape(periods, m).mean(axis=0)
    lag = lag_from_trial(r, y, f0_hz, f_cut_hz)
    ilc = ILC(m, f0_hz, f_cut_hz, alpha=alpha, loop=loop_response(r, y, f0_hz, f_cut_hz))
    first = True
    rms_all = [float(np.sqrt(np.mean((cols["ref"] - cols["y"])[settle * m:] ** 2)))]

    def trial(c):
        nonlocal first
        if first:   # already measured above (c = 0)
            first = False
            spec = np.fft.rfft(r - y) * np.exp(2j * np.pi * np.arange(m // 2 + 1) * preview_ticks / n_ticks)
            return np.fft.irfft(spec, n=m)
        upload(ctl, c, f0_hz)
        e = periodic_trial(ctl, n_ticks, periods=periods, settle_periods=settle, decimation=dec,
                           preview_ticks=preview_ticks, rms_all=rms_all)
        if ctl.status()["faults"]:
            # the correction rang the stage past its sensor: a failed trial (its error, the
            # disarmed stage's, is large: refused), and the controller armed again
            ctl.arm(False)
            ctl.command("clear_faults")
            ctl.arm(True)
            e = np.full_like(e, 1e3 * max(1.0, float(np.sqrt(np.mean(e ** 2)))))
        if say:
            say(f"  trial {len(ilc.history) + 1}: {np.sqrt(np.mean(e ** 2)) * 1e3:.1f} nm RMS")
        return e

    res = learn(trial, ilc, iterations)
    info = upload(ctl, res["best"], f0_hz)
    res.update({"rms_all_um": rms_all, "lag_s": lag, "decimation": dec, "n_entries": info["n"], "clipped": info["clipped"],
                "f_cut_hz": f_cut_hz})
    return res
