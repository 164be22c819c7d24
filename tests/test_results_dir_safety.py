"""A results directory survives what happens around its run.

A run holds its directory locked from before it reads anything there until its report is written: a second run on it,
with or without ``--resume``, is refused with one line naming the pid of the one that holds it, and changes nothing.
SIGTERM (a batch scheduler, ``timeout``, ``docker stop``) interrupts a run as Ctrl-C does: status 130 and the line
that says how to finish it; and a pool's workers end with the process that started them, however it ends. That line
names the directory the run wrote, the default one included, which its ``--resume`` then names too. The files a run
rewrites (``run.json`` on every resume, the summary and report at its end) are written whole or not at all. A file
that cannot be written (a full disk, a read-only file system) stops the run with one line (status 2) that names it,
says the trials stored are kept, and how ``--resume`` finishes the run.
"""

import errno
import importlib
import json
import os
import re
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from conftest import SHORT_SCENARIO

from wbc.arena import executors
from wbc.arena import results as results_module
from wbc.arena.identity import RunIdentity
from wbc.arena.results import LOCK_FILE, ResultsStore, hold_results_dir
from wbc.arena.trial_record import TrialRecord
from wbc.cli.main import main
from wbc.errors import ResultsDirError
from wbc.output_files import directory_holder

cli = importlib.import_module("wbc.cli.main")  # the module (the package's name `main` is the function)


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


def test_a_store_given_its_callers_lock_uses_it_and_leaves_it_held(short, tmp_path):
    # how a command that writes files of its own beside the run's (wbc paper) keeps the directory until they are written
    out = tmp_path / "out"
    assert main(_run(short, out)) == 0
    identity = RunIdentity.load(out / "run.json")
    with hold_results_dir(out) as lock:
        ResultsStore(out, identity, resume=True, lock=lock).close()
        assert lock.held and directory_holder(out).pid == os.getpid()  # closing the store left it to its caller
        with pytest.raises(ResultsDirError, match="in use by another wbc run"):
            ResultsStore(out, identity, resume=True)  # another run is refused all the same
        with hold_results_dir(tmp_path / "other") as theirs, pytest.raises(ValueError, match="another directory"):
            ResultsStore(out, identity, resume=True, lock=theirs)
    assert directory_holder(out) is None
    with pytest.raises(ValueError, match="released"):
        ResultsStore(out, identity, resume=True, lock=lock)
    ResultsStore(out, identity, resume=True).close()


def test_a_held_directory_that_a_refusal_leaves_empty_goes_if_this_hold_created_it(tmp_path):
    # a command that takes its directory before the run (wbc paper), refused or interrupted before anything is stored
    out = tmp_path / "new" / "out"
    with pytest.raises(ResultsDirError, match="refused"), hold_results_dir(out):
        raise ResultsDirError("refused")
    assert not (tmp_path / "new").exists()  # nor the parent created with it
    with pytest.raises(KeyboardInterrupt), hold_results_dir(out):
        (out / "trials.csv").write_text("header\n")  # what the store writes first
        raise KeyboardInterrupt
    assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE, "trials.csv"]
    with hold_results_dir(tmp_path / "done"):
        pass  # a run that ends well keeps its directory
    assert [p.name for p in (tmp_path / "done").iterdir()] == [LOCK_FILE]
    mine = tmp_path / "mine"
    mine.mkdir()
    with pytest.raises(KeyboardInterrupt), hold_results_dir(mine):
        raise KeyboardInterrupt
    assert [p.name for p in mine.iterdir()] == [LOCK_FILE]  # the user's: it stays
    assert directory_holder(mine) is None and directory_holder(out) is None


def test_sigterm_interrupts_a_run_as_ctrl_c_does(short, tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "wbc.cli", "compare", "stand", "stand-noarm", "--scenario",
                             str(short), "--trials", "30", "--workers", "2", "--out", "out", "--quiet"],
                            cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        trials_csv = out / "trials.csv"
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if trials_csv.exists() and trials_csv.read_text().count("\n") >= 2:  # header + a trial
                break
            time.sleep(0.05)
        assert proc.poll() is None, proc.stderr.read()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    assert err.splitlines()[-1] == ("wbc: interrupted; the trials finished are stored in out: the same command with "
                                    "--resume plays the rest")
    assert "Traceback" not in err
    assert 1 <= len(TrialRecord.read_csv(trials_csv)) < 60


def _gone(pid: int) -> bool:
    """`pid` has ended: no such process, or a zombie left for an init that does not reap."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rpartition(")")[2].split()[0] == "Z"
    except FileNotFoundError:
        return True


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_a_pools_workers_end_when_the_process_that_started_them_is_killed(tmp_path):
    parent = textwrap.dedent("""
        import time
        from wbc.arena.executors import spawn_pool

        pool = spawn_pool(2)
        for future in [pool.submit(time.sleep, 0.5) for _ in range(2)]:  # both workers started, both initialised
            future.result()
        print(*pool._processes, flush=True)
        time.sleep(600)
    """)
    # its stderr dropped: the resource tracker it leaves warns there of the pool's semaphores, which it cleans up
    proc = subprocess.Popen([sys.executable, "-c", parent], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    workers: list[int] = []
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 120)
        assert ready, "the parent did not start its workers"
        workers = [int(pid) for pid in proc.stdout.readline().split()]
        assert len(workers) == 2 and not any(_gone(pid) for pid in workers)
        proc.kill()  # SIGKILL: the parent shuts nothing down
        proc.wait()
        deadline = time.monotonic() + 30  # a bound for failing, not a figure the test asserts
        while time.monotonic() < deadline and not all(_gone(pid) for pid in workers):
            time.sleep(0.1)
        assert all(_gone(pid) for pid in workers)
    finally:
        proc.kill()
        for pid in workers:  # not left behind if the test fails
            if not _gone(pid):
                os.kill(pid, signal.SIGKILL)


def test_a_worker_without_the_kernels_help_ends_once_its_parent_is_gone():
    parents, exits = iter([7, 7, 7, 1]), []
    executors._watch_parent(7, getppid=lambda: next(parents), sleep=lambda s: None, exit_=exits.append)
    assert exits == [1]


def test_an_interrupted_run_without_out_names_the_directory_it_wrote_and_resume_finishes_it(short, tmp_path, capsys,
                                                                                           monkeypatch):
    monkeypatch.chdir(tmp_path)
    append = results_module.ResultsStore.append

    def interrupted(store, record):  # Ctrl-C once the first trial is stored
        append(store, record)
        raise KeyboardInterrupt

    monkeypatch.setattr(results_module.ResultsStore, "append", interrupted)
    args = ["run", "stand", "--scenario", "short.toml", "--trials", "2", "--workers", "1", "--in-process", "--quiet"]
    assert main(args) == 130
    (out,) = Path("runs").iterdir()
    assert out.name.startswith("short-stand-")
    assert _last_line(capsys) == (f"wbc: interrupted; the trials finished are stored in {out}: the same command with "
                                  f"--resume --out {out} plays the rest")
    monkeypatch.setattr(results_module.ResultsStore, "append", append)
    assert main([*args, "--resume", "--out", str(out)]) == 0  # as the line says
    assert len(TrialRecord.read_csv(out / "trials.csv")) == 2
    assert "\n1 trials played in " in (printed := capsys.readouterr().out)
    assert "(and 1 stored before, resumed: 2 in all)" in printed


def test_a_run_interrupted_once_every_trial_is_stored_says_that_resume_only_writes_its_summary(short, tmp_path, capsys,
                                                                                             monkeypatch):
    import wbc.arena.compare as compare

    summarize = compare.summarize

    def interrupted(*args, **kwargs):  # Ctrl-C after the last trial, as the summary is made
        raise KeyboardInterrupt

    monkeypatch.setattr(compare, "summarize", interrupted)
    out = tmp_path / "out"
    assert main(_run(short, out)) == 130
    assert _last_line(capsys) == (f"wbc: interrupted; every trial is stored in {out}, its summary and report are not "
                                  "yet written: the same command with --resume writes them")
    assert not (out / "summary.json").exists()
    monkeypatch.setattr(compare, "summarize", summarize)
    assert main([*_run(short, out), "--resume"]) == 0  # as the line says
    assert "\n0 trials played in " in capsys.readouterr().out and (out / "summary.json").is_file()


@pytest.mark.parametrize(("command", "patched", "default"), [
    (["compare", "stand", "stand-noarm", "--scenario", "short.toml"], "run_arena", "short-stand-stand-noarm-"),
    (["paper", "table1"], "run_paper_table", "paper-table1-"),
    (["demo", "--scenario", "short.toml"], "run_arena", "demo-"),
])
def test_each_resumable_command_names_its_default_directory_when_interrupted(short, tmp_path, capsys, monkeypatch,
                                                                            command, patched, default):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(cli, "analyze_tail", lambda robot: None)  # demo's analysis first: not what is tested
    monkeypatch.setattr(cli.printers, "print_tail", lambda result: None)

    def interrupted(cfg):  # the run has begun to store its trials, then Ctrl-C before the first finished
        cfg.out_dir.mkdir(parents=True)
        (cfg.out_dir / "trials.csv").write_text("")
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, patched, interrupted)
    assert main([*command, "--quiet"]) == 130
    (out,) = Path("runs").iterdir()
    assert out.name.startswith(default)
    assert _last_line(capsys) == (f"wbc: interrupted; no trial had finished ({out} holds the run's plan only): the "
                                  f"same command with --resume --out {out} plays it")


def test_a_run_interrupted_before_it_stored_anything_says_a_new_run_starts_afresh(short, tmp_path, capsys,
                                                                                 monkeypatch):
    monkeypatch.chdir(tmp_path)

    def interrupted(cfg):  # Ctrl-C while the controllers are built, before the directory exists
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "run_arena", interrupted)
    assert main(["run", "stand", "--scenario", "short.toml", "--quiet"]) == 130
    assert re.fullmatch(r"wbc: interrupted; no trial was stored yet \(runs/short-stand-[0-9-]+ holds no trials\.csv\): "
                        r"the same command starts the run afresh", _last_line(capsys))


class _WrappedFile:
    """A file opened for the code under test, whose `write` a subclass replaces; the rest is the file's."""

    def __init__(self, file):
        self.file = file

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.file.close()

    def __getattr__(self, name):
        return getattr(self.file, name)


class _TornFile(_WrappedFile):
    """A file being written that is interrupted (Ctrl-C) halfway through its first write."""

    def write(self, data):
        self.file.write(data[: len(data) // 2])
        self.file.flush()
        raise KeyboardInterrupt


@pytest.mark.parametrize("name", ["run.json", "summary.json", "report.md"])
def test_a_results_file_interrupted_while_it_is_rewritten_is_left_whole_and_the_run_resumes(short, tmp_path, capsys,
                                                                                           monkeypatch, name):
    out = tmp_path / "out"
    assert main(_run(short, out)) == 0
    before = (out / name).read_bytes()
    open_ = Path.open

    def torn(path, mode="r", *args, **kwargs):  # every write of `name`, or of a file beside it that replaces it
        file = open_(path, mode, *args, **kwargs)
        return _TornFile(file) if path.name.startswith(name) and "w" in mode else file

    monkeypatch.setattr(Path, "open", torn)
    assert main(_run(short, out, "--resume")) == 130  # run.json: as the resumed run opens; the others: as it ends
    monkeypatch.setattr(Path, "open", open_)
    if name == "run.json":
        assert (out / name).read_bytes() == before  # the old file, whole
    else:  # removed as the resume began (derived from trials.csv, written again at its end): never torn
        assert not (out / name).exists()
    assert sorted(p.name for p in out.iterdir() if p.name.endswith(".tmp")) == []
    capsys.readouterr()
    assert main(_run(short, out, "--resume")) == 0  # the run is finished as if it had never been interrupted
    assert len(TrialRecord.read_csv(out / "trials.csv")) == 2
    assert json.loads((out / "summary.json").read_text())["controllers"]["stand"]


class _FullDisk(_WrappedFile):
    """A file whose writes fail with `code` (a full disk, a read-only file system) after its first `writes`."""

    def __init__(self, file, writes, code):
        super().__init__(file)
        self.writes, self.code = writes, code

    def write(self, data):
        if self.writes <= 0:
            raise OSError(self.code, os.strerror(self.code))
        self.writes -= 1
        return self.file.write(data)


def _failing(monkeypatch, name: str, opened: str, writes: int, code: int) -> None:
    """Writes of the files named `name` (or their temporary files), `opened` so, fail after `writes` writes."""
    open_ = Path.open

    def failing(path, mode="r", *args, **kwargs):
        file = open_(path, mode, *args, **kwargs)
        return _FullDisk(file, writes, code) if path.name.startswith(name) and opened in mode else file

    monkeypatch.setattr(Path, "open", failing)


def test_a_full_disk_stops_the_run_in_one_line_keeping_the_trials_stored(short, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    args = ["run", "stand", "--scenario", str(short), "--trials", "4", "--out", str(out), "--workers", "1",
            "--in-process", "--quiet"]
    _failing(monkeypatch, "trials.csv", "a", 2, errno.ENOSPC)  # the disk fills up as the third trial is stored
    assert main(args) == 2
    assert _last_line(capsys) == (f"wbc: error: {out / 'trials.csv'}: cannot be written (No space left on device); "
                                  f"the 2 trial(s) finished are kept in {out / 'trials.csv'}: the same command with "
                                  f"--resume --out {out} finishes the run once there is room")
    monkeypatch.undo()
    assert len(TrialRecord.read_csv(out / "trials.csv")) == 2
    assert main([*args, "--resume"]) == 0
    assert len(TrialRecord.read_csv(out / "trials.csv")) == 4


def test_a_summary_that_cannot_be_written_stops_the_run_in_one_line_and_resume_writes_it(short, tmp_path, capsys,
                                                                                       monkeypatch):
    out = tmp_path / "out"
    _failing(monkeypatch, "summary.json", "w", 0, errno.EROFS)
    assert main(_run(short, out)) == 2
    assert _last_line(capsys) == (f"wbc: error: {out / 'summary.json'}: cannot be written (Read-only file system); "
                                  f"the 2 trial(s) finished are kept in {out / 'trials.csv'}: the same command with "
                                  f"--resume --out {out} finishes the run once {out} can be written")
    assert not (out / "summary.json").exists() and not (out / "summary.json.tmp").exists()
    monkeypatch.undo()
    assert main(_run(short, out, "--resume")) == 0  # plays nothing, and writes the summary and report
    assert json.loads((out / "summary.json").read_text())["controllers"]["stand"]
    assert len(TrialRecord.read_csv(out / "trials.csv")) == 2


def test_an_episode_that_cannot_be_saved_stops_the_run_in_one_line(short, tmp_path, capsys, monkeypatch):
    from wbc.arena.episode import Episode

    def full(episode, path):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Episode, "save", full)
    out = tmp_path / "out"
    assert main(_run(short, out, "--save-episodes")) == 2
    assert _last_line(capsys) == (f"wbc: error: {out / 'episodes' / 'stand' / 'soft-s0-t0.npz'}: cannot be written (No "
                                  f"space left on device); no trial was stored yet: the same command with --resume "
                                  f"--out {out} finishes the run once there is room")


def _not_results(tmp_path: Path) -> Path:
    """A directory of someone's files, two of them named as a run's: its summary.json and report.md."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "summary.json").write_text('{"mine": 1}\n')
    (out / "report.md").write_text("notes\n")
    return out


@pytest.mark.parametrize("command", ["run", "compare", "paper", "demo"])
def test_a_directory_of_other_files_is_refused_before_anything_plays(command, short, tmp_path, capsys) -> None:
    """An existing --out that held no trials.csv was taken as the run's: ``wbc run stand --out DIR`` replaced the
    summary.json and report.md it held without a word. Every command that writes a results directory refuses it
    now, before it plays, naming it and what it holds, and leaves it as it was."""
    out = _not_results(tmp_path)
    before = _snapshot(out)
    argv = {"run": _run(short, out),
            "compare": ["compare", "stand", "stand-noarm", "--scenario", str(short), "--trials", "1", "--workers", "1",
                        "--quiet", "--out", str(out)],
            "paper": ["paper", "table1", "--trials", "1", "--workers", "1", "--quiet", "--out", str(out)],
            "demo": ["demo", "--trials", "1", "--workers", "1", "--quiet", "--out", str(out)]}[command]
    assert main(argv) == 2
    line = _last_line(capsys)
    assert line.startswith(f"wbc: error: {out}: --out is an existing directory that is not a wbc results directory")
    assert "it holds report.md, summary.json; the run would overwrite report.md, summary.json" in line
    assert _snapshot(out) == before and sorted(p.name for p in out.iterdir()) == ["report.md", "summary.json"]


def test_hw_run_refuses_a_directory_of_other_files_before_it_connects(short, tmp_path) -> None:
    from conftest import hw_run_arm_in_lockstep

    out = _not_results(tmp_path)
    before = _snapshot(out)
    with pytest.raises(ResultsDirError, match="not a wbc results directory"):
        hw_run_arm_in_lockstep(str(short), str(out), 0.1)
    assert _snapshot(out) == before


def test_an_empty_directory_or_a_results_directory_is_a_runs(tmp_path) -> None:
    """Empty (a lock file aside), or holding run.json or trials.csv (resumed or refused as that run decides): taken."""
    for held in ((), (LOCK_FILE,), ("run.json",), ("trials.csv", "notes.txt")):
        out = tmp_path / f"d{len(list(tmp_path.iterdir()))}"
        out.mkdir()
        for name in held:
            (out / name).write_text("")
        results_module.check_out_dir(out)
    with pytest.raises(ResultsDirError, match=r"it holds notes\.txt; choose another --out"):
        results_module.check_out_dir(_holding(tmp_path / "other", "notes.txt"))


def _holding(out: Path, name: str) -> Path:
    out.mkdir()
    (out / name).write_text("")
    return out
