"""The command's standard output: with --json it carries the JSON alone."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN

from wbc.cli.main import main

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


def test_check_controller_json_holds_the_json_alone(chatty, capsys) -> None:
    code = main(["check-controller", "chattyplug.chatty:make", "--seconds", "0.2", "--json"])
    captured = capsys.readouterr()
    assert isinstance(json.loads(captured.out), dict), captured.out
    assert "chatty: building" in captured.err and code in (0, 1)
