"""Start-up time of the CLI: ``piezoctl --help`` and ``piezoctl COMMAND --help``.

``tools/bench-cli [--runs N] [--budget S]`` runs each command line N times
(default 5) as a fresh process (``python -m piezoctl.cli``, as
``tools/piezoctl`` does) and prints, per command line, the median and the
largest wall time [s], the heavy libraries the process imported (numpy,
scipy, matplotlib, pymodbus) and whether the median is within the budget
(default 0.5 s). Exit status 1 if any median is over the budget.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

__all__ = ["HEAVY", "command_lines", "time_command", "main"]

HEAVY = ("numpy", "scipy", "matplotlib", "pymodbus")

# Runs the CLI like tools/piezoctl and reports, at exit, which heavy libraries were imported.
_PROBE = ("import atexit, sys\n"
          "atexit.register(lambda: sys.stderr.write('\\nHEAVY:' + ','.join(m for m in %r if m in sys.modules)))\n"
          "from piezoctl.cli import main\n"
          "sys.exit(main(sys.argv[1:]))\n") % (HEAVY,)


def command_lines() -> list[list[str]]:
    """``[]`` (the top level) and ``[COMMAND]`` for every command, each followed by ``--help``."""
    from ..cli import build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    return [["--help"]] + [[name, "--help"] for name in sorted(sub.choices)]


def time_command(argv: list[str], runs: int) -> tuple[list[float], str]:
    """Wall times [s] of ``runs`` fresh processes of ``piezoctl ARGV``, and the heavy modules imported."""
    times, heavy = [], ""
    for _ in range(runs):
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-c", _PROBE, *argv], capture_output=True, text=True)
        times.append(time.perf_counter() - t0)
        if p.returncode != 0:
            raise SystemExit(f"bench-cli: piezoctl {' '.join(argv)} exited {p.returncode}: {p.stderr.strip()}")
        heavy = p.stderr.rpartition("HEAVY:")[2].strip()
    return times, heavy


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="tools/bench-cli", description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5, help="processes per command line (default 5)")
    ap.add_argument("--budget", type=float, default=0.5, help="largest median [s] (default 0.5)")
    args = ap.parse_args(argv)
    if args.runs < 1:
        ap.error("--runs must be >= 1")
    print(f"piezoctl start-up, median of {args.runs} fresh processes ({sys.executable})")
    print(f"{'command line':32s} {'median s':>9s} {'max s':>7s}  {'heavy imports':28s} budget {args.budget:g} s")
    over = 0
    for cmd in command_lines():
        times, heavy = time_command(cmd, args.runs)
        med = statistics.median(times)
        ok = med <= args.budget
        over += not ok
        print(f"{'piezoctl ' + ' '.join(cmd):32s} {med:9.3f} {max(times):7.3f}  {heavy or '-':28s} "
              f"{'ok' if ok else 'OVER'}")
    print(f"{over} command line(s) over {args.budget:g} s")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
