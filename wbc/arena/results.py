"""`ResultsStore`: a results directory that never loses a finished trial, and trusts nothing it did not write.

Each finished trial is appended to ``trials.csv`` as one line and flushed to disk (fsync) before the next is
accepted, so a run killed at any moment keeps everything it finished; a line cut short by the kill is dropped when
the store is reopened. Every row carries a checksum of its cells, and a row that fails it, does not parse, holds an
impossible value, belongs to another scenario file or repeats a trial is refused on reopening with its file and line
(`wbc.arena.trial_record.scan_csv`), unless the run asks for such rows to be dropped and played again
(``--drop-bad-rows``). ``run.json`` holds the run's identity (`wbc.arena.identity.RunIdentity`: the resolved
configuration and scenario hash), the environment the run began under (package versions, CPU, git revision ...:
`wbc.provenance.provenance`; kept on a resume, which is compared with it: `wbc.arena.run_environment`) and what each
controller is (its kind, a plug-in's
target and distribution version, the sha256 of every file it was built from: weights, an ONNX model and its external
data, an I/O or configuration file); it is read back as strictly as a scenario (`RunIdentity.from_json`: every
field known and of its type), and reopening a directory for another run is refused, naming the fields that differ.
The paths the run will write are checked before any trial is played (`check_out_dir`). A run holds its directory
locked (`LOCK_FILE`) from before it reads anything there until it is done: a second run on it, with or without
``--resume``, is refused, naming the pid of the one that holds it. A command that writes files of its own beside the
run's (``wbc paper``: ``paper.txt``, ``paper.json``) takes the lock first (`hold_results_dir`) and hands it to the
store, so that the directory stays held until those files are written too; refused or interrupted before the run
stored anything there, it leaves no directory it created.

Everything else a results directory holds is derived from ``trials.csv`` (`DERIVED_FILES`: ``summary.json``,
``failures.json``, ``report.md``, the plots, a paper's ``paper.json`` and ``paper.txt``), and ``run.json``'s
``complete`` (`mark_complete`), written last, says the run ended with them: a resume removes them all, and that mark,
before it touches ``trials.csv`` or plays a trial, so that a directory never shows a summary of other trials than it
holds; they are computed again from ``trials.csv`` at its end. ``run.json`` also records how each call ran
(``sessions``: the command line, working directory, executor, workers, time limit, UTC start and end), the command
that wrote the directory (``command``: a resume by another is refused), the trial time limit (``trial_time_limit_s``:
a resume with another is refused), and copies of the input files (``inputs``, under ``inputs/``); a checkout's
uncommitted changes are kept as ``wbc.diff`` (and ``wbc-resume-N.diff`` for a resume under other ones).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import errno
import hashlib
import json
import os
import re
import shutil
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from wbc.arena import run_environment
from wbc.arena.error_guard import DEFAULT_MAX_CONSECUTIVE_ERRORS
from wbc.arena.identity import RunIdentity, compared, moved_files, publication_change
from wbc.arena.trial_record import RefusedRow, TrialRecord, scan_csv
from wbc.errors import InputFileError, RecordError, ResultsDirError
from wbc.input_files import read_json
from wbc.output_files import LOCK_FILE, DirectoryInUse, DirectoryLock, directory_holder, lock_directory, write_text
from wbc.provenance import git_diff, provenance

__all__ = ["DERIVED_FILES", "INPUTS_DIR", "LOCK_FILE", "OUTPUT_FILES", "ResultsStore", "check_not_held",
           "check_out_dir", "derived_files_present", "episode_path", "file_name_part", "hold_results_dir",
           "holds_results", "is_complete", "mark_complete", "unwritable", "utc_now"]

OUTPUT_FILES = ("trials.csv", "run.json", "summary.json", "failures.json", "report.md", "push_recovery.png",
                "ttf.png", "tracking.png")
"""The files a results directory holds (`ResultsStore`, `wbc.arena.finish.finish_results`)."""


DERIVED_FILES = ("summary.json", "failures.json", "report.md", "push_recovery.png", "ttf.png", "tracking.png",
                 "paper.json", "paper.txt")
"""The files of a results directory computed from its ``trials.csv`` at a run's end (``paper.*``: ``wbc paper``'s):
a resume removes them before any trial plays, and its end writes them again."""

INPUTS_DIR = "inputs"
"""Where a results directory keeps copies of its input files (the scenario, each ``--controller-config``)."""

DIFF_FILE = "wbc.diff"
"""Where a results directory keeps the uncommitted changes of the checkout the run began in."""

_RUN_KEYS = ("config", "environment", "controllers", "command", "trial_time_limit_s", "sessions", "inputs",
             "complete")
"""The top-level fields of ``run.json``."""

_SAME_COMMAND = {"run": "arena", "compare": "arena"}
"""Commands that write the same kind of directory (``wbc run`` is ``wbc compare`` of one controller)."""


def utc_now() -> str:
    """The time now, UTC, as ``run.json`` records it (ISO 8601, seconds)."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def derived_files_present(out_dir: Path) -> list[str]:
    """The `DERIVED_FILES` `out_dir` holds, in that order."""
    return [name for name in DERIVED_FILES if (Path(out_dir) / name).is_file()]


def is_complete(out_dir: Path) -> bool:
    """Whether `out_dir`'s ``run.json`` carries the mark of a run ended with its derived files (`mark_complete`)."""
    try:
        run = json.loads((Path(out_dir) / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(run, dict) and isinstance(run.get("complete"), dict)


def mark_complete(out_dir: Path, trials: int) -> None:
    """Mark `out_dir`'s run complete: ``run.json``'s ``complete`` (its trials, when) and its last session's end.

    Written last, once every file of the directory is written (a caller that writes files of its own beside the
    run's, ``wbc paper``, marks it after them); a resume removes the mark before it touches anything.

    Raises:
        ResultsDirError: ``run.json`` cannot be read or written.
    """
    path = Path(out_dir) / "run.json"
    try:
        run = json.loads(path.read_text(encoding="utf-8"))
        now = utc_now()
        sessions = run.get("sessions")
        if isinstance(sessions, list) and sessions and isinstance(sessions[-1], dict):
            sessions[-1]["ended_utc"] = now
        run["complete"] = {"trials": trials, "ended_utc": now}
        write_text(path, json.dumps(run, indent=2))
    except (OSError, ValueError) as exc:
        raise ResultsDirError(f"{path}: cannot mark the run complete ({exc}); the same command with --resume writes "
                              "its files again") from exc


def check_out_dir(out_dir: Path) -> None:
    """Refuse an output directory the run could not complete, before any trial is played.

    An existing directory is a run's only if it is empty (its lock file aside) or a results directory, one that holds
    ``run.json`` or ``trials.csv`` (whose run is then resumed, or refused, as `ResultsStore` decides): any other
    directory holds someone's files, which the run's own (``summary.json``, ``report.md`` ...) would replace without a
    word.

    Raises:
        ResultsDirError: `out_dir` exists and is not a directory (a file), or is a directory that is neither empty nor
            a results directory (the message names what it holds), or one of the files it will write
            (`OUTPUT_FILES`) exists as something else than a file (a directory); the message says what to move.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ResultsDirError(f"{out}: --out is an existing file, not a directory; choose another --out, or move the "
                              "file away")
    for name in OUTPUT_FILES:
        path = out / name
        if path.exists() and not path.is_file():
            raise ResultsDirError(f"{path}: the run writes this file, but it is a directory (or not a regular file); "
                                  "move it away, or choose another --out")
    if out.is_dir():
        _check_results_or_empty(out)


def _check_results_or_empty(out: Path) -> None:
    """Refuse `out`, an existing directory, if it holds files and is not a results directory (`check_out_dir`)."""
    try:
        held = sorted(entry.name for entry in out.iterdir() if entry.name != LOCK_FILE)
    except OSError as exc:
        raise ResultsDirError(f"{out}: --out cannot be read ({exc.strerror or exc}); choose another --out") from None
    if not held or {"run.json", "trials.csv"} & set(held):
        return
    shown = ", ".join(held[:5]) + (f" and {len(held) - 5} more" if len(held) > 5 else "")
    replaced = [name for name in held if name in OUTPUT_FILES]
    what = f"; the run would overwrite {', '.join(replaced)}" if replaced else ""
    raise ResultsDirError(f"{out}: --out is an existing directory that is not a wbc results directory (no run.json "
                          f"or trials.csv) and is not empty: it holds {shown}{what}; choose another --out, or an "
                          "empty or new directory")


def unwritable(path: str | Path, exc: OSError, out_dir: Path, *, stored: int,
               resumable: bool = True) -> ResultsDirError:
    """The error of a results file that could not be written: one line, what failed, what is kept, how to go on.

    Every row of ``trials.csv`` written before is kept (each was flushed to disk as its trial finished), so the same
    command with ``--resume`` finishes the run: once there is room, for a full disk or quota (ENOSPC, EDQUOT), or
    once the directory can be written, for anything else (no permission, a read-only file system).

    Args:
        path: the file (or directory) that could not be written.
        exc: what writing it raised.
        out_dir: the results directory.
        stored: the trials stored in its ``trials.csv``.
        resumable: the run can be resumed (``--resume``); off: a hardware trial, which is played again instead.
    """
    why = exc.strerror or str(exc)
    room = exc.errno in (errno.ENOSPC, errno.EDQUOT)
    if not resumable:
        return ResultsDirError(f"{path}: cannot be written ({why}); the results in {out_dir} are incomplete, and a "
                               "hardware trial is not resumed: " + ("free some space, then play the trial again with "
                                                                    "another --out" if room else
                                                                    "play the trial again with a writable --out"))
    kept = (f"the {stored} trial(s) finished are kept in {Path(out_dir) / 'trials.csv'}" if stored else
            "no trial was stored yet")
    when = "once there is room" if room else f"once {out_dir} can be written"
    return ResultsDirError(f"{path}: cannot be written ({why}); {kept}: the same command with --resume --out "
                           f"{out_dir} finishes the run {when}")


def holds_results(out_dir: Path, *, resumable: bool = True) -> ResultsDirError:
    """The refusal of a results directory that holds results already (its ``trials.csv``).

    Args:
        out_dir: the directory.
        resumable: the run can be resumed, and the message says how (``--resume``); off: a hardware trial, which is
            played once.
    """
    if not resumable:
        return ResultsDirError(f"{out_dir}: already holds results; a hardware trial is played once: choose another "
                               "--out")
    return ResultsDirError(f"{out_dir}: already holds results; pass --resume to finish that run, or choose another "
                           "--out")


def _lock(out_dir: Path) -> DirectoryLock:
    """Hold `out_dir` for this run (`wbc.output_files.lock_directory`): ``LOCK_FILE``, locked, with this pid in it.

    The lock is the OS's (``flock``): it goes when its file is closed or the process ends, however it ends, so a
    killed run leaves nothing to clean up.

    Raises:
        ResultsDirError: another process holds it (the message names its pid, as written in the file), or the lock
            file cannot be opened or locked.
    """
    try:
        return lock_directory(out_dir)
    except DirectoryInUse as held:
        raise _in_use(out_dir, held) from None
    except OSError as exc:
        raise ResultsDirError(f"{out_dir / LOCK_FILE}: cannot open or lock the results directory's lock file "
                              f"({exc.strerror or exc}); move it away, or choose another --out") from None


def _in_use(out_dir: Path, held: DirectoryInUse) -> ResultsDirError:
    """The refusal of a results directory another process holds: it names the holder's pid where its file has it."""
    holder = f" (pid {held.pid})" if held.pid is not None else ""
    return ResultsDirError(f"{out_dir} is in use by another wbc run{holder}; wait for it to end, or give another --out")


def check_not_held(out_dir: Path) -> None:
    """Refuse a results directory another process holds, without taking it (`wbc.output_files.directory_holder`).

    A command that checks its input before it takes its directory (``wbc paper``) asks first, so that a held
    directory is refused before any controller is built; the lock, taken once the run starts, still refuses a run
    that took the directory in between.

    Raises:
        ResultsDirError: another process holds it (the message names its pid), as taking its lock would say.
    """
    held = directory_holder(out_dir)
    if held is not None:
        raise _in_use(Path(out_dir), held)


def _make_dir(out_dir: Path) -> tuple[Path, ...]:
    """Create `out_dir` (and its parents) if missing.

    Returns:
        The directories this call created, outermost first (none where `out_dir` existed); one that another process
        created meanwhile is not among them.

    Raises:
        ResultsDirError: it cannot be created; the message says to choose another ``--out``.
    """
    missing = []
    for folder in (out_dir, *out_dir.parents):
        if os.path.lexists(folder):
            break
        missing.append(folder)
    made = []
    try:
        for folder in reversed(missing):
            with contextlib.suppress(FileExistsError):  # made meanwhile by another process: not this call's
                folder.mkdir()
                made.append(folder)
        out_dir.mkdir(parents=True, exist_ok=True)  # refuses an `out_dir` that exists as something else
    except OSError as exc:
        _remove_made(made)
        raise ResultsDirError(f"{out_dir}: cannot be created ({exc.strerror or exc}); choose another --out, or "
                              "make its parent directory writable") from exc
    return tuple(made)


def _remove_made(made: Sequence[Path]) -> None:
    """Remove the directories `_make_dir` created, innermost first, each only while empty."""
    for folder in reversed(made):
        try:
            folder.rmdir()
        except OSError:
            return  # not empty (or gone): it and its parents stay


@contextlib.contextmanager
def hold_results_dir(out_dir: Path) -> Iterator[DirectoryLock]:
    """Hold a results directory (created if missing) for a command that writes files of its own beside a run's.

    The lock is the one a `ResultsStore` takes (`LOCK_FILE`); handed to the store (its ``lock``, through
    `wbc.arena.compare.play_arena`), it is used by the store and outlives it, so that the directory stays held after
    the run's own files are written, until the caller has written its own and the ``with`` block ends (or `release`
    gives it back earlier). A second run on the directory, with or without ``--resume``, is refused meanwhile.

    A block that ends by an exception (a refusal, Ctrl-C) while the directory holds nothing but its lock file, the
    run having stored nothing there, leaves no trace of a directory this call created: the lock file is removed while
    still held, then the directory and the parents created with it, each while empty. A directory that existed
    before stays, and so does one that holds anything else (``trials.csv``, even without a trial in it).

    Raises:
        ResultsDirError: `out_dir` is a file, or a file a run writes there is a directory (`check_out_dir`); it
            cannot be created; or another process holds it (the message names its pid).
    """
    out = Path(out_dir)
    check_out_dir(out)
    made = _make_dir(out)
    try:
        lock = _lock(out)
    except BaseException:
        _remove_made(made)  # a lock file there, whoever made it, keeps it
        raise
    try:
        yield lock
    except BaseException:
        if out in made and lock.held and _holds_only_its_lock(out):
            with contextlib.suppress(OSError):
                (out / LOCK_FILE).unlink()
            lock.release()
            _remove_made(made)
        raise
    finally:
        lock.release()


def _holds_only_its_lock(out_dir: Path) -> bool:
    """Whether `out_dir` holds its lock file and nothing else."""
    try:
        return [entry.name for entry in out_dir.iterdir()] == [LOCK_FILE]
    except OSError:
        return False


_MISSING = object()

_DEFAULTS = {"max_consecutive_errors": DEFAULT_MAX_CONSECUTIVE_ERRORS}
"""The options ``run.json``'s ``config`` leaves out at their default (`wbc.arena.identity`), with that default: a
message names an absent one by it."""


def _differences(stored: Mapping[str, Any], given: Mapping[str, Any], *, most: int = 4) -> str:
    """The first `most` fields in which two run configurations differ, each with its stored and its given value.

    Nested objects (the scenario's name, version and hash) are followed to the field that differs, so another scenario
    file reads as its hash, not as "scenario".
    """
    found: list[str] = []

    def walk(a: object, b: object, name: str) -> None:
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            for key in sorted(set(a) | set(b)):
                walk(a.get(key, _MISSING), b.get(key, _MISSING), f"{name}.{key}" if name else str(key))
        elif a != b:
            found.append(f"{name} stored {_shown(a, default=_DEFAULTS.get(name))}, given "
                         f"{_shown(b, default=_DEFAULTS.get(name))}")

    walk(stored, given, "")
    more = f" (and {len(found) - most} more)" if len(found) > most else ""
    return "; ".join(found[:most]) + more


def _shown(value: object, width: int = 80, *, default: object = None) -> str:
    """A configuration value as a message shows it: its JSON; "none" when absent ("the default (D)": at `default`).

    A string (a path, a hash) is shown whole up to 200 characters, and beyond by its two ends, where paths differ;
    anything else up to `width` characters, then its beginning.
    """
    if value is _MISSING:
        return "none" if default is None else f"the default ({json.dumps(default)})"
    text = json.dumps(value, sort_keys=True)
    if isinstance(value, str):
        return text if len(text) <= 200 else f"{text[:97]}...{text[-100:]}"
    return text if len(text) <= width else text[: width - 3] + "..."


def file_name_part(controller: str) -> str:
    """A controller name as one part of a file or directory name (``onnx:runs/x/p.onnx`` -> ``onnx_runs_x_p.onnx``).

    Each run of characters other than letters, digits, ``.``, ``_`` and ``-`` becomes ``_``.
    """
    return re.sub(r"[^A-Za-z0-9._-]+", "_", controller)


def episode_path(out_dir: Path, controller: str, band: str, seed: int, index: int) -> Path:
    """Where a results directory keeps a trial's episode log (``wbc run --save-episodes``).

    A controller name that is not a plain word (``policy:runs/x/policy``) becomes one directory (`file_name_part`).
    """
    return Path(out_dir) / "episodes" / file_name_part(controller) / f"{band}-s{seed}-t{index}.npz"


def _outside(identity: RunIdentity) -> Callable[[TrialRecord], str | None]:
    """Why a stored record is not one of `identity`'s trials (its band, seed or trial index), or None."""
    bands, seeds, trials = set(identity.bands), set(identity.seeds), set(identity.trials_played)

    def why(record: TrialRecord) -> str | None:
        if record.band not in bands:
            return f"band {record.band!r} is not one of this run's ({', '.join(identity.bands)})"
        if record.seed not in seeds:
            return f"seed {record.seed} is not one of this run's ({', '.join(map(str, identity.seeds))})"
        if record.trial not in trials:
            return (f"trial {record.trial} is not one of this run's (0 to {max(trials)} per band and seed)"
                    if trials == set(range(len(trials))) else f"trial {record.trial} is not this run's")
        return None

    return why


def _file_sha256(path: str | Path) -> str:
    """The sha256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _changed_code(stored: Mapping[str, Any], current: Mapping[str, Any]) -> str | None:
    """What of a controller's code or files differs between a stored run's ``controllers`` and this run's, or None.

    Compared where both sides hashed it: each file's sha256 by role and path, and a plug-in module's sha256.
    """
    for name, now in current.items():
        before = stored.get(name)
        if not isinstance(before, Mapping) or not isinstance(now, Mapping):
            continue
        old_plugin, new_plugin = before.get("plugin") or {}, now.get("plugin") or {}
        old_hash, new_hash = old_plugin.get("module_sha256"), new_plugin.get("module_sha256")
        if old_hash and new_hash and old_hash != new_hash:
            return (f"controller {name}'s module {new_plugin.get('module_file')} (sha256 {old_hash[:12]}... then, "
                    f"{new_hash[:12]}... now)")
        old_files = {(f.get("role"), f.get("path")): f.get("sha256") for f in before.get("files") or ()
                     if isinstance(f, Mapping)}
        for f in now.get("files") or ():
            was = old_files.get((f.get("role"), f.get("path")))
            if was and f.get("sha256") and was != f["sha256"]:
                return f"controller {name}'s {f.get('role')} file {f.get('path')} (sha256 {was[:12]}... then, " \
                       f"{f['sha256'][:12]}... now)"
    return None


class ResultsStore:
    """A results directory, held locked by this process until `close` (a second run on it is refused).

    Args:
        out_dir: the directory (created if missing).
        identity: what the run is; when resuming, its JSON form must equal the stored one (``run.json``'s
            ``config``) but for the paths its files were given by (`wbc.arena.identity.compared`: a file given by
            another path, with the same hash, is noted on stderr); unset options are absent from both.
        resume: continue a run already in `out_dir`; without it, a directory holding trials is refused.
        controllers: what each controller is, by name (`wbc.control.spec.ControllerSpec.provenance`: its kind, a
            plug-in's target and distribution version, the sha256 of every file it was built from), recorded in
            ``run.json`` beside the configuration.
        drop_bad_rows: drop the rows of ``trials.csv`` that are refused (`wbc.arena.trial_record.scan_csv`), with one
            warning line each on stderr, so that their trials are played again; off: such rows are refused.
        resumable: the run can be resumed (``--resume``), as its messages then say; off: a hardware trial.
        lock: the directory's lock, already held by the caller (`hold_results_dir`), who gives it back after `close`;
            None: the store takes the lock and gives it back on `close`.
        session: how this call runs, recorded in ``run.json``'s ``sessions`` (one entry per call, with its UTC start,
            and its end once `mark_complete` marks the run): ``command`` (the wbc command: ``compare``, ``paper
            table1`` ..., recorded as ``run.json``'s ``command``; a resume by another is refused), ``command_line``,
            ``cwd``, ``executor``, ``workers`` and ``trial_time_limit_s`` (recorded as ``run.json``'s
            ``trial_time_limit_s``; a resume with another is refused). None: nothing recorded or compared.
        inputs: the input files to keep a copy of, by role (``scenario``, ``controller-config NAME``): copied under
            `INPUTS_DIR` and recorded with their sha256 in ``run.json``'s ``inputs``; a resume checks the files given
            against the copies' hashes.

    Raises:
        ResultsDirError: `out_dir` is a file, or a file the run writes is a directory (`check_out_dir`); another
            process holds it (a run still going: `LOCK_FILE`); it holds results and `resume` is off, or holds another
            run (the message names the fields that differ), or its ``run.json`` is unreadable or missing beside
            stored trials; or a file of it cannot be written (a full disk, no permission: `unwritable`).
        RecordError: its ``run.json`` is malformed (the message names the field), its ``trials.csv`` has other
            columns, or holds a refused row and `drop_bad_rows` is off (the message names the file and line).
        ResultsDirError: a resume, with trials stored, under other versions of packages that change results than the
            run began under (`wbc.arena.run_environment.refusal`); a resume under another environment otherwise is
            a warning on stderr, recorded in ``run.json`` (`wbc.arena.run_environment`).
        ValueError: `lock` is given back already, or is another directory's (a caller's mistake, not the user's).

    Attributes:
        dir: the directory.
        identity: the run's identity, as given.
        environment: what ``run.json`` records of the environment (`wbc.provenance.provenance`): the one the run
            began under, kept on every resume, with ``resumes`` listing each resume under another one (what changed,
            the trials stored before it: `wbc.arena.run_environment`).
        records: the trials stored, in the order they finished.
        dropped: the rows of ``trials.csv`` dropped on opening (with `drop_bad_rows`), in file order.
        resumable: as given.
    """

    def __init__(self, out_dir: Path, identity: RunIdentity, *, resume: bool,
                 controllers: dict[str, object] | None = None, drop_bad_rows: bool = False,
                 resumable: bool = True, lock: DirectoryLock | None = None,
                 session: Mapping[str, Any] | None = None, inputs: Mapping[str, Path] | None = None) -> None:
        self.dir = Path(out_dir)
        self.resumable = resumable
        self.identity = identity
        self.trials_path = self.dir / "trials.csv"
        self.run_path = self.dir / "run.json"
        if lock is not None and not (lock.held and lock.path.resolve() == (self.dir / LOCK_FILE).resolve()):
            raise ValueError(f"ResultsStore({self.dir}): the lock given is "
                             + ("released" if not lock.held else f"another directory's ({lock.path})")
                             + "; give the one hold_results_dir gives for this directory, still held")
        check_out_dir(self.dir)
        _make_dir(self.dir)
        # held until `close`, taken before anything in the directory is read or rewritten: a second run on it would
        # replace trials.csv under this one, whose appends would then go to a deleted file; a lock the caller holds
        # is the caller's to give back
        self._owns_lock = lock is None
        self._lock: DirectoryLock | None = _lock(self.dir) if lock is None else lock
        self._file = None
        self._failed = False  # a write of trials.csv failed: closing it does not try again
        self.records: list[TrialRecord] = []
        try:
            self._open(identity.as_json(), resume=resume, controllers=controllers, drop_bad_rows=drop_bad_rows,
                       session=dict(session) if session is not None else None, inputs=dict(inputs or {}))
        except BaseException:
            self.close()
            raise

    def _open(self, config: dict, *, resume: bool, controllers: dict[str, object] | None,
              drop_bad_rows: bool, session: dict[str, Any] | None, inputs: dict[str, Path]) -> None:
        """Check the directory against this run, read its trials and write ``run.json`` (the lock held)."""
        if self.trials_path.exists() and not resume:
            raise holds_results(self.dir, resumable=self.resumable)
        self._stored_run: dict[str, Any] = {}
        if resume and self.run_path.exists():
            # validated as a RunIdentity (every field known and typed), then compared as JSON: a stored run of
            # another kind or with other options is named field by field as differing
            stored = self._stored_config()
            before, now = compared(stored), compared(config)  # files by their hashes, not by the paths given
            if before != now:
                diff = sorted(k for k in set(before) | set(now) if before.get(k) != now.get(k))
                raise ResultsDirError(f"{self.dir}: --resume with a different configuration (differs in: "
                                      f"{', '.join(diff)}): {_differences(before, now)}; rerun with the original "
                                      "options or another --out")
            self._check_session(session)
            self._check_inputs(inputs)
            moved = list(moved_files(stored, config))
            start = self._stored_environment
            changed = _changed_code(self._stored_controllers, controllers or {})
            if changed:
                raise ResultsDirError(f"{self.run_path}: --resume with {changed} changed since the run began: its "
                                      "stored trials were played by the earlier one, and a run mixes no two; restore "
                                      "it, or start afresh with another --out")
            at_start = publication_change(stored, config)
            # said when this call finds it otherwise than the last one; recorded as long as it differs from the start
            republished = stored.get("scenario", {}).get("published") != config["scenario"]["published"]
            if at_start is not None:  # the same content: run.json records both what was and what is
                scenario = dataclasses.replace(self.identity.scenario, published_at_start=at_start)
                self.identity = dataclasses.replace(self.identity, scenario=scenario)
                config = self.identity.as_json()
        else:
            moved, at_start, republished, start = [], None, False, None
        environment = dict(provenance())  # taken once: what run.json records and the report shows
        self.dropped: tuple[RefusedRow, ...] = ()
        if self.trials_path.exists():
            rows = scan_csv(self.trials_path, scenario_hash=self.identity.scenario_hash,
                            outside=_outside(self.identity))
            if rows.records and not self.run_path.exists():
                raise ResultsDirError(f"{self.run_path}: missing, so the run the {len(rows.records)} stored trial(s) "
                                      "of trials.csv belong to is unknown; restore run.json, or start afresh with "
                                      "another --out")
            if rows.refused and not drop_bad_rows:
                raise RecordError(rows.refusal(self.trials_path, "pass --drop-bad-rows to play those trials again, "
                                                                 "or restore the file"))
            found = self._environment_changes(start, environment, len(rows.records))
            for bad in rows.refused:
                print(f"wbc: warning: {self.trials_path}:{bad.line}: {bad.reason}; row dropped (--drop-bad-rows), "
                      "its trial is played again", file=sys.stderr)
            self.records, self.dropped = list(rows.records), rows.refused
            if resume:
                self._invalidate()
            # rewrite without a torn last line (so appends start on a fresh line) and without the rows dropped, with
            # this version's columns
            with self._writing(self.trials_path):
                self._rewrite()
        else:
            found = []
            with self._writing(self.trials_path):
                try:  # created, never overwritten: a file that appeared since is another run's
                    f = self.trials_path.open("x", encoding="utf-8", newline="")
                except FileExistsError:
                    raise holds_results(self.dir, resumable=self.resumable) from None
                with f:
                    csv.writer(f).writerow(TrialRecord.header())
        for what, was, given in moved:  # said once the resume is sure to go on
            print(f"wbc: note: {self.run_path}: {what} is given as {_shown(given)}, the run's was "
                  f"{_shown(was)}: the same content, so the run resumes, and run.json records the path given",
                  file=sys.stderr)
        if republished:
            published = bool(config["scenario"]["published"])
            now = "published now (a lock lists its hash)" if published else "not published now (no lock lists its hash)"
            said = (f"and {'was' if at_start else 'was not'} when the run began: the same content, so the run "
                    f"resumes, and run.json records both (scenario.published {str(published).lower()}, "
                    f"scenario.published_at_start {str(at_start).lower()})" if at_start is not None else
                    "as when the run began, not as at its last call: the same content, so the run resumes")
            print(f"wbc: note: {self.run_path}: the scenario is {now}, {said}", file=sys.stderr)
        begins = not (start and self.records)  # a run with no trial stored yet begins under this environment
        diff_file = self._keep_diff(environment, start, found, begins=begins)
        if begins and diff_file is not None:
            environment["git_diff_file"] = diff_file
        if found:
            print(run_environment.warning(self.run_path, found, len(self.records), diff_file=diff_file),
                  file=sys.stderr)
        # what `run.json` records, and the report shows: the environment the run began under, kept on every resume
        # with the resumes under another one; a run with no trial stored yet begins under this one
        self.environment = (environment if begins else
                            run_environment.record(start, found, len(self.records), diff_file=diff_file))
        run: dict[str, Any] = {"config": config, "environment": self.environment}
        if controllers:
            run["controllers"] = controllers
        run.update(self._execution(session, inputs))
        with self._writing(self.run_path):
            write_text(self.run_path, json.dumps(run, indent=2))  # whole or not at all: the stored trials need it
        with self._writing(self.trials_path):
            self._file = self.trials_path.open("a", encoding="utf-8", newline="")
        self._writer = csv.writer(self._file)

    def _check_session(self, session: dict[str, Any] | None) -> None:
        """Refuse a resume by another command, or with another trial time limit, than ``run.json`` records.

        A directory written before these were recorded (no ``command``, no ``trial_time_limit_s``) takes any, but
        one holding a ``paper.json`` takes only ``wbc paper``.
        """
        stored = self._stored_run
        if session is None:
            return
        was, now = stored.get("command"), session.get("command")
        if was is None and now is not None and not now.startswith("paper") and (self.dir / "paper.json").is_file():
            # written before the command was recorded: its paper.json says wbc paper wrote it, whose files a resume
            # by another command would remove and not write again
            raise ResultsDirError(f"{self.run_path}: field command: the run was written by wbc paper (its paper.json "
                                  f"says so), and a resume by wbc {now} would remove its paper files and not write "
                                  "them again; finish it with wbc paper TABLE ... --resume, or choose another --out")
        if was is not None and now is not None and _SAME_COMMAND.get(was, was) != _SAME_COMMAND.get(now, now):
            raise ResultsDirError(f"{self.run_path}: field command: the run was written by wbc {was}, and a resume "
                                  f"by wbc {now} would not write its files (wbc {was}'s own); finish it with wbc "
                                  f"{was} ... --resume, or choose another --out")
        if "trial_time_limit_s" in stored and stored["trial_time_limit_s"] != session.get("trial_time_limit_s"):
            def said(limit: object) -> str:
                return "none (no --trial-time-limit)" if limit is None else f"{limit:g} s"
            raise ResultsDirError(f"{self.run_path}: field trial_time_limit_s: --resume with another trial time limit "
                                  f"(stored {said(stored['trial_time_limit_s'])}, given "
                                  f"{said(session.get('trial_time_limit_s'))}): a trial past it is its controller's "
                                  "error, so the run's trials would be judged by two limits; rerun with the stored "
                                  "--trial-time-limit (or none), or start afresh with another --out")

    def _check_inputs(self, inputs: dict[str, Path]) -> None:
        """Refuse a resume whose input files differ from the copies the run kept (``run.json``'s ``inputs``).

        Each file's bytes are compared with its copy's, and the copy with the hash recorded: a scenario whose content
        is the run's (its hash in ``config``, compared before) but whose bytes are not (comments, layout) is a note.
        A role the run kept no copy of (a directory written before copies were kept, or copied without ``inputs/``)
        is not compared: its file given is kept then, its content already compared by its hash in ``config``.
        """
        kept = self._stored_run.get("inputs") or {}
        for role, path in inputs.items():
            entry = kept.get(role)
            if not isinstance(entry, Mapping):
                continue
            copy = self.dir / str(entry.get("copy"))
            if not copy.is_file():  # a directory copied without it: kept again from the file given (`_execution`)
                continue
            try:
                given, copied = _file_sha256(path), _file_sha256(copy)
            except OSError as exc:
                raise ResultsDirError(f"{self.run_path}: field inputs.{role}: cannot read {exc.filename} "
                                      f"({exc.strerror or exc}); restore {copy} (the copy of the run's {role} file), "
                                      "or start afresh with another --out") from None
            if copied != entry.get("sha256"):
                raise ResultsDirError(f"{copy}: the run's copy of its {role} file was changed (sha256 {copied}, "
                                      f"run.json field inputs.{role}.sha256 {entry.get('sha256')}); restore it, or "
                                      "start afresh with another --out")
            if given != copied and role == "scenario":  # its content is compared by its hash (config.scenario)
                print(f"wbc: note: {path}: the scenario's content is the run's (its hash), its bytes (comments, "
                      f"layout) are not; {copy} keeps the file the run began with", file=sys.stderr)
            elif given != copied:
                raise ResultsDirError(f"{path}: --resume with another {role} file than the run was played with "
                                      f"(sha256 {given}; the run's copy {copy}: {copied}); give the run's file "
                                      f"(--resume reads {copy} as it was), or start afresh with another --out")

    def _invalidate(self) -> None:
        """Remove what a finished run derived from ``trials.csv`` (`DERIVED_FILES`) and its ``complete`` mark.

        Done by a resume before it touches ``trials.csv`` or plays a trial: an interrupted resume then leaves no
        summary, report or plot of other trials than the directory holds. Its end writes them all again.
        """
        if "complete" in self._stored_run:  # the mark first: a directory is never marked without its files
            run = {k: v for k, v in self._stored_run.items() if k != "complete"}
            with self._writing(self.run_path):
                write_text(self.run_path, json.dumps(run, indent=2))
        for name in DERIVED_FILES:
            path = self.dir / name
            with self._writing(path):
                if path.is_file():
                    path.unlink()

    def _keep_diff(self, environment: dict[str, Any], start: dict | None, found: list[run_environment.Change], *,
                   begins: bool) -> str | None:
        """Write this checkout's uncommitted changes into the directory where the run needs them; their file's name.

        At the run's start (`begins`) to `DIFF_FILE`, for a checkout with uncommitted changes; on a resume whose
        changes differ from the start's (``git_diff_sha256`` among `found`), to ``wbc-resume-N.diff`` (N: the
        resume's number among those recorded). None where nothing is written.
        """
        if not str(environment.get("git_revision", "")).endswith("-dirty"):
            return None
        if begins:
            name = DIFF_FILE
        elif any(c.field == "git_diff_sha256" for c in found):
            name = f"wbc-resume-{len((start or {}).get('resumes') or []) + 1}.diff"
        else:
            return None
        diff = git_diff()
        if diff is None:
            return None
        path = self.dir / name
        with self._writing(path):
            path.write_bytes(diff)
        return name

    def _execution(self, session: dict[str, Any] | None, inputs: dict[str, Path]) -> dict[str, Any]:
        """``run.json``'s fields of how the run is executed, those of the stored run kept.

        ``command``, ``trial_time_limit_s``, ``sessions`` (this call's appended) and ``inputs`` (copied here where the
        run has no copy yet).
        """
        stored = self._stored_run
        out: dict[str, Any] = {}
        sessions = list(stored.get("sessions") or [])
        if session is not None:
            command = stored.get("command", session.get("command"))
            if command is not None:
                out["command"] = command
            if "trial_time_limit_s" in stored or not self.records:
                out["trial_time_limit_s"] = stored.get("trial_time_limit_s", session.get("trial_time_limit_s"))
            # else: trials were stored under a limit never recorded; the run's is unknown (each session has its own)
            sessions.append({**{k: v for k, v in session.items() if k != "command"},
                             "started_utc": utc_now(), "ended_utc": None, "stored_trials": len(self.records)})
        else:
            out.update({k: stored[k] for k in ("command", "trial_time_limit_s") if k in stored})
        if sessions:
            out["sessions"] = sessions
        kept = dict(stored.get("inputs") or {})
        # the copies' names told apart case-folded: two roles that differ only in case (labels H8 and h8), or that
        # one name stands for, would be one file on a case-insensitive file system
        taken = {str(entry.get("copy")).casefold() for entry in kept.values() if isinstance(entry, Mapping)}
        for role, path in inputs.items():
            if role in kept and (self.dir / str(kept[role].get("copy"))).is_file():
                continue
            copy, k = Path(INPUTS_DIR) / f"{file_name_part(role)}-{Path(path).name}", 2
            while copy.as_posix().casefold() in taken:
                copy, k = Path(INPUTS_DIR) / f"{file_name_part(role)}-{k}-{Path(path).name}", k + 1
            taken.add(copy.as_posix().casefold())
            with self._writing(self.dir / copy):
                (self.dir / INPUTS_DIR).mkdir(exist_ok=True)
                shutil.copyfile(path, self.dir / copy)
            kept[role] = {"source": str(path), "copy": copy.as_posix(), "sha256": _file_sha256(self.dir / copy)}
        if kept:
            out["inputs"] = kept
        return out

    @contextlib.contextmanager
    def _writing(self, path: Path) -> Iterator[None]:
        """Turn an `OSError` of the block, which writes `path`, into its one-line error (`unwritable`)."""
        try:
            yield
        except OSError as exc:
            raise unwritable(path, exc, self.dir, stored=len(self.records), resumable=self.resumable) from exc

    def _environment_changes(self, start: dict | None, now: dict, stored: int) -> list[run_environment.Change]:
        """What differs from the environment the stored trials began under; refused for a result's package.

        Nothing is compared for a fresh run, or with no trial stored (none was played under the earlier one).

        Raises:
            ResultsDirError: another version of a package that changes results (`run_environment.refusal`).
        """
        if not start or not stored:
            return []
        found = run_environment.changes(start, now)
        refused = run_environment.refusal(self.run_path, found, stored)
        if refused is not None:
            raise ResultsDirError(refused)
        return found

    def _stored_config(self) -> dict:
        """The ``config`` of the stored ``run.json``, checked to be a run identity this version reads.

        Raises:
            ResultsDirError: not a regular file, not UTF-8, not JSON.
            RecordError: not an object of `_RUN_KEYS`, or its ``config`` is malformed (`RunIdentity.from_json`).
        """
        try:
            run = read_json(self.run_path)
        except InputFileError as exc:
            where = str(exc).removeprefix(str(self.run_path)).lstrip(":").strip()
            raise ResultsDirError(f"{self.run_path}: unreadable run configuration (at {where}); restore the file, or "
                                  "start afresh with another --out") from None
        if not isinstance(run, dict) or "config" not in run:
            raise RecordError(f"{self.run_path}: field config: missing (the file holds no run identity); restore the "
                              "file, or start afresh with another --out")
        unknown = [key for key in run if key not in _RUN_KEYS]
        if unknown:
            raise RecordError(f"{self.run_path}: field {unknown[0]}: not a field of run.json ({', '.join(_RUN_KEYS)}); "
                              "restore the file, or start afresh with another --out")
        for key in ("environment", "controllers"):
            if key in run and not isinstance(run[key], dict):
                raise RecordError(f"{self.run_path}: field {key}: expected an object, got {run[key]!r}; restore the "
                                  "file, or start afresh with another --out")
        for key, kind in (("sessions", list), ("inputs", dict)):
            if key in run and not isinstance(run[key], kind):
                raise RecordError(f"{self.run_path}: field {key}: expected {'a list' if kind is list else 'an object'}"
                                  f", got {run[key]!r}; restore the file, or start afresh with another --out")
        RunIdentity.from_json(run["config"], source=self.run_path)
        self._stored_run = run
        self._stored_controllers = run.get("controllers") or {}
        self._stored_environment = run.get("environment") or {}
        run_environment.check_stored(self._stored_environment, self.run_path)
        return run["config"]

    def _rewrite(self) -> None:
        tmp = self.trials_path.with_suffix(".tmp")
        with tmp.open("w", encoding="utf-8", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(TrialRecord.header())
            writer.writerows(r.to_row() for r in self.records)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, self.trials_path)

    def done(self) -> set[tuple[str, str, int, int]]:
        """Keys (controller, band, seed, trial) already finished."""
        return {r.run_key for r in self.records}

    def append(self, record: TrialRecord) -> None:
        """Store one finished trial durably.

        Raises:
            ResultsDirError: it could not be written (a full disk, a quota, no permission: `unwritable`); the rows
                written before are kept, and a row cut short is dropped when the directory is reopened.
        """
        try:
            with self._writing(self.trials_path):
                self._writer.writerow(record.to_row())
                self._file.flush()
                os.fsync(self._file.fileno())
        except ResultsDirError:
            self._failed = True
            raise
        self.records.append(record)

    def close(self) -> None:
        """Close the trials file and give the directory's lock back (`LOCK_FILE`); closing again does nothing.

        A lock the caller handed in (``lock``) stays held: the caller gives it back.
        """
        try:
            if self._file is not None:
                file, self._file = self._file, None
                if self._failed:  # what it still buffers is the row that failed: closed without another error
                    with contextlib.suppress(OSError):
                        file.close()
                else:
                    with self._writing(self.trials_path):
                        file.close()
        finally:
            if self._lock is not None:
                if self._owns_lock:
                    self._lock.release()
                self._lock = None
