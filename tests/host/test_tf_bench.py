"""tools/bench-tf: the comparison table, the claim check, a clear failure without scikit-rf."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from piezoctl.bench import tf as bench
from piezoctl.ident import tf

TOP = Path(__file__).resolve().parents[2]


def test_noisy_response_is_the_papers_model_with_the_stated_noise():
    w, h0, h = bench.noisy_response(0.02, 3)
    assert w.size == 200 and np.isclose(w[0], 2 * np.pi * 0.01) and np.isclose(w[-1], 2 * np.pi * 50)
    np.testing.assert_allclose(h0, tf.freqresp(bench.B_PAPER, bench.A_PAPER, w))
    rel = (h - h0) / h0
    assert 0.015 < np.sqrt(np.mean(np.abs(rel) ** 2)) < 0.025  # E|n|^2 = sigma^2
    _, _, again = bench.noisy_response(0.02, 3)
    np.testing.assert_array_equal(h, again)


def test_run_gives_every_method_and_the_claim_on_one_seed():
    pytest.importorskip("skrf")
    rows = bench.run(levels=(0.02,), seeds=1)
    assert [r["method"] for r in rows] == list(bench.METHODS)
    got = {r["method"]: r for r in rows}
    assert got["pso-wcls"]["te_true"] <= 0.005 and got["pso-wcls"]["stable"] == 1.0
    assert got["pso-wcls, paper"]["te_true"] > 0.01
    assert all(r["ms"] > 0 and r["te_data"] > 0 for r in rows)
    ok, line = bench.check_claim(rows)
    assert ok and line.startswith("claim holds: pso-wcls at 2 % noise")
    table = bench.markdown(rows)
    assert table.splitlines()[0].startswith("| noise | method | Te vs truth (median)")
    assert len([ln for ln in table.splitlines() if ln.startswith("| 2 %")]) == len(bench.METHODS)


def test_main_fails_when_the_claim_fails(monkeypatch, capsys):
    pytest.importorskip("skrf")
    monkeypatch.setattr(bench, "TE_CLAIM", 1e-9)
    assert bench.main(["--seeds", "1", "--levels", "0.02"]) == 1
    assert "claim FAILS" in capsys.readouterr().out


def test_main_without_scikit_rf_is_one_clear_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "skrf", None)  # import skrf raises ImportError
    assert bench.main(["--seeds", "1"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1
    assert err.startswith("bench-tf: error: scikit-rf is not installed") and "tools/setup" in err


def test_tool_script_prints_the_table_and_the_claim():
    pytest.importorskip("skrf")
    r = subprocess.run([str(TOP / "tools" / "bench-tf"), "--seeds", "1", "--levels", "0.02"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "| 2 % | pso-wcls | " in r.stdout and "claim holds" in r.stdout
    assert "noise 2 %" in r.stderr  # progress on stderr
