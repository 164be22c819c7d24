"""A results directory survives what happens around its run.

A run holds its directory locked from before it reads anything there until its report is written: a second run on it,
with or without ``--resume``, is refused with one line naming the pid of the one that holds it, and changes nothing.
"""

import os
from pathlib import Path

import pytest
from conftest import SHORT_SCENARIO

from wbc.arena.identity import RunIdentity
from wbc.arena.results import LOCK_FILE, ResultsStore
from wbc.arena.trial_record import TrialRecord
from wbc.cli.main import main


@pytest.fixture
def short(tmp_path):
    path = tmp_path / "short.toml"
    path.write_text(SHORT_SCENARIO)
    return path


def _run(short: Path, out: Path, *extra: str) -> list[str]:
    """``wbc run stand`` on the short scenario into `out`, in this process."""
    return ["run", "stand", "--scenario", str(short), "--trials", "2", "--out", str(out), "--workers", "1",
            "--in-process", "--quiet", *extra]


def _snapshot(out: Path) -> dict[str, tuple[bytes, int, int]]:
    """Every file of `out`: its bytes, inode and modification time (a file replaced by an equal one differs)."""
    return {p.name: (p.read_bytes(), p.stat().st_ino, p.stat().st_mtime_ns) for p in sorted(out.iterdir())
            if p.is_file()}


def _last_line(capsys) -> str:
    """The last line the command wrote to stderr (the scenario's warning, an edited copy, comes first)."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err.splitlines()[-1]


def test_a_results_directory_in_use_by_another_run_is_refused_and_left_as_it_is(short, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(_run(short, out)) == 0
    capsys.readouterr()
    # another run holds it: a resumed one, still playing
    holder = ResultsStore(out, RunIdentity.load(out / "run.json"), resume=True)
    try:
        before = _snapshot(out)
        assert (out / LOCK_FILE).read_text() == f"{os.getpid()}\n"
        for extra in (["--resume"], []):
            assert main(_run(short, out, *extra)) == 2
            assert _last_line(capsys) == (f"wbc: error: {out} is in use by another wbc run (pid {os.getpid()}); wait "
                                          "for it to end, or give another --out")
            assert _snapshot(out) == before  # nothing read and rewritten, nothing replaced
    finally:
        holder.close()
    # once it is done, the directory is free again
    assert main(_run(short, out, "--resume")) == 0
    assert len(TrialRecord.read_csv(out / "trials.csv")) == 2


def test_a_store_that_refuses_a_directory_gives_its_lock_back(short, tmp_path):
    out = tmp_path / "out"
    assert main(_run(short, out)) == 0
    identity = RunIdentity.load(out / "run.json")
    with pytest.raises(Exception, match="already holds results"):
        ResultsStore(out, identity, resume=False)
    ResultsStore(out, identity, resume=True).close()  # not refused as in use: the refusal above let it go
