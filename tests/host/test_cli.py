"""The CLI's conventions (issue 16, part 5): a light start-up, one description of
PORT, --json/--quiet, one-line errors with documented exit codes, options of
another model kind refused, no library log lines in the output.

Start-up time itself is measured by tools/bench-cli, not here; these tests
check what makes it fast (which modules a command line imports)."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest

from piezoctl import cli
from piezoctl.commands import _options
from piezoctl.commands import status as status_cmd
from piezoctl.errors import (EXIT_CHECK_FAILED, EXIT_CONNECTION, EXIT_CONTROLLER, EXIT_INTERNAL,
                             EXIT_INTERRUPTED, EXIT_REFUSED, CheckFailed)
from piezoctl.io.recording import save_recording
from piezoctl.transport.errors import ModbusExceptionError, ProtocolError

from sil_fixture import sil  # noqa: F401  (pytest fixture)

# The commands this part of the issue converted; the others follow the same
# conventions in their owners' branches (then add them here).
HEAVY = ("scipy", "matplotlib")


def _imports_after(argv: list[str]) -> set[str]:
    """Top-level packages imported by a fresh ``piezoctl ARGV`` (run to its exit)."""
    code = ("import sys\n"
            "from piezoctl.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))\n")
    p = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=120)
    return set(p.stdout.strip().splitlines()[-1].split())


def test_importing_cli_imports_no_heavy_library():
    code = "import sys, piezoctl.cli; print(' '.join(sorted(sys.modules)))"
    mods = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout.split()
    assert not [m for m in mods if m.split(".")[0] in ("numpy", *HEAVY)]
    assert not [m for m in mods if m.startswith("piezoctl.commands.") and m != "piezoctl.commands._options"]


@pytest.mark.parametrize("argv", [["--help"], ["status", "--help"], ["stage", "simulate", "--help"],
                                  ["golden-error", "--help"]])
def test_help_imports_no_numpy(argv):
    mods = _imports_after(argv)
    assert "piezoctl" in mods
    assert not {"numpy", *HEAVY} & mods


def test_identify_help_imports_no_scipy():
    assert not set(HEAVY) & _imports_after(["identify", "--help"])


def test_top_level_help_lists_commands_without_importing_them():
    """The summaries of :data:`cli.COMMANDS` are the modules' own: the lazy
    ``piezoctl --help`` reads exactly like the one built from every module."""
    lazy = cli.build_parser(["--help"]).format_help()
    full = cli.build_parser().format_help()
    assert lazy == full
    sub = next(a for a in cli.build_parser()._actions if a.dest == "command")
    assert sorted(sub.choices) == sorted(cli.COMMANDS)   # every command module is in the table


@pytest.mark.parametrize("name", sorted(cli.COMMANDS))
def test_table_names_the_module_of_each_command(name):
    """``piezoctl NAME`` imports the module the table names: that module registers NAME."""
    module, _ = cli.COMMANDS[name]
    sub = argparse.ArgumentParser().add_subparsers()
    importlib.import_module(f"piezoctl.commands.{module}").add_parser(sub)
    assert name in sub.choices


def _leaf_parsers():
    """(command line, parser) of every runnable command of the full parser."""
    out = []

    def walk(prefix, parser):
        subs = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
        if not subs:
            out.append((prefix, parser))
        for a in subs:
            for name, p in a.choices.items():
                walk(f"{prefix} {name}".strip(), p)

    walk("", cli.build_parser())
    return dict(out)


def test_port_described_once():
    parsers = _leaf_parsers()
    ports = [a for a in parsers["status"]._actions if "--port" in a.option_strings]
    assert ports and ports[0].help.endswith(_options.PORT_HELP)
    assert "PORT" in parsers["status"].format_help()


# ------------------------------------------------------------ exit codes
def _recording(tmp_path, n=400):
    t = np.arange(n) / 1000.0
    u = 50 + 40 * np.sin(2 * np.pi * 5 * t)
    y = 0.2 * u + 0.5 * np.sin(2 * np.pi * 5 * t + 0.3)
    path = tmp_path / "rec.csv"
    save_recording(path, {"t": t, "u": u, "y": y}, meta={"sample_rate_hz": 1000})
    return path


def test_exit_0_identify_json_is_one_document(tmp_path, capsys):
    rec = _recording(tmp_path)
    out = tmp_path / "m.json"
    rc = cli.main(["identify", "--model", "kp", "--kp-levels", "4", "--data", str(rec), "--out", str(out),
                   "--json"])
    cap = capsys.readouterr()
    assert rc == 0
    doc = json.loads(cap.out)
    assert doc["model"] == "kp" and doc["out"] == str(out) and doc["data"][0]["rows"] == 400
    assert 0 <= doc["data"][0]["nrmse"] < 1
    assert out.exists()
    assert cap.err == ""   # --json: no progress


def test_identify_progress_on_stderr_unless_quiet(tmp_path, capsys):
    rec = _recording(tmp_path)
    args = ["identify", "--model", "kp", "--kp-levels", "4", "--data", str(rec), "--out", str(tmp_path / "m.json")]
    assert cli.main(args) == 0
    cap = capsys.readouterr()
    assert "fitting kp" in cap.err and "fitting kp" not in cap.out
    assert "model written to" in cap.out
    assert cli.main(args + ["--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.err == "" and "model written to" in cap.out


def _one_error_line(err: str, command: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"piezoctl {command}: error: ")
    return lines[0]


def test_exit_2_usage(capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["status"])             # --port missing
    assert e.value.code == EXIT_REFUSED
    assert "--port" in _one_error_line(capsys.readouterr().err, "status")


def test_exit_2_input(tmp_path, capsys):
    rc = cli.main(["identify", "--model", "kp", "--data", str(tmp_path / "none.csv"), "--out", str(tmp_path / "m")])
    assert rc == EXIT_REFUSED
    _one_error_line(capsys.readouterr().err, "identify")
    assert not (tmp_path / "m").exists()


def test_exit_2_option_of_another_kind(tmp_path, capsys):
    for extra, says in ((["--order", "4"], "--model cascade takes --cascade-order"),
                        (["--rkp-levels", "4"], "--rkp-levels is an option of --model rkp, not of --model kp")):
        with pytest.raises(SystemExit) as e:
            cli.main(["identify", "--model", "kp", *extra, "--data", "x.csv", "--out", str(tmp_path / "m")])
        assert e.value.code == EXIT_REFUSED
        assert says in _one_error_line(capsys.readouterr().err, "identify")
    assert not (tmp_path / "m").exists()


def test_exit_2_bad_port(capsys):
    assert cli.main(["status", "--port", "tcpx:1"]) == EXIT_REFUSED
    _one_error_line(capsys.readouterr().err, "status")


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_exit_5_no_connection(capsys):
    assert cli.main(["status", "--port", f"tcp:127.0.0.1:{_closed_port()}"]) == EXIT_CONNECTION
    _one_error_line(capsys.readouterr().err, "status")
    assert cli.main(["status", "--port", "rtu:/dev/piezoctl-no-such-device"]) == EXIT_CONNECTION
    _one_error_line(capsys.readouterr().err, "status")


def test_no_library_log_lines_on_a_failed_connect():
    """pymodbus logs a refused connect at ERROR; a fresh process prints only our line."""
    p = subprocess.run([sys.executable, "-m", "piezoctl.cli", "status", "--port", f"tcp:127.0.0.1:{_closed_port()}"],
                       capture_output=True, text=True, timeout=60,
                       env={k: v for k, v in os.environ.items() if k != "PIEZOCTL_DEBUG"})
    assert p.returncode == EXIT_CONNECTION
    assert p.stdout == ""
    _one_error_line(p.stderr, "status")


def _failing(monkeypatch, exc):
    def run(args):
        raise exc
    monkeypatch.setattr(status_cmd, "run", run)


@pytest.mark.parametrize("exc, code", [
    (CheckFailed("the acceptance test failed"), EXIT_CHECK_FAILED),
    (ModbusExceptionError("tcp:x: illegal data value (exception 03)", 3, 16), EXIT_CONTROLLER),
    (ProtocolError("tcp:x: answer has function 0x83, asked 0x03"), EXIT_CONNECTION),
    (ConnectionResetError(104, "Connection reset by peer"), EXIT_CONNECTION),
    (BrokenPipeError(32, "Broken pipe"), EXIT_CONNECTION),
    (ZeroDivisionError("division by zero"), EXIT_INTERNAL),
    (KeyboardInterrupt(), EXIT_INTERRUPTED),
])
def test_exit_code_of_each_error(monkeypatch, capsys, exc, code):
    """How main maps what a command raises: the error classes of piezoctl.errors
    and piezoctl.transport.errors, a link error escaping the transport, a bug."""
    monkeypatch.delenv("PIEZOCTL_DEBUG", raising=False)
    _failing(monkeypatch, exc)
    assert cli.main(["status", "--port", "tcp:127.0.0.1:1"]) == code
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("piezoctl status: ")
    if code == EXIT_INTERNAL:
        assert "ZeroDivisionError" in lines[0] and "PIEZOCTL_DEBUG=1" in lines[0]


def test_exit_4_controller_refused_sil(sil, monkeypatch, capsys):  # noqa: F811
    """A real refusal through main: the controller answers an exception to a read outside its map."""
    def run(args):
        from piezoctl.device import connect
        connect(args.port).client.read_input(0xFFF0, 4)
        return 0
    monkeypatch.setattr(status_cmd, "run", run)
    assert cli.main(["status", "--port", sil.spec]) == EXIT_CONTROLLER
    assert "exception" in _one_error_line(capsys.readouterr().err, "status")


def test_status_json_sil(sil, capsys):  # noqa: F811
    assert cli.main(["status", "--port", sil.spec, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["tick_hz"] == 10000 and "active_table_crc" in doc
    assert cli.main(["status", "--port", sil.spec, "--quiet"]) == 0
    assert capsys.readouterr().out.startswith(f"controller on {sil.spec}")


_NOISY = """
import logging, sys, warnings
import numpy as np
from piezoctl import cli
from piezoctl.commands import status
def run(args):
    logging.getLogger("pymodbus.logging").error("Connection to (x, 1) failed")
    logging.getLogger("matplotlib.font_manager").warning("findfont: Font family not found")
    warnings.warn("something deprecated", DeprecationWarning)
    np.log(np.zeros(1))                      # numpy's own RuntimeWarning
    print("result")
    return 0
status.run = run
rc = cli.main(["status", "--port", "tcp:127.0.0.1:1"])
logging.getLogger("after").warning("logging works again after the command")
sys.exit(rc)
"""


@pytest.mark.parametrize("debug", [False, True])
def test_library_logs_and_warnings_stay_out(debug):
    """A fresh process (no pytest handlers): library log lines and warnings raised
    while a command runs do not reach the output; PIEZOCTL_DEBUG=1 lets them through."""
    env = {k: v for k, v in os.environ.items() if k != "PIEZOCTL_DEBUG"}
    env["PYTHONWARNINGS"] = "default"
    if debug:
        env["PIEZOCTL_DEBUG"] = "1"
    p = subprocess.run([sys.executable, "-c", _NOISY], capture_output=True, text=True, timeout=60, env=env)
    assert p.returncode == 0
    assert p.stdout == "result\n"
    if debug:
        assert "Connection to (x, 1) failed" in p.stderr and "RuntimeWarning" in p.stderr
    else:
        assert p.stderr == "logging works again after the command\n"


@pytest.mark.parametrize("command", sorted(_leaf_parsers()))
def test_json_and_quiet(command):
    p = _leaf_parsers()[command]
    p.format_help()   # runs the before-parse hooks (identify: none without --model)
    flags = {s for a in p._actions for s in a.option_strings}
    assert {"--json", "--quiet"} <= flags


@pytest.mark.parametrize("command", sorted(_leaf_parsers()))
def test_every_port_option_carries_the_one_description(command):
    p = _leaf_parsers()[command]
    ports = [a for a in p._actions if "--port" in a.option_strings]
    assert all(a.help.endswith(_options.PORT_HELP) for a in ports)


@pytest.mark.parametrize("name", sorted(cli.COMMANDS))
def test_every_command_help_imports_no_scipy_or_matplotlib(name):
    """``piezoctl NAME --help`` loads the command's parser only (the 0.5 s start-up: tools/bench-cli)."""
    assert not set(HEAVY) & _imports_after([name, "--help"])


def test_closed_stdout_is_not_a_connection_error(tmp_path):
    """`piezoctl ... | head`: the reader leaves; exit 141 (128 + SIGPIPE) and no error line, not exit 5."""
    script = ("import sys\n"
              "from piezoctl import cli\n"
              "from piezoctl.commands import status as s\n"
              "def run(args):\n"
              "    for _ in range(100000):\n"
              "        print('line of output')\n"
              "s.run = run\n"
              "sys.exit(cli.main(['status', '--port', 'tcp:127.0.0.1:1']))\n")
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         env={k: v for k, v in os.environ.items() if k != "PIEZOCTL_DEBUG"})
    p.stdout.read(100)
    p.stdout.close()                      # the reader goes away while the command writes
    err = p.stderr.read().decode()
    assert p.wait(timeout=60) == 141
    assert "connection" not in err and "error" not in err, err
