"""Time and memory of the diagnosis at full length: ``tools/bench-diagnose-speed`` (docs/diagnose-speed.md).

Runs ``diagnose()`` on one full-length foreign case (default: seed 0, case 17, scale 1: 113 s of 10 kHz data)
in a fresh process and prints its wall and CPU seconds, its peak resident MiB and the Python stack at which the
resident size peaked (a thread samples ``/proc/self/statm`` every 20 ms). Then times the numerical kernels of
``models.hysteresis``, ``models.play`` and ``dsp`` on 1.13 M samples (median of ``--repeat`` runs).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
import traceback

import numpy as np

__all__ = ["main"]

N_SAMPLES = 1_130_000   # the length of case s0-017's data at scale 1 (113 s at 10 kHz)


def _rss_mib() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


class _PeakWatcher(threading.Thread):
    """Samples the resident size; keeps the main thread's stack at the largest sample."""

    def __init__(self, period_s: float = 0.02):
        super().__init__(daemon=True)
        self.period_s = period_s
        self.peak = 0.0
        self.stack: list = []
        self.at_peak: dict = {}
        self.main_id = threading.main_thread().ident
        self._halt = threading.Event()

    def run(self):
        while not self._halt.wait(self.period_s):
            rss = _rss_mib()
            if rss > self.peak:
                self.peak = rss
                frame = sys._current_frames().get(self.main_id)
                self.stack = traceback.format_stack(frame) if frame is not None else []
                if getattr(self, "designs", None) is not None:
                    self.at_peak = {"design_mib": self.designs.live / 2 ** 20, "designs_made": self.designs.count,
                                    "state_cache_mib": sum(x.nbytes for e in list(self.cache.values())
                                                           for x in (e if isinstance(e, tuple) else (e,))) / 2 ** 20}

    def stop(self):
        self._halt.set()
        self.join()


def _case_files(d: str) -> tuple[list, list]:
    cal = sorted(glob.glob(os.path.join(d, "cal*.csv")))
    rev = sorted(glob.glob(os.path.join(d, "rev*.csv")))
    if not cal or not rev:
        raise SystemExit(f"bench-diagnose-speed: no cal*.csv and rev*.csv in {d}")
    return cal, rev


class _DesignBytes:
    """Live bytes of the diagnosis' cached regressor designs (``diagnose.select._Design``, when it exists):
    counted at construction, released by a weakref finalizer. Attribution only (``--attribute``)."""

    def __init__(self):
        self.live = 0
        self.count = 0
        self.max = 0
        try:
            from ..diagnose import select
        except ImportError:
            return
        cls = getattr(select, "_Design", None)
        if cls is None:
            return
        import weakref
        init = cls.__init__
        me = self

        def wrapped(obj, *a, **k):
            init(obj, *a, **k)
            nb = getattr(obj, "own_nbytes", None)   # round 21: columns shared with the term's first design
            if nb is None:                           # are that design's (counted once)
                nb = int(sum(v.nbytes for v in vars(obj).values() if isinstance(v, np.ndarray)))
            me.live += nb
            me.count += 1
            me.max = max(me.max, me.live)
            weakref.finalize(obj, me._free, nb)
        cls.__init__ = wrapped

    def _free(self, nb):
        self.live -= nb


def _evict_designs_after_each_term() -> bool:
    """Experiment (``--evict-designs``), not the tool's behaviour: empty the contexts' design caches after each
    term's evaluation (``diagnose.select._evaluate``), to measure what the cache of every term's every setting
    costs in memory and saves in time. False when the diagnosis has no such function (a later tree)."""
    try:
        from ..diagnose import select
    except ImportError:
        return False
    ev = getattr(select, "_evaluate", None)
    if ev is None:
        return False

    def wrapped(ctxs, *a, **k):
        try:
            return ev(ctxs, *a, **k)
        finally:
            for c in ctxs:
                getattr(c, "design_cache", {}).clear()
    select._evaluate = wrapped
    return True


def _child(case_dir: str, out_dir: str, attribute: bool = False, evict: bool = False, profile: str | None = None) -> None:
    """Runs the diagnosis once in this process; prints one JSON line. ``profile``: write a cProfile of the
    diagnosis there, timed on the process' CPU clock (``time.process_time``: the other core's load and the
    waits do not count), and print its 25 largest own times before the JSON line."""
    from ..diagnose.run import diagnose
    from ..models import hysteresis
    cal, rev = _case_files(case_dir)
    if evict and not _evict_designs_after_each_term():
        raise SystemExit("bench-diagnose-speed: --evict-designs: no diagnose.select._evaluate in this tree")
    designs = _DesignBytes() if attribute else None
    w = _PeakWatcher()
    w.designs = designs
    w.cache = hysteresis._STATE_CACHE
    w.start()
    prof = None
    if profile:
        import cProfile
        prof = cProfile.Profile(time.process_time)
    t0, c0 = time.perf_counter(), time.process_time()
    if prof is not None:
        prof.enable()
    doc = diagnose(cal, rev, out_dir, report=False, log=lambda *a, **k: None)
    if prof is not None:
        prof.disable()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if prof is not None:
        import pstats
        prof.dump_stats(profile)
        pstats.Stats(prof, stream=sys.stdout).sort_stats("tottime").print_stats(25)
    w.stop()
    h = doc.get("fit", {}).get("heldout", {})
    stack = [s for s in w.stack if "piezoctl" in s or "numpy" in s or "scipy" in s]
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "sampled_peak_mib": w.peak, "stack": stack, "named": doc.get("named"), "at_peak": w.at_peak,
                      "design_max_mib": designs.max / 2 ** 20 if designs else None,
                      "base_nrmse": h.get("base_nrmse"), "refined_nrmse": h.get("refined_nrmse")}))


def _make_case(seed: int, index: int, scale: float, root: str, n: int = 20) -> str:
    """Writes foreign case ``index`` of an ``n``-case plan (``tools/bench-diagnose --foreign --n n``)."""
    from ..foreign.cases import case_plan, draw_case, write_case
    plan = case_plan(max(n, index + 1))
    case = draw_case(seed, index, plan[index], scale=scale)
    d = os.path.join(root, case.case_id)
    write_case(case, d)
    return d


def _median_time(fn, repeat: int) -> float:
    """Median seconds of ``repeat`` calls; nan when the kernel does not take these arguments (an older tree)."""
    try:
        fn()
    except TypeError:
        return float("nan")
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def _kernel_inputs(n: int = N_SAMPLES, seed: int = 0, noise: float = 0.0):
    """A normalized drive like the recordings of a case, within [-1, 1]: a random walk (piecewise-constant
    velocity), triangles, a decaying sine, a chirp from 5 to 500 Hz (runs of 10 samples at its end) and steps,
    plus white noise of ``noise`` RMS. The recorded drives carry no noise: their monotone runs are hundreds of
    samples long; noise makes them one or two samples long."""
    rng = np.random.default_rng(seed)
    q = n // 5
    t = np.arange(q) / 1e4
    walk = np.cumsum(np.repeat(rng.normal(0, 1.0, q // 2000 + 1), 2000)[:q])
    walk = 0.9 * walk / max(1e-9, np.max(np.abs(walk)))
    tri = 0.9 * (2 * np.abs(2 * ((t * 1.0) % 1.0) - 1) - 1)
    sine = 0.9 * np.exp(-t / 10) * np.sin(2 * np.pi * 5 * t)
    chirp = 0.5 * np.sin(2 * np.pi * (5 * t + 0.5 * (495 / t[-1]) * t ** 2))
    steps = np.repeat(rng.uniform(-0.9, 0.9, (n - 4 * q + 499) // 500), 500)[:n - 4 * q]
    return np.concatenate([walk, tri, sine, chirp, steps]) + (rng.normal(0, noise, n) if noise else 0.0)


def _plane_hp(n_plays: int = 16, n_knots: int = 20, seed: int = 1) -> dict:
    """A ``plane`` operator with the base's layout (play thresholds 0..0.9, evenly spaced knots over each
    play's output span) and random knot values."""
    rng = np.random.default_rng(seed)
    r = np.linspace(0.0, 0.9, n_plays)
    knots = [np.linspace(-1.0 + ri, 1.0 - ri, max(2, int(n_knots * (2 - 2 * ri) / 2) + 1)).tolist() for ri in r]
    values = [np.concatenate([[0.0], np.cumsum(rng.uniform(0.0, 2.0, len(k) - 1))]).tolist() for k in knots]
    return {"type": "plane", "r": r.tolist(), "knots": knots, "values": values, "v_rest": 0.0,
            "bw": {"beta": 3.0, "gamma": 1.0, "c_h": 0.5}}


def kernel_timings(repeat: int = 3) -> list:
    """(name, median seconds) of each kernel on N_SAMPLES samples."""
    from .. import dsp
    from ..models import hysteresis as hy
    from ..models.play import play_outputs
    v = _kernel_inputs()
    vn = _kernel_inputs(noise=1e-4)
    hp = _plane_hp()
    r = np.asarray(hp["r"])
    rows = []
    rows.append(("play_outputs, 16 classical plays", _median_time(lambda: play_outputs(v, r), repeat)))
    rows.append(("play_outputs, 16 classical plays, column-major",
                 _median_time(lambda: play_outputs(v, r, order="F"), repeat)))
    rows.append(("play_outputs, 16 classical plays, drive with 1e-4 noise",
                 _median_time(lambda: play_outputs(vn, r), repeat)))
    rows.append(("play_outputs, 16 unparallel plays (a = 0.9)",
                 _median_time(lambda: play_outputs(v, r, a=0.9), repeat)))
    rows.append(("play_outputs, 40 unparallel plays, varied a (was a 5 s test limit on 300k samples)",
                 _median_time(lambda: play_outputs(v, np.linspace(0, 0.9, 40), a=np.linspace(0.5, 1.5, 40)),
                              repeat)))
    from ..models import kp as fkp
    g10 = fkp.kp_grid(10)
    vk = np.clip(vn / max(1.0, float(np.max(np.abs(vn)))), -1.0, 1.0)
    rows.append(("kp_outputs, 55 KP operators (L = 10), drive with 1e-4 noise (was a 4 s test limit on 300k)",
                 _median_time(lambda: fkp.kp_outputs(vk, g10), repeat)))
    kn, vals = hp["knots"][3], hp["values"][3]
    rows.append(("interp_linear_ext, 17 even knots", _median_time(lambda: hy.interp_linear_ext(v, kn, vals), repeat)))
    kn_u = np.sort(np.concatenate([[-1.0, 1.0], np.random.default_rng(2).uniform(-1, 1, 15)]))
    rows.append(("interp_linear_ext, 17 uneven knots",
                 _median_time(lambda: hy.interp_linear_ext(v, kn_u, vals), repeat)))
    rows.append(("hat_basis, 17 even knots", _median_time(lambda: hy.hat_basis(v, kn), repeat)))
    rows.append(("state cache key + store (old: BLAKE2b; new: CRC-32, copy)",
                 _median_time(lambda: hy._cached_state("bench", (), v, lambda x: x[:1].copy()), repeat)))

    # the operator per recording (the diagnosis' longest, rev0 of s0-017, has 444,865 samples; this stretch
    # holds the end of the decaying sine, the chirp and the steps)
    vr = v[-444_865:]

    def cold():
        hy._STATE_CACHE.clear()
        return hy.plane_parts(hp, vr)
    rows.append(("plane_parts, 16 plays + Bouc-Wen, 445 k samples, cold", _median_time(cold, repeat)))
    hy.plane_parts(hp, vr)
    rows.append(("plane_parts, 445 k samples, cached states", _median_time(lambda: hy.plane_parts(hp, vr), repeat)))
    rows.append(("hysteresis_groups, 445 k samples, cached states",
                 _median_time(lambda: hy.hysteresis_groups(hp, vr), repeat)))
    hy._STATE_CACHE.clear()
    u = 50.0 + 50.0 * v
    step = float(np.quantile(np.abs(np.diff(u)), 0.999)) * 0.1
    rows.append((f"slew_limit, acts on {100 * np.mean(np.abs(np.diff(dsp.slew_limit(u, step))) >= step * 0.999):.1f} % "
                 "of samples", _median_time(lambda: dsp.slew_limit(u, step), repeat)))
    step2 = float(np.max(np.abs(np.diff(u)))) * 0.03
    rows.append((f"slew_limit, acts on {100 * np.mean(np.abs(np.diff(dsp.slew_limit(u, step2))) >= step2 * 0.999):.1f} % "
                 "of samples", _median_time(lambda: dsp.slew_limit(u, step2), repeat)))
    rows.append(("lowpass (lfilter)", _median_time(lambda: dsp.lowpass(u, 100.0, 1e-4), repeat)))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench-diagnose-speed", description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", default=None, help="a case directory with cal*.csv and rev*.csv (default: generate)")
    ap.add_argument("--seed", type=int, default=0, help="foreign case seed (default 0)")
    ap.add_argument("--index", type=int, default=17, help="foreign case index (default 17: thermal drift)")
    ap.add_argument("--n", type=int, default=20,
                    help="cases in the plan the index refers to (default 20, as the development runs of round 5)")
    ap.add_argument("--scale", type=float, default=1.0, help="foreign case duration factor (default 1)")
    ap.add_argument("--keep", default=None, help="write the generated case and the output here")
    ap.add_argument("--repeat", type=int, default=3, help="runs per kernel timing (median; default 3)")
    ap.add_argument("--no-kernels", action="store_true", help="the diagnosis only")
    ap.add_argument("--no-diagnose", "--kernels-only", dest="no_diagnose", action="store_true",
                    help="the kernels only")
    ap.add_argument("--attribute", action="store_true",
                    help="also count the live bytes of the diagnosis' cached designs and of the state cache")
    ap.add_argument("--evict-designs", action="store_true",
                    help="experiment: empty the diagnosis' design caches after each term's evaluation")
    ap.add_argument("--busy", action="store_true",
                    help="keep the other core busy during the diagnosis (a niced busy loop, as the goal says)")
    ap.add_argument("--profile", default=None, metavar="FILE",
                    help="write a cProfile of the diagnosis (CPU-time clock) to FILE and print its largest own times")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--child-out", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        _child(a.child, a.child_out, a.attribute, a.evict_designs, a.profile)
        return 0
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
    load = os.getloadavg()[0]
    print(f"bench-diagnose-speed at {commit or '?'}, load average {load:.1f} on {os.cpu_count()} cores", flush=True)
    if not a.no_diagnose:
        root = a.keep or tempfile.mkdtemp(prefix="bench-diagnose-speed-")
        d = a.case or _make_case(a.seed, a.index, a.scale, root, a.n)
        cal, rev = _case_files(d)
        n = 0
        for p in cal + rev:
            with open(p) as f:
                n += sum(1 for _ in f) - 1
        print(f"case {d}: {len(cal)} calibration + {len(rev)} reveal recordings, {n} samples "
              f"({n / 1e4:.0f} s at 10 kHz)", flush=True)
        out = os.path.join(root, "out")
        busy = None
        if a.busy:   # one niced busy loop: "the other core busy" of issue 12 item 6
            busy = subprocess.Popen([sys.executable, "-c", "while True: pass"], preexec_fn=lambda: os.nice(19))
        try:
            p = subprocess.run([sys.executable, "-m", "piezoctl.bench.diagnose_speed", "--child", d, "--child-out", out]
                               + (["--attribute"] if a.attribute else []) + (["--evict-designs"] if a.evict_designs else [])
                               + (["--profile", os.path.abspath(a.profile)] if a.profile else []),
                               capture_output=True, text=True)
        finally:
            if busy is not None:
                busy.kill()
                busy.wait()
        if p.returncode != 0:
            print(p.stderr[-3000:], file=sys.stderr)
            return 3
        lines = p.stdout.strip().splitlines()
        if a.profile:
            print("\n".join(lines[:-1]))
        res = json.loads(lines[-1])
        print(f"diagnose: {res['wall_s']:.1f} s wall ({100 * res['wall_s'] / max(n / 1e4, 1e-9):.1f} s per 100 s of "
              f"data{', the other core busy' if a.busy else ''}), {res['cpu_s']:.1f} s CPU "
              f"({100 * res['cpu_s'] / max(n / 1e4, 1e-9):.1f} s per 100 s of data), peak resident "
              f"{res['peak_rss_mib']:.0f} MiB (goal 60 s per 100 s of data, 2048 MiB); named "
              f"{','.join(res['named'] or ['none'])}, held-out NRMSE {res['base_nrmse']:.5f} -> "
              f"{res['refined_nrmse']:.5f}", flush=True)
        print(f"stack at the sampled peak ({res['sampled_peak_mib']:.0f} MiB):")
        for s in res["stack"][-8:]:
            print("  " + s.strip().replace("\n", " | "))
        if a.attribute:
            pk = res.get("at_peak") or {}
            print(f"at the peak: cached designs (diagnose.select._Design) {pk.get('design_mib', float('nan')):.0f} MiB "
                  f"({pk.get('designs_made', 0)} made so far), state cache {pk.get('state_cache_mib', float('nan')):.0f} "
                  f"MiB; cached designs at most {res.get('design_max_mib') or float('nan'):.0f} MiB")
    if not a.no_kernels:
        print(f"\nkernels on {N_SAMPLES} samples (median of {a.repeat}):", flush=True)
        for name, s in kernel_timings(a.repeat):
            print(f"  {name:55s} {1000 * s:9.1f} ms", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
