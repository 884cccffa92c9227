"""tools/diff-diagnosis (``piezoctl.bench.diff_diagnosis``): what it calls equal and what it reports."""

import json

from piezoctl.bench.diff_diagnosis import compare, main

DOC = {"named": ["delay"], "time_s": 12.0, "calibration": ["/a/case/cal0.csv"],
       "effects": [{"name": "delay", "ratio": 0.5, "p": 1e-6, "significant": True, "setting": [3, 4]}]}


def _doc(**changes):
    d = json.loads(json.dumps(DOC))
    d["effects"][0].update(changes)
    return d


def test_equal_within_tolerance_and_time_and_directories_ignored():
    b = _doc(ratio=0.5 * (1 + 1e-12))
    b["time_s"] = 99.0
    b["calibration"] = ["/elsewhere/cal0.csv"]
    r = compare(DOC, b)
    assert not r["struct"] and not r["beyond"] and r["n_numbers_differ"] == 1 and 0 < r["max_rel"] < 1e-11


def test_reports_numbers_beyond_tolerance_and_other_differences(tmp_path, capsys):
    b = _doc(ratio=0.5001, significant=False, setting=[3])
    b["named"] = ["none"]
    r = compare(DOC, b)
    assert [x[1] for x in r["beyond"]] == ["/effects[0]/ratio"]
    assert len(r["struct"]) == 3     # the name, the bool, the list's length
    pa, pb = tmp_path / "a.json", tmp_path / "b.json"
    pa.write_text(json.dumps(DOC))
    pb.write_text(json.dumps(b))
    assert main([str(pa), str(pb)]) == 1
    assert main([str(pa), str(pa)]) == 0
    assert main([str(pa), str(tmp_path / "missing.json")]) == 2
    assert "1 beyond 1e-09" in capsys.readouterr().out
