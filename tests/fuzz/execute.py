"""Run one fuzz case and judge it: ``clean``, ``valid``, ``crash``, ``hang`` or ``silent``.

`execute` runs a case in this process. With ``full=True`` (the campaign's child process, `main`) it plays what a user
would: a scenario's trial, a controller's trial, a resumed run, ``wbc view --record``; with ``full=False`` (the
default test suite) it stops where the work would start: the loaders run for real, a command line runs up to the
call that would play trials (`STUBBED`), and a case whose input the issue calls invalid must have been refused by then.

Verdicts:

- ``clean``: a `WbcError` (or an argparse usage error), its message one short line (<= `MAX_MESSAGE` characters);
- ``valid``: exit 0 or 1, and every record plausible (`check_results`), every loaded policy finite at a plausible
  rate, every replayed frame finite with a unit quaternion;
- ``crash``: any other exception (a traceback), or an error message that is not one short line;
- ``hang``: past the time limit;
- ``silent``: finished, but implausible: a record out of range, a success with no ticks, a controller that never
  acts, or an input the issue calls invalid accepted (`Case.must_reject`).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import importlib
import io
import json
import math
import os
import pickle
import resource
import shutil
import signal
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path

from .cases import TINY_SCENARIO, Case, Dir, Link, Tree

MAX_MESSAGE = 2000
"""Longest error message that counts as clean [characters]: room for a list of valid options, not for a huge value
echoed whole."""

MAX_VELOCITY_ERROR = 50.0  # [m/s] or [rad/s]: no controller tracks a command this badly while it stands
RATE_RANGE = (1.0, 10_000.0)  # [Hz] a controller slower than 1 Hz never acts in a trial; one faster is not a rate

VERDICTS = ("clean", "valid", "crash", "hang", "silent")


@dataclass(frozen=True)
class Verdict:
    """What a case did: one of `VERDICTS`, and why (the error's first line, the implausible field)."""

    kind: str
    detail: str = ""


class Implausible(Exception):
    """A result that finished but cannot be right."""


class _Timeout(BaseException):
    """The in-process time limit ran out (a `BaseException`, so that the code under test cannot swallow it)."""


class _ReachedWork(BaseException):
    """The command got past its checks to the call that plays trials (raised by a stub in the in-process suite)."""


STUBBED = (("wbc.arena.compare", "LocalExecutor"), ("wbc.arena.compare", "RayExecutor"),
           ("wbc.control.controller_contract", "_check_one"), ("wbc.viz.view", "view_trial"))
"""What the in-process suite replaces with a stub that raises `_ReachedWork`: the calls that play trials (everything
before them, the checks of the options, the scenario, the results directory, runs for real)."""


# ------------------------------------------------------------------------------------------------- the files --

def materialize(case: Case, d: Path) -> None:
    """Write the case's files into the empty directory `d`."""
    for rel, content in case.files:
        p = d / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if p.is_symlink() or p.is_file():
            p.unlink()
        elif p.is_dir():
            shutil.rmtree(p)
        if isinstance(content, Link):
            p.symlink_to(content.target)
        elif isinstance(content, Dir):
            p.mkdir()
        elif isinstance(content, Tree):
            shutil.copytree(content.source, p, symlinks=True)
        else:
            p.write_bytes(content)


# -------------------------------------------------------------------------------------------- plausibility --

def _float(row: dict, key: str) -> float:
    try:
        return float(row[key])
    except (KeyError, TypeError, ValueError):
        raise Implausible(f"{key}={row.get(key)!r} is not a number") from None


def check_row(row: dict) -> None:
    """A stored trial's record: ttf in [0, 1], finite metrics, success consistent with outcome and with ticks."""
    success = row.get("success")
    if success not in ("True", "False"):
        raise Implausible(f"success={success!r}")
    if (success == "True") != (row.get("outcome") == "success"):
        raise Implausible(f"success={success} with outcome={row.get('outcome')!r}")
    ttf = _float(row, "ttf")
    if not 0.0 <= ttf <= 1.0:
        raise Implausible(f"ttf={ttf}")
    for key in ("seed", "trial"):
        value = _float(row, key)
        if not (0 <= value < 2**31 and value == int(value)):
            raise Implausible(f"{key}={value}")
    if "ticks" in row:
        ticks = _float(row, "ticks")
        if success == "True" and not ticks >= 2:
            raise Implausible(f"success after {ticks:g} control ticks: the controller never acted")
    for key in ("vlin_err", "vang_err"):
        value = _float(row, key)
        if math.isinf(value) or value > MAX_VELOCITY_ERROR or value < 0 or (success == "True" and math.isnan(value)):
            raise Implausible(f"{key}={value}")
    for key in ("max_roll_deg", "max_pitch_deg", "energy_j", "push_force_n", "friction", "wall_s"):
        if key in row:
            value = _float(row, key)
            if math.isinf(value) or (success == "True" and math.isnan(value)):
                raise Implausible(f"{key}={value}")
    for key in ("energy_j", "push_force_n", "friction", "wall_s", "fall_time_s", "act_ms_p50", "act_ms_p99", "ticks",
                "n_pushes", "fallbacks", "wbc_failures", "safety_trips", "deadline_misses", "clamped_ticks"):
        if key in row and _float(row, key) < 0:  # NaN (not measured) passes
            raise Implausible(f"{key}={_float(row, key)} < 0")
    if success == "True" and not math.isnan(_float(row, "fall_time_s")):
        raise Implausible(f"a success with a fall at {_float(row, 'fall_time_s')} s")


def check_results(out: Path, rows: int | None) -> None:
    """A results directory a run left: every row plausible, each trial once, one scenario; `rows` of them if given."""
    path = out / "trials.csv"
    if not path.is_file():
        raise Implausible(f"{path} missing after a run that exited 0")
    with path.open(encoding="utf-8", newline="") as f:
        records = list(csv.DictReader(f))
    keys, hashes = set(), set()
    for r in records:
        check_row(r)
        key = (r["controller"], r["band"], r["seed"], r["trial"])
        if key in keys:
            raise Implausible(f"trial {key} stored twice")
        keys.add(key)
        hashes.add(r["scenario_hash"])
    if len(hashes) > 1:
        raise Implausible(f"rows of {len(hashes)} scenario hashes")
    if rows is not None and len(records) != rows:
        raise Implausible(f"{len(records)} rows, expected {rows}")


def _finite(name: str, value: object) -> None:
    import numpy as np

    a = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(a)):
        raise Implausible(f"{name} not finite")


def _rate(ctrl: object) -> None:
    rate = getattr(ctrl, "rate_hz", None)
    if not isinstance(rate, (int, float)) or not RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
        raise Implausible(f"rate_hz={rate!r}: outside {RATE_RANGE} Hz")


def _exercise(spec: object) -> None:
    """Build a controller on its robot and act three times from the nominal posture: finite commands, a real rate."""
    import numpy as np

    from wbc.robots.registry import get_robot
    from wbc.types import RobotState, VelocityCommand

    desc = get_robot((spec.robots or ('a1-wx200',))[0], spec.arm_mode)  # a plug-in claims no robot
    ctrl = spec.make(desc)
    _rate(ctrl)
    ctrl.reset()
    n = desc.num_joints
    for tick in range(3):
        state = RobotState(tick=tick, time=0.02 * tick, q=desc.nominal_q.copy(), dq=np.zeros(n), tau_est=np.zeros(n),
                           imu_quat=np.array([1.0, 0.0, 0.0, 0.0]), gyro_in_body=np.zeros(3),
                           accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.full(4, 40.0))
        out = ctrl.act(state, VelocityCommand(vx=0.3))
        for name in ("q", "dq", "kp", "kd", "tau"):
            _finite(f"act().{name}", getattr(out, name))


# ------------------------------------------------------------------------------------------------ the calls --

def _cli(argv: list[str], out: Path | None, rows: int | None, *, full: bool) -> None:
    """Run ``wbc`` in this process; raise the `WbcError`-equivalent `_CleanExit`, or check what it wrote."""
    cli = importlib.import_module("wbc.cli.main")

    err = io.StringIO()
    saved = {}
    if not full:
        for module, name in STUBBED:
            mod = importlib.import_module(module)
            saved[module, name] = getattr(mod, name)
            setattr(mod, name, _stub)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                rc = cli.main(argv)
            except SystemExit as exc:  # argparse: a usage error exits 2 after its message
                rc = exc.code if isinstance(exc.code, int) else 2
    finally:
        for (module, name), value in saved.items():
            setattr(importlib.import_module(module), name, value)
    text = err.getvalue()
    if rc == 2:
        raise _CleanExit(text)
    if rc not in (0, 1):
        raise Implausible(f"exit status {rc}")
    if out is not None and full:
        check_results(out, rows)
        if rc == 1 and _all_failed(out):
            raise _ControllerFailed()


def _all_failed(out: Path) -> bool:
    """Every stored trial is a controller error: the run refused the controller trial by trial, and said so."""
    with (out / "trials.csv").open(encoding="utf-8", newline="") as f:
        return all(r.get("outcome") == "controller_error" for r in csv.DictReader(f))


class _ControllerFailed(Exception):
    """``wbc run`` exited 1: the controller failed every trial (it cannot act), reported as a controller error."""


class _Stub:
    """Stands for an executor (its ``run``) or a function that would play trials."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        raise _ReachedWork()


_stub = _Stub


class _CleanExit(Exception):
    """``wbc`` exited with status 2; its stderr."""


def _scenario(path: str, *, full: bool) -> None:
    """Load a scenario, draw its trials and build each one's ground."""
    from wbc.scenario.scenario import load_scenario
    from wbc.scenario.terrain import fractal_heights

    scenario = load_scenario(path)
    for trial in scenario.trials(None, (0, 1), 2):
        if not (math.isfinite(trial.duration_s) and trial.duration_s > 0):
            raise Implausible(f"trial duration {trial.duration_s}")
        if trial.terrain.kind == "fractal":
            _finite("terrain heights", fractal_heights(trial.terrain, trial.terrain_seed))


def _controller(name: str, io_file: str | None) -> object:
    from wbc.control.registry import get_controller

    return get_controller(name, io=io_file or None)


def execute(case: Case, d: Path, *, full: bool) -> Verdict:
    """Run `case` (its files already in `d`) and judge it; see the module docstring."""
    from wbc.errors import WbcError

    args = [a.replace("{d}", str(d)) for a in case.args]
    try:
        try:
            _dispatch(case, args, d, full=full)
        except _CleanExit as exc:
            lines = [ln for ln in str(exc).splitlines() if ln.strip()]
            if "Traceback" in str(exc):
                return Verdict("crash", _last(str(exc)))
            error = [ln for ln in lines if "error:" in ln]
            if not error:
                return Verdict("crash", f"exit 2 without an error line: {_cut(str(exc))}")
            message = str(exc)[str(exc).find(error[0]):]
            if len(message) > MAX_MESSAGE:
                return Verdict("crash", f"error message of {len(message)} characters: {_cut(message)}")
            return Verdict("clean", _cut(error[0]))
        except WbcError as exc:
            if len(str(exc)) > MAX_MESSAGE:
                return Verdict("crash", f"error message of {len(str(exc))} characters: {_cut(str(exc))}")
            return Verdict("clean", _cut(f"{type(exc).__name__}: {exc}"))
        except _ControllerFailed:
            return Verdict("valid", "every trial a controller error, exit 1")
        except _ReachedWork:
            if case.must_reject:
                return Verdict("silent", "accepted and started to play: " + case.name)
            return Verdict("valid", "reached the trials")
        except Implausible as exc:
            return Verdict("silent", str(exc))
        except (_Timeout, KeyboardInterrupt):
            return Verdict("hang", "time limit")
        except MemoryError:
            return Verdict("crash", "MemoryError (past the memory cap)")
        except RecursionError:
            return Verdict("crash", "RecursionError")
        except Exception as exc:  # anything but a WbcError is a bug: the user would see a traceback
            return Verdict("crash", _cut(f"{type(exc).__name__}: {exc} [{_where(exc)}]"))
    except _Timeout:
        return Verdict("hang", "time limit")
    if case.must_reject:
        return Verdict("silent", "accepted: " + case.name)
    return Verdict("valid")


def _dispatch(case: Case, args: list[str], d: Path, *, full: bool) -> None:
    call = case.call
    if call == "cli":
        _cli(args, d / case.out if case.out else None, case.rows, full=full)
    elif call == "scenario":
        _scenario(args[0], full=full)
    elif call == "scenario_run":
        if full:
            _cli(["run", "stand", "--scenario", args[0], "--trials", "1", "--workers", "1", "--out", f"{d}/out",
                  "--quiet"], d / "out", case.rows, full=True)
        else:
            _scenario(args[0], full=False)
    elif call == "plugin_config":
        from wbc.control.plugin import read_controller_config

        data = read_controller_config(args[0])
        if not isinstance(data, dict):
            raise Implausible(f"configuration table of type {type(data).__name__}")
    elif call in ("policy", "onnx"):
        spec = _controller(f"policy:{args[0]}" if call == "policy" else f"onnx:{args[0]}",
                           args[1] if call == "onnx" else None)
        _exercise(spec)
    elif call == "controller_run":
        # a trial of the controller on the tiny scenario: in full it is played; in process the command runs up to
        # the trials (the controller resolved, a plug-in built once), and a rate that never acts must be refused
        name, tiny, io_file = args
        _write_tiny(tiny)
        argv = ["run", name, "--scenario", tiny, "--trials", "1", "--workers", "1", "--out", f"{d}/out", "--quiet",
                *(["--io", io_file] if io_file else [])]
        if str(d) not in sys.path:  # a plug-in module is written beside the case
            sys.path.insert(0, str(d))
        try:
            _cli(argv, d / "out", 1, full=full)
        finally:
            sys.path.remove(str(d))
    elif call == "results":
        out, tiny = Path(args[0]), args[1]
        if full:
            _cli(["run", "stand", "--scenario", tiny, "--trials", "2", "--workers", "1", "--resume", "--out", str(out),
                  "--quiet"], out, 2, full=True)
        else:
            _resume(out)
    elif call == "episode":
        if full:
            _cli(["view", "--episode", args[0], "--trial", "0", "--record", f"{d}/v.html"], None, None, full=True)
        else:
            _episode(args[0])
    else:
        raise ValueError(f"unknown call {call!r}")


def _write_tiny(path: str) -> None:
    p = Path(path)
    if not p.exists():
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(TINY_SCENARIO)


def _resume(out: Path) -> None:
    """Reopen a results directory as ``--resume`` does (its identity, its store), and check the records it keeps."""
    from wbc.arena.identity import RunIdentity
    from wbc.arena.results import ResultsStore

    identity = RunIdentity.load(out / "run.json")
    store = ResultsStore(out, identity, resume=True)
    store.close()
    if len(store.records) > 2:
        raise Implausible(f"{len(store.records)} records kept from a 2-trial run")
    check_results(out, None)


def _episode(results: str) -> None:
    """Load a stored episode as ``wbc view --episode`` does and check every frame it would draw."""
    import numpy as np

    from wbc.viz.replay import load_stored_episode

    stored = load_stored_episode(results, 0)
    last = -math.inf
    count = 0
    for frame in stored.frames():
        count += 1
        if not math.isfinite(frame.t) or frame.t < last:
            raise Implausible(f"frame time {frame.t} after {last}")
        last = frame.t
        _finite("frame qpos", frame.qpos)
        norm = float(np.linalg.norm(frame.qpos[3:7]))
        if not 0.5 < norm < 1.5:
            raise Implausible(f"base quaternion of norm {norm}")
        if count > 1_000_000:
            raise Implausible("more than a million frames")
    if count == 0:
        raise Implausible("no frames")


def _cut(text: str, n: int = 200) -> str:
    text = " ".join(text.split())
    return text if len(text) <= n else text[: n - 3] + "..."


def _last(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return _cut(lines[-1] if lines else text)


def _where(exc: BaseException) -> str:
    frames = traceback.extract_tb(exc.__traceback__)
    inside = [f for f in frames if "/wbc/" in f.filename] or frames
    f = inside[-1] if inside else None
    return f"{Path(f.filename).name}:{f.lineno}" if f else "?"


# ----------------------------------------------------------------------------------------------- the limits --

@contextlib.contextmanager
def limits(seconds: float, extra_mb: int):
    """Raise `_Timeout` after `seconds` and cap this process's address space at its size now plus `extra_mb`.

    For the in-process suite: a loader that reads ``/dev/zero`` or inflates a bomb fails with `MemoryError` instead of
    taking the machine, and one that loops is stopped.
    """
    def alarm(signum: int, frame: object) -> None:
        raise _Timeout()

    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    size = _vm_size()
    cap = size + extra_mb * (1 << 20) if size else resource.RLIM_INFINITY
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _vm_size() -> int:
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


# ------------------------------------------------------------------------------------------------ the child --

def main(argv: list[str] | None = None) -> int:
    """``python -m fuzz.execute CASE.pkl DIR --memory-mb M``: run one case in full under an address-space cap.

    Prints one line ``FUZZ-VERDICT {"kind": ..., "detail": ...}``; the campaign kills it at its time limit.
    """
    p = argparse.ArgumentParser()
    p.add_argument("case")
    p.add_argument("dir")
    p.add_argument("--memory-mb", type=int, default=4096)
    args = p.parse_args(argv)
    cap = args.memory_mb * (1 << 20)
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    with open(args.case, "rb") as f:
        case = pickle.load(f)
    d = Path(args.dir)
    os.chdir(d)
    verdict = execute(case, d, full=True)
    print("FUZZ-VERDICT " + json.dumps({"kind": verdict.kind, "detail": verdict.detail}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
