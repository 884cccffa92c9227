"""host/pyproject.toml gives ranges, host/requirements.lock pins the whole venv
with hashes (issue 16, part 7)."""

from __future__ import annotations

import importlib.metadata as md
import pathlib
import re
import tomllib

ROOT = pathlib.Path(__file__).resolve().parents[2]
LOCK = ROOT / "host" / "requirements.lock"


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _lock() -> dict[str, tuple[str, int]]:
    """name -> (version, number of hashes) of every requirement in the lock."""
    out, name = {}, None
    for line in LOCK.read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==([^ ;\\]+)", line)
        if m:
            name = _norm(m.group(1))
            out[name] = (m.group(2), 0)
        elif name and "--hash=sha256:" in line:
            out[name] = (out[name][0], out[name][1] + 1)
    return out


def _project() -> dict:
    return tomllib.loads((ROOT / "host" / "pyproject.toml").read_text())["project"]


def test_runtime_dependencies_are_ranges_without_test_tools():
    deps = _project()["dependencies"]
    names = {_norm(re.split(r"[<>=!~ ;\[]", d)[0]) for d in deps}
    assert {"numpy", "scipy", "matplotlib", "pymodbus", "pyserial", "pyusb"} == names
    assert all(">=" in d and "<" in d for d in deps), deps          # a range, not a pin or nothing
    extras = _project()["optional-dependencies"]
    assert [_norm(d.split(">")[0]) for d in extras["test"]] == ["pytest"]
    assert [_norm(d.split(">")[0]) for d in extras["bench"]] == ["scikit-rf"]


def test_lock_pins_every_package_with_hashes():
    lock = _lock()
    assert lock, "empty lock"
    assert all(n >= 1 for _, n in lock.values()), [k for k, (_, n) in lock.items() if n == 0]
    text = LOCK.read_text()
    assert "--find-links" not in text and "--index-url" not in text   # no machine-specific sources


def test_lock_covers_the_venv():
    """Every distribution installed in this venv (but pip's own tools and the
    package itself) is pinned in the lock at the installed version: nothing floats."""
    lock = _lock()
    own = {"piezoctl", "pip", "setuptools", "wheel"}
    installed = {_norm(d.metadata["Name"]): d.version for d in md.distributions()}
    missing = {n: v for n, v in installed.items() if n not in own and n not in lock}
    differ = {n: (v, lock[n][0]) for n, v in installed.items() if n in lock and lock[n][0] != v}
    assert not missing, f"installed but not in the lock: {missing}"
    assert not differ, f"installed version differs from the lock: {differ}"
    requires = {_norm(re.split(r"[<>=!~ ;\[]", r)[0]) for r in md.requires("piezoctl") or []
                if "extra ==" not in r}
    assert requires <= set(lock)
