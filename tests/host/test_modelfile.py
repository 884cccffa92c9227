"""MODEL.json: versioned format, provenance, checks on load (piezoctl.io.modelfile)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from piezoctl import __version__
from piezoctl.errors import CliError
from piezoctl.io.modelfile import (FORMAT, VERSION, ModelFileError, changed_data, file_sha256,
                                   load_model, make_provenance, save_model)


@pytest.fixture
def data_file(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text("t,u,y\n0,0,0\n1,1,1\n")
    return p


def test_round_trip_and_provenance(tmp_path, data_file):
    prov = make_provenance([str(data_file)], {"kp_levels": 10}, nrmse=[0.0123], rows=[2],
                           metrics={"time_s": 0.5})
    params = {"u_min": -1.0, "u_max": 1.0, "L": np.int64(2), "nmin": -1.0, "nmax": 1.0, "s": 1.0, "N": 3,
              "w": np.arange(3.0), "offset": 0.0, "nested": {"a": np.float32(0.5)}}
    out = tmp_path / "m.json"
    save_model(out, "kp", params, prov)
    doc = json.loads(out.read_text())
    assert doc["format"] == FORMAT == "piezoctl-model" and doc["version"] == VERSION == 1
    m = load_model(out)
    assert m.kind == "kp" and m.version == 1
    assert m.params["w"] == [0.0, 1.0, 2.0] and m.params["L"] == 2 and m.params["nested"] == {"a": 0.5}
    d = m.provenance["data"][0]
    assert d["sha256"] == hashlib.sha256(data_file.read_bytes()).hexdigest()
    assert d["rows"] == 2 and d["nrmse"] == pytest.approx(0.0123)
    assert m.provenance["tool_version"] == __version__
    assert m.provenance["options"] == {"kp_levels": 10}
    assert m.provenance["created"].endswith("Z")
    assert changed_data(m) == []
    data_file.write_text("t,u,y\n0,0,0\n1,1,2\n")
    assert changed_data(m) == [str(data_file)]


def test_save_refuses_nan_and_unknown_kind(tmp_path, data_file):
    prov = make_provenance([str(data_file)], {})
    with pytest.raises(ModelFileError, match=r"params\.w\[1\]"):
        save_model(tmp_path / "m.json", "kp", {"w": [1.0, float("nan")]}, prov)
    with pytest.raises(ModelFileError, match="unknown model kind"):
        save_model(tmp_path / "m.json", "spline", {}, prov)


def good_doc(data_file):
    return {"format": FORMAT, "version": 1, "kind": "preisach",
            "params": {"u_min": 0.0, "u_max": 1.0, "n": 2, "alpha": [0.0, 0.0], "p1": 0.0, "p2": 0.0,
                       "offset": 0.0},
            "provenance": {"tool_version": "0.1.0", "created": "2025-01-01T00:00:00Z",
                           "data": [{"path": str(data_file), "sha256": file_sha256(data_file),
                                     "nrmse": 0.1}],
                           "options": {}}}


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(format="other"), "not a piezoctl model file"),
    (lambda d: d.pop("format"), "not a piezoctl model file"),
    (lambda d: d.update(version=2), "newer than this piezoctl"),
    (lambda d: d.update(version=0), "version 0 is not supported"),
    (lambda d: d.update(version="1"), "'version' must be an integer"),
    (lambda d: d.update(kind="spline"), "unknown model kind 'spline'"),
    (lambda d: d.pop("params"), "lacks 'params'"),
    (lambda d: d.update(params=[1, 2]), "'params' must be an object"),
    (lambda d: d["provenance"].pop("options"), "provenance lacks 'options'"),
    (lambda d: d["provenance"].update(tool_version=1), "tool_version must be a string"),
    (lambda d: d["provenance"]["data"][0].update(sha256="abc"), r"data\[0\]\.sha256"),
    (lambda d: d["provenance"]["data"][0].update(nrmse="low"), r"data\[0\]\.nrmse"),
])
def test_load_checks_fields(tmp_path, data_file, mutate, message):
    doc = good_doc(data_file)
    load_model(_write(tmp_path, doc))          # the unmodified document loads
    mutate(doc)
    with pytest.raises(ModelFileError, match=message) as info:
        load_model(_write(tmp_path, doc))
    assert isinstance(info.value, CliError) and "\n" not in str(info.value)


def _write(tmp_path, doc):
    p = tmp_path / "m.json"
    p.write_text(json.dumps(doc))
    return p


def test_load_invalid_json_names_line(tmp_path):
    p = tmp_path / "m.json"
    p.write_text('{\n "format": "piezoctl-model",\n "version": 1,,\n}')
    with pytest.raises(ModelFileError, match=r"line 3 column .*invalid JSON"):
        load_model(p)
    p.write_text('{"format": "piezoctl-model", "version": 1, "x": NaN}')
    with pytest.raises(ModelFileError, match="NaN is not allowed"):
        load_model(p)
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model(tmp_path / "absent.json")
