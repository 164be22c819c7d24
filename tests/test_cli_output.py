"""The command's standard output: with --json it carries the JSON alone, and a failure to write it is said in one line
with status 2, as an error is; a bug exits with a status of its own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN

from wbc.cli.main import main

ROOT = Path(__file__).resolve().parents[1]

CHATTY = STAND_PLUGIN.format(
    doc="A stand controller that prints to standard output in reset, from Python and at the file descriptor.",
    reset='print("chatty: reset"); import os; os.write(1, b"chatty: fd reset\\n")',
    act="pass", counters="return {}")


@pytest.fixture
def chatty(plugin_package, tmp_path) -> Path:
    plugin_package("chattyplug", {"chatty": CHATTY.replace(
        "        return Wrapped(desc)", '        print("chatty: building")\n        return Wrapped(desc)')})
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    return scenario


@pytest.mark.parametrize("workers", ["1", "2"])
def test_json_output_holds_the_json_alone_when_a_controller_prints(chatty, tmp_path, capfd, workers) -> None:
    """A plug-in that prints (in its factory, in ``reset``, at the file descriptor too) wrote into ``--json``'s
    output, in this process (one worker: played here) and in the pool's workers (two): json.load failed on it."""
    out = tmp_path / "out"
    code = main(["run", "chattyplug.chatty:make", "--scenario", str(chatty), "--trials", "1", "--workers", workers,
                 "--quiet", "--out", str(out), "--json"])
    captured = capfd.readouterr()
    assert code == 0, captured.err
    summary = json.loads(captured.out)
    assert "chattyplug.chatty:make" in summary["controllers"]
    assert "chatty: building" in captured.err and "chatty: reset" in captured.err
    if workers == "2":  # the worker's own write to its file descriptor 1 goes to standard error too
        assert "chatty: fd reset" in captured.err


def test_check_controller_json_holds_the_json_alone(chatty, capfd) -> None:
    # the checks run in a worker process, whose prints reach the command's standard error at the file descriptor
    code = main(["check-controller", "chattyplug.chatty:make", "--seconds", "0.2", "--json"])
    captured = capfd.readouterr()
    assert isinstance(json.loads(captured.out), dict), captured.out
    assert "chatty: building" in captured.err and code in (0, 1)


def _wbc(*args: str, shell_tail: str) -> subprocess.CompletedProcess:
    """``python -m wbc.cli ARGS`` from a shell, its standard output redirected by `shell_tail`."""
    command = " ".join([sys.executable, "-m", "wbc.cli", *args]) + " " + shell_tail
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    return subprocess.run(["bash", "-c", command], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_full_standard_output_is_an_error_in_one_line() -> None:
    """``wbc controllers > /dev/full`` printed an OSError traceback and exited 1, the status of a controller's error."""
    proc = _wbc("controllers", shell_tail="> /dev/full")
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == ["wbc: error: standard output cannot be written: [Errno 28] No space left on "
                                        "device"]


def test_a_closed_standard_output_is_refused_before_anything_runs() -> None:
    """``wbc controllers >&-`` raised AttributeError ('NoneType' object has no attribute 'flush') and exited 1."""
    proc = _wbc("controllers", shell_tail=">&-")
    assert proc.returncode == 2
    (line,) = proc.stderr.splitlines()
    assert line.startswith("wbc: error: standard output cannot be written: it is closed") and "nothing was done" in line


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_run_whose_json_cannot_be_written_says_where_its_results_are(chatty, tmp_path, monkeypatch, capsys) -> None:
    """The JSON of a run meets a full disk after its trials are stored: status 2 and the directory, not a traceback
    and status 1."""
    out = tmp_path / "out"
    full = open("/dev/full", "w")  # noqa: SIM115  (closed below: the command's standard output)
    try:
        monkeypatch.setattr(sys, "stdout", full)
        code = main(["run", "chattyplug.chatty:make", "--scenario", str(chatty), "--trials", "1", "--workers", "1",
                     "--quiet", "--out", str(out), "--json"])
    finally:
        monkeypatch.undo()
        full.close()
    err = capsys.readouterr().err
    assert code == 2
    assert (f"wbc: error: standard output cannot be written: [Errno 28] No space left on device; the run's results "
            f"are stored in {out}") in err
    assert (out / "trials.csv").is_file() and (out / "summary.json").is_file()


def test_a_bug_exits_with_a_status_of_its_own(monkeypatch, capsys) -> None:
    """An unexpected exception exited 1, the status that says a controller errored: it exits 70 (EX_SOFTWARE), its
    traceback and a line that calls it a bug on standard error."""
    import importlib

    import wbc.cli

    cli = importlib.import_module("wbc.cli.main")

    def buggy(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setitem(cli.HANDLERS, "controllers", buggy)
    monkeypatch.setattr(sys, "argv", ["wbc", "controllers"])
    assert wbc.cli.main() == wbc.cli.INTERNAL_ERROR == 70
    err = capsys.readouterr().err
    assert "ZeroDivisionError: a bug" in err and "wbc: internal error" in err
