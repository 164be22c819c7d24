"""Executors: where trials run. A local process pool (default) or a Ray cluster; the results are identical.

On Ray, each worker first checks that it runs the driver's wbc, packages and controller files
(`wbc.arena.worker_check`): a node that does not would give other results.

Both take `TrialTask`s and yield each finished trial's record as soon as it is done, in completion order; the caller
stores it at once. Both read the tasks lazily, a bounded number ahead of the finished ones, so that a caller feeding
a generator can stop handing out tasks during the run (a settled sequential test, a controller stopped for its
errors). A controller's failure in a trial comes back as that trial's record (`wbc.arena.sim_trial.run_trial`), not
as an exception that would end the run.

Every trial is fully determined by its `Trial` and its controller's resolved `ControllerSpec`, so neither the worker
nor the order changes a result. A task carries the spec, not the name: the parent resolves each
name once (reading a ``policy:PATH`` file there), and the spec pickles to spawned processes and Ray workers.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import dataclasses
import hashlib
import itertools
import math
import multiprocessing
import multiprocessing.connection
import multiprocessing.process
import os
import signal
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from wbc.arena.episode import Episode, EpisodeBuffer
from wbc.arena.runner import TickObserver, forget_played, played_s
from wbc.arena.sim_trial import run_trial, simulated_robot
from wbc.arena.trial_record import TrialRecord
from wbc.arena.worker_check import Expectation, check_worker, expectation, without_colour
from wbc.control.spec import ControllerSpec
from wbc.errors import ClusterError, ConfigError
from wbc.hardware.interpreter import child_process_env
from wbc.optional import require
from wbc.scenario.trial import Trial

__all__ = ["EXECUTORS", "VIEWED_TIME_LIMIT", "LocalExecutor", "RayExecutor", "TrialTask", "run_task",
           "shut_down_pool", "spawn_pool", "worker_environment"]


@dataclass(frozen=True, kw_only=True)
class TrialTask:
    """One trial for one controller, as sent to a worker.

    Attributes:
        trial: the trial to play.
        controller: the controller, resolved (`wbc.control.registry.get_controller`) once by the parent.
        debug_truth: throw the controller's ground-truth debug switch.
        episode_path: where to save the episode log as ``.npz`` (None: not saved).
        time_limit_s: the wall time the trial may take in its worker, from the controller's construction to its
            record [s]; past it the worker process is ended and the trial recorded as its controller's error (None:
            no limit). Played in a worker process only (`LocalExecutor` uses its pool whenever a task has a limit).
    """

    trial: Trial
    controller: ControllerSpec
    debug_truth: bool = False
    episode_path: str | None = None
    time_limit_s: float | None = None


@contextmanager
def worker_environment() -> Iterator[None]:
    """Processes spawned inside this context start in a worker's environment; this process's is restored after.

    That is `wbc.hardware.interpreter.child_process_env`: the BLAS single-threaded, since workers run one trial each
    on one core and a multi-threaded BLAS in every worker oversubscribes the cores (two MPC workers on two cores ran
    2.5x slower than one); and MuJoCo's rendering off unless ``MUJOCO_GL`` is set. Only processes started inside it
    are affected: a library already loaded keeps its settings.
    """
    env = child_process_env()
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def run_task(task: TrialTask, observer: TickObserver | None = None) -> TrialRecord:
    """Play one task in this process and return its record.

    The episode is saved (when the task names a path) before the record is returned, so a stored record always has its
    episode. `observer` watches every tick (a live viewer; see `wbc.arena.runner.run_episode`).

    Raises:
        OSError: the episode could not be saved (a full disk, no permission), with its path as the filename.
    """
    record, episode = run_trial(task.trial, task.controller, debug_truth=task.debug_truth, observer=observer)
    if task.episode_path is not None:
        _save_episode(episode, task.episode_path)
    return record


def _save_episode(episode: Episode, path: str) -> None:
    """Save `episode` to `path`.

    Raises:
        OSError: it could not be saved, with `path` as the filename (for the run's message: a full disk,
            `wbc.arena.results.unwritable`).
    """
    try:
        episode.save(path)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror or str(exc), path) from exc


VIEWED_TIME_LIMIT = ("--trial-time-limit ends the worker process of a trial that overruns, and a viewed run (--view) "
                     "plays its trials in this process: leave one of them out")
"""Why a time limit and a live view are refused together."""

OVERRUN_EXIT = 86
"""The exit status of a worker ended because its trial ran past its time limit."""


class _Watchdog:
    """In a worker process: ends the process if the trial is still playing `limit_s` after it started.

    A trial whose controller hangs (a sleep, a deadlock, a loop that never returns) cannot be interrupted from inside
    its own process reliably (a loop in compiled code ignores signals), so the process is ended (``os._exit``), after
    writing `flag`: the parent reads it to record the trial as overrun instead of playing it again. `wait` is
    `threading.Event.wait`'s signature (tests pass their own clock).
    """

    def __init__(self, limit_s: float, flag: str, *, wait: Callable[[threading.Event, float], bool] | None = None,
                 exit_: Callable[[int], object] = os._exit) -> None:
        self._done = threading.Event()
        self._lock = threading.Lock()  # the trial's end and the watchdog's exit exclude each other
        self._limit_s, self._flag, self._exit = limit_s, flag, exit_
        self._wait = wait or (lambda event, timeout: event.wait(timeout))
        self._thread = threading.Thread(target=self._watch, name="wbc-trial-time-limit", daemon=True)

    def __enter__(self) -> _Watchdog:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        with self._lock:  # once past this, the watchdog can no longer end the process
            self._done.set()

    def _watch(self) -> None:
        if self._wait(self._done, self._limit_s):
            return
        with self._lock:
            if self._done.is_set():  # the trial ended as the clock ran out: its record stands
                return
            try:
                with open(self._flag, "w", encoding="utf-8") as f:
                    # the limit, then how far the trial got: its record's time to fall, as a controller that raises
                    # gets the time it raised at
                    f.write(f"{self._limit_s!r}\n{played_s()!r}\n")
            except OSError:
                pass  # ended all the same (the parent then sees a worker that died): a hung trial must not hold it
            self._exit(OVERRUN_EXIT)


def _run_limited(task: TrialTask, flag: str) -> TrialRecord:
    """`run_task` in a worker, under `task`'s time limit (`_Watchdog`); `flag` is the file an overrun leaves."""
    if task.time_limit_s is None:
        return run_task(task)
    forget_played()  # a worker plays trial after trial: until this one's episode begins, it has played nothing
    with _Watchdog(task.time_limit_s, flag):
        return run_task(task)


def _flag_name(task: TrialTask) -> str:
    """The name of the file `task`'s worker leaves if its trial overruns: one per (controller, band, seed, trial)."""
    trial = task.trial
    return hashlib.sha256(f"{trial.band}-s{trial.seed}-t{trial.index}-{task.controller.name}".encode()).hexdigest()[:32]


def overran(task: TrialTask, flag: str | None = None) -> TrialRecord:
    """The record of `task`, whose worker was ended when the trial ran past its time limit: a controller error.

    Its time to fall is the share of the episode played before the worker was ended, as `flag` (the file the worker's
    watchdog left) says, as a controller that raises is judged on what it played before it raised; 0 when the flag
    does not say (the trial had not begun its episode). Its other metrics are NaN: the episode went with the worker.
    """
    record = _no_tick_record(task, f"ran past the trial time limit of {task.time_limit_s:g} s (--trial-time-limit), "
                                   "and its worker process was ended")
    played = _played_in(flag) if flag is not None else None
    if played is None:
        return record
    return dataclasses.replace(record, ttf=min(1.0, played / task.trial.duration_s))


def _played_in(flag: str) -> float | None:
    """The simulated seconds an overrun trial played, from its flag (`_Watchdog`); None when it does not say."""
    try:
        with open(flag, encoding="utf-8") as f:
            lines = f.read().splitlines()
        played = float(lines[1])
    except (OSError, IndexError, ValueError):
        return None  # a flag of the limit alone, or none readable: how far it got is not known
    return played if math.isfinite(played) and played >= 0.0 else None


_PR_SET_PDEATHSIG = 1
"""``prctl``'s option that has the kernel signal a process when its parent ends (Linux)."""

_PARENT_POLL_S = 0.5
"""How often a worker without ``PR_SET_PDEATHSIG`` checks that its parent is still there [s]."""


def spawn_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of `workers` spawned processes, each ended when this process ends, none writing to standard output."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_start_worker, initargs=(os.getpid(),))


def _start_worker(parent: int) -> None:
    """A pool's worker, as it starts: its standard output to standard error; ended when `parent` ends."""
    _stdout_to_stderr()
    _die_with_parent(parent)


def _stdout_to_stderr() -> None:
    """Send this process's standard output to its standard error, at the file descriptor: C-level writes too.

    A worker inherits the command's standard output, and what a controller prints there (in its factory, ``reset``,
    ``act``, or a C extension's ``printf``) landed in the middle of the command's output, in the JSON of ``--json``.
    Nothing a worker does is meant for standard output: its records go back to the command through the pool.
    """
    try:
        sys.stdout.flush()
    except (OSError, ValueError, AttributeError):  # closed, or none
        pass
    try:
        os.dup2(sys.stderr.fileno(), 1)
    except (OSError, ValueError, AttributeError):  # no standard error to send it to: it stays as it was
        pass


def _die_with_parent(parent: int) -> None:
    """In a pool's worker, as it starts: end it when `parent`, the process that started it, ends, however it ends.

    A parent killed (SIGKILL, the out-of-memory killer) or ended by a signal it does not handle never shuts its pool
    down, and an idle worker waits for work forever (reparented to init, a few hundred MB each). On Linux the kernel
    kills the worker (``PR_SET_PDEATHSIG``; it fires when the parent's thread that spawned the worker ends, and the
    pool spawns its workers from the thread that submits to it, the run's own); elsewhere a daemon thread checks the
    parent every `_PARENT_POLL_S`. A parent that died before the request was made is caught by the check after it.
    """
    if not _killed_with_parent():
        threading.Thread(target=_watch_parent, args=(parent,), name="wbc-parent-watch", daemon=True).start()
    if os.getppid() != parent:  # ended before the kernel was asked: it will not signal for it
        os._exit(1)


def _killed_with_parent() -> bool:
    """Ask the kernel to SIGKILL this process when its parent ends (``prctl``); False where it cannot be asked."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        return libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent: int, *, period_s: float = _PARENT_POLL_S, getppid: Callable[[], int] = os.getppid,
                  sleep: Callable[[float], object] = time.sleep, exit_: Callable[[int], object] = os._exit) -> None:
    """End this process (``os._exit(1)``) once its parent is no longer `parent`; tests pass their own functions."""
    while getppid() == parent:
        sleep(period_s)
    exit_(1)


class LocalExecutor:
    """Runs tasks in a pool of local processes (``workers`` <= 1: in this process, unless `isolated`).

    Args:
        workers: number of processes (default: all cores).
        observer: watches every tick of every trial (a live viewer); trials then run one by one in this process.
        isolated: with one worker, play in a worker process all the same (without an observer): a controller that
            ends its process (``os._exit``, a crash in native code) then costs only its own trial, as with a pool.
    """

    name = "local"

    def __init__(self, workers: int | None = None, observer: TickObserver | None = None, *,
                 isolated: bool = False) -> None:
        self.workers = 1 if observer is not None else (workers or os.cpu_count() or 1)
        self.observer = observer
        self.isolated = isolated and observer is None
        self._flags: str | None = None  # the directory of the overrun flags, while a pool runs

    def describe(self, time_limit: bool = False) -> str:
        """Where the trials play, for a run's report and ``run.json``.

        ``local, in this process`` (one worker, not isolated), ``local, 1 worker process`` (isolated, or with a trial
        time limit: `time_limit`), ``local pool of N worker processes``.
        """
        if self.workers <= 1 and not self.isolated and not time_limit:
            return "local, in this process" + (" (live view)" if self.observer is not None else "")
        if self.workers <= 1:
            return "local, 1 worker process"
        return f"local pool of {self.workers} worker processes"

    def run(self, tasks: Iterable[TrialTask]) -> Iterator[TrialRecord]:
        """Yield each task's record as it finishes.

        `tasks` is read lazily, a task when a worker is free (a few ahead with a pool), so a caller that feeds a
        generator can stop handing out tasks in the middle of a run (``--until-significant``).
        """
        queue = iter(tasks)
        first = next(queue, None)
        if first is None:
            return
        queue = itertools.chain((first,), queue)
        if first.time_limit_s is not None and self.observer is not None:
            raise ConfigError(VIEWED_TIME_LIMIT)
        if self.workers <= 1 and first.time_limit_s is None and not self.isolated:
            for task in queue:
                yield run_task(task, self.observer)
            return
        # Spawned (not forked) workers, so each starts its BLAS single-threaded from the environment; the pool starts
        # its processes on demand, so the environment stays set until the pool is done. A time limit needs a worker
        # process to end (one, with --workers 1), and so does isolation.
        with worker_environment(), tempfile.TemporaryDirectory(prefix="wbc-overrun-") as flags:
            self._flags = flags
            try:
                yield from self._run_pool(queue)
            finally:
                self._flags = None

    def _flag(self, task: TrialTask) -> str:
        """The file `task`'s worker leaves if the trial overruns its time limit (only while a pool runs)."""
        if self._flags is None:
            raise RuntimeError("LocalExecutor._flag is asked outside a pool's run")
        return os.path.join(self._flags, _flag_name(task))

    def _run_pool(self, tasks: Iterable[TrialTask]) -> Iterator[TrialRecord]:
        """The pool's records; a worker that dies costs only the trial it was playing.

        A process that exits in a trial (a controller calling ``os._exit``, one killed by a signal or for its
        memory) breaks the whole pool: every task then in flight fails with it. Each of those is played again alone,
        in a pool of its own: the one whose worker dies again is recorded as that controller's error, the others
        give their records (a trial's result does not depend on the process that plays it), and a fresh pool takes
        the rest of the queue.
        """
        queue: Iterator[TrialTask] = iter(tasks)
        while True:
            suspects = yield from self._pool_pass(queue)
            if suspects is None:
                return
            late = [task for task in suspects if os.path.exists(self._flag(task))]
            for task in late:
                yield overran(task, self._flag(task))
            others = [task for task in suspects if task not in late]
            if late:
                # an overrun explains the break: the trials beside it are innocent, and go back to the fresh pool
                # (each pass that breaks this way records at least one trial, so this ends)
                queue = itertools.chain(others, queue)
                continue
            for task in others:
                yield _alone(task, self._flag(task))

    def _pool_pass(self, queue: Iterator[TrialTask]) -> Generator[TrialRecord, None, list[TrialTask] | None]:
        """Play `queue` in one pool until it is empty (None) or the pool breaks (the tasks it broke with)."""
        pool = spawn_pool(self.workers)
        broke = ended = False  # ended: every task played (else stopped early: an interrupt, a caller gone)
        try:
            pending: dict[Future, TrialTask] = {}
            unsent: list[TrialTask] = []  # taken from the queue after the pool broke

            def send(task: TrialTask) -> bool:
                try:
                    pending[pool.submit(_run_limited, task, self._flag(task))] = task
                    return True
                except BrokenProcessPool:
                    unsent.append(task)
                    return False

            for task in queue:  # keep a bounded number in flight so a kill loses little
                if not send(task) or len(pending) >= 2 * self.workers:
                    break
            while pending and not unsent:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                if any(isinstance(fut.exception(), BrokenProcessPool) for fut in done):
                    break
                for fut in done:
                    pending.pop(fut)
                    yield fut.result()
                    nxt = next(queue, None)
                    if nxt is not None and not send(nxt):
                        break
            if not pending and not unsent:
                ended = True
                return None
            broke = True
            # a broken pool fails every task in flight at once; those that finished before it keep their records
            wait(pending, timeout=_LINGER_S)
            finished = [fut for fut in pending if fut.done() and fut.exception() is None]
            for fut in finished:
                yield fut.result()
            return [task for fut, task in pending.items() if fut not in finished] + unsent
        finally:
            # a pool stopped early or broken has nothing worth waiting for: its workers are stopped at once
            _shut_down(pool, broken=broke or not ended)


def _alone(task: TrialTask, flag: str) -> TrialRecord:
    """Play `task` in a pool of its own: its record, or, if its worker dies, the record of that controller error."""
    pool = spawn_pool(1)
    try:
        return pool.submit(_run_limited, task, flag).result()
    except BrokenProcessPool:
        if os.path.exists(flag):
            return overran(task, flag)
        return worker_died(task, "died again when the trial was played alone; the trials beside it were played again")
    finally:
        _shut_down(pool, broken=True)  # its one task is done, or its worker dead: nothing left to wait for


def worker_died(task: TrialTask, again: str) -> TrialRecord:
    """The record of `task` whose worker process died playing it: a controller error, with no tick played.

    `again` ends the message: how the trial was played once more, and died again.
    """
    return _no_tick_record(task, f"the worker process playing it died (it exited, or was killed by a signal or for "
                                 f"its memory) and {again}")


def _trial_name(task: TrialTask) -> str:
    """``controller X, band B, seed S, trial I``: a task as messages name it."""
    trial = task.trial
    return f"controller {task.controller.name}, band {trial.band}, seed {trial.seed}, trial {trial.index}"


def _no_tick_record(task: TrialTask, what: str) -> TrialRecord:
    """A controller-error record of `task` with an empty episode: its worker ended before the trial gave a record."""
    trial, spec = task.trial, task.controller
    robot = simulated_robot(trial, spec.arm_mode)  # its joints and time step, for the empty episode
    empty = EpisodeBuffer(nq=7 + robot.num_joints).finish(duration_s=trial.duration_s,
                                                           control_dt=robot.config.timestep, fell=False,
                                                           fall_time_s=math.nan)
    error = f"controller {spec.name}, band {trial.band}, seed {trial.seed}, trial {trial.index}: {what}"
    return TrialRecord.of_trial(trial, controller=spec.name, episode=empty, counters={}, wall_s=0.0,
                                debug_truth=task.debug_truth, error=error)


_RAY_RETRIES = 1
"""How many times Ray plays again a task whose worker died, before the trial is recorded as its controller's error."""

_RAY_CLUSTER_RETRIES = 2
"""How many times a task that Ray's cluster failed (`_CLUSTER_ERRORS`) is handed to it again before the run stops."""

_CLUSTER_ERRORS = ("NodeDiedError", "ObjectLostError", "RaySystemError", "RuntimeEnvSetupError",
                   "LocalRayletDiedError")
"""Ray's errors (``ray.exceptions``) that are its cluster's, not a controller's: a node lost, an object lost (its
subclasses too: an owner died, a fetch timed out), Ray's own failure, a worker environment that could not be set up,
the local raylet dead. A worker that crashes (``WorkerCrashedError``, ``OutOfMemoryError``) is the controller's."""

_LINGER_S = 5.0
"""How long a worker may take to exit once its pool is shut down [s]: one that a controller's thread keeps alive is
stopped after this."""


def shut_down_pool(pool: ProcessPoolExecutor, *, broken: bool = False) -> None:
    """Shut down a pool from `spawn_pool` (`_shut_down`).

    A worker that a controller's thread keeps alive is stopped; a `broken` pool's workers (or a hung one's) at once.
    """
    _shut_down(pool, broken=broken)


def _shut_down(pool: ProcessPoolExecutor, *, broken: bool = False) -> None:
    """Shut `pool` down; a worker still alive after `_LINGER_S` (a controller's thread keeps it) is terminated.

    A `broken` pool's workers are terminated at once: what they were playing is played again elsewhere.

    The pool's own thread reaps its workers (it joins each of them): this waits for that thread, and reads whether a
    worker has ended from its sentinel (`_running`), which reaps nothing. Joining the workers here as well raced that
    thread: the join that lost the reap read a worker that had ended as still alive, and was sent a signal to a process
    id that was no longer its own, with a warning that blamed a controller's thread.
    """
    processes = list((getattr(pool, "_processes", None) or {}).values())  # the pool's own worker processes
    reaper = getattr(pool, "_executor_manager_thread", None)  # None once shut down: taken before
    pool.shutdown(wait=False, cancel_futures=True)
    if broken:
        for process in _running(processes):
            process.terminate()
    if reaper is None:  # no task was ever submitted: no worker was started
        return
    reaper.join(timeout=_LINGER_S)
    if not reaper.is_alive():
        return
    lingering = _running(processes)
    for process in lingering:
        process.terminate()
    reaper.join(timeout=_LINGER_S)
    if lingering and not broken:
        print(f"wbc: warning: {len(lingering)} worker process(es) still ran {_LINGER_S:g} s after their trials "
              "ended and were stopped; every trial's record is kept. A thread a controller started and left running "
              "keeps its worker alive; so can a machine too busy for the worker to exit in time", file=sys.stderr)


def _running(processes: Iterable[multiprocessing.process.BaseProcess]) -> list[multiprocessing.process.BaseProcess]:
    """The `processes` that have not ended, read from their sentinels (a process's end closes it): nothing is reaped."""
    def ended(process: multiprocessing.process.BaseProcess) -> bool:
        try:
            return bool(multiprocessing.connection.wait([process.sentinel], timeout=0))
        except ValueError:  # the process object was closed: its process ended and was reaped
            return True

    return [process for process in processes if not ended(process)]


def _run_checked(task: TrialTask, expected: Expectation) -> tuple[TrialRecord, Episode | None]:
    """A task on a Ray worker, once the worker is checked to run what the driver recorded (`check_worker`).

    Returns the record, and the episode when the task saves one: the driver saves it (`RayExecutor.run`), where the
    task's path means what it meant when the driver made it (a relative ``--out``, a disk of its own).
    """
    check_worker(expected)
    record, episode = run_trial(task.trial, task.controller, debug_truth=task.debug_truth)
    return record, (episode if task.episode_path is not None else None)


class RayExecutor:
    """Runs tasks on a Ray cluster (or a local Ray started on demand).

    Args:
        address: cluster address (``auto``, ``ray://host:10001`` ...); None: the one ``RAY_ADDRESS`` names (as
            ``ray job submit`` sets it), else a local Ray started on this machine.
        num_cpus: CPUs for a local Ray (default: all cores).
        environ: the environment ``RAY_ADDRESS`` is read from (default: this process's).

    Raises:
        ConfigError: `num_cpus` with ``RAY_ADDRESS`` set: a cluster's CPUs are its own.
    """

    name = "ray"

    def __init__(self, address: str | None = None, num_cpus: int | None = None, *,
                 environ: Mapping[str, str] | None = None) -> None:
        from_env = (os.environ if environ is None else environ).get("RAY_ADDRESS") or None
        self.address = address or from_env
        self.from_env = address is None and from_env is not None  # the address is RAY_ADDRESS's
        if self.from_env and num_cpus is not None:
            raise ConfigError(f"--workers {num_cpus} with RAY_ADDRESS={from_env} set: a Ray cluster's CPUs are its "
                              "own; leave --workers out, or unset RAY_ADDRESS to start a Ray on this machine")
        self.num_cpus = num_cpus
        self._ray: Any = None  # the ray module, once connected
        self._started = False  # this executor started (or connected) Ray, and shuts it down
        self._handlers: dict[int, Any] = {}  # this process's signal handlers before Ray's start

    def describe(self) -> str:
        """Where the trials play, for a run's report: ``ray (cluster at ADDRESS, from RAY_ADDRESS)`` ..."""
        if self.address is None:
            return "ray (a Ray started on this machine)"
        return f"ray (cluster at {self.address}, from {'RAY_ADDRESS' if self.from_env else '--address'})"

    def _named(self) -> str:
        return f"{self.address} ({'RAY_ADDRESS' if self.from_env else '--address'})"

    def connect(self) -> None:
        """Start Ray, or connect to the cluster, unless this process already has; this process's handlers kept.

        A cluster's address is first reached over TCP within `_CONNECT_TIMEOUT_S` (Ray itself retries an address that
        does not answer for minutes, with no word but its own log lines).

        ``ray.init`` installs its own SIGTERM handler (and SIGINT's), which ended the command with a native dump and
        no word of what was stored: the handlers this process had are put back as soon as it returns, and again when
        `close` shuts Ray down.

        Raises:
            ClusterError: the address cannot be reached, or Ray refuses to connect (an authentication token that
                differs, another Ray version) or to start; the message names the address.
        """
        if self._ray is not None:
            return
        ray = require("ray", "cluster")
        if not ray.is_initialized():
            # without an address, a new Ray on this machine ("local"): Ray would otherwise join a cluster that
            # `ray start` left here (its /tmp/ray/ray_current_cluster), and then refuse the CPU count
            kwargs: dict[str, Any] = {"address": self.address} if self.address else {
                "address": "local", "num_cpus": self.num_cpus or os.cpu_count(), "include_dashboard": False}
            if self.from_env:
                print(f"wbc: note: --executor ray without --address plays on the Ray cluster at {self.address} that "
                      "RAY_ADDRESS names", file=sys.stderr)
            if self.address:
                _reach(self.address, self._named())
            self._handlers = _signal_handlers()
            try:
                ray.init(log_to_driver=False, configure_logging=False,
                         runtime_env={"env_vars": child_process_env()}, **kwargs)
            except Exception as exc:  # noqa: BLE001 - whatever Ray raises (a token refused, a version) is said plainly
                with contextlib.suppress(Exception):
                    ray.shutdown()
                where = f"connect to the Ray cluster at {self._named()}" if self.address else "start Ray here"
                raise ClusterError(f"cannot {where}: {type(exc).__name__}: {without_colour(str(exc)).strip()}; "
                                   "nothing was played") from None
            finally:
                _restore_signal_handlers(self._handlers)
            self._started = True
        self._ray = ray

    def close(self) -> None:
        """Shut down the Ray this executor started (a cluster: disconnect), and put this process's handlers back."""
        ray, self._ray = self._ray, None
        if ray is None or not self._started:
            return
        self._started = False
        try:
            ray.shutdown()
        finally:
            _restore_signal_handlers(self._handlers)

    def run(self, tasks: Iterable[TrialTask]) -> Iterator[TrialRecord]:
        """Yield each task's record as it finishes.

        `tasks` is read lazily: twice as many in flight as the cluster has CPUs, a new one when one finishes. A
        task whose worker process dies (a controller that exits it, a kill, Ray's memory monitor) is played once
        more; one that dies again is recorded as its controller's error, and the run goes on.

        Each worker checks, before it builds a controller, that it runs the driver's wbc and result-changing packages
        and the controller's files as recorded (`wbc.arena.worker_check`).

        A task the cluster fails (a node lost, an object lost, Ray's own error: `_CLUSTER_ERRORS`) is handed to it
        again, `_RAY_CLUSTER_RETRIES` times at most; it is no trial's result.

        Ray is started (`connect`) unless it was, and shut down (`close`) at the end.

        Raises:
            ClusterError: a worker runs another wbc or package version, or lacks a controller file or has another
                one, or the cluster failed a task more often than it is handed again; the run stops there (the
                records yielded before are the caller's to keep).
        """
        self.connect()
        ray = self._ray
        try:
            # a task whose worker dies is played once more (a trial on a lost node finishes elsewhere)
            remote = ray.remote(num_cpus=1, max_retries=_RAY_RETRIES)(_run_checked)
            expected: dict[str, Expectation] = {}

            def submit(task: TrialTask) -> object:
                if task.time_limit_s is not None:  # before it is sent (ArenaConfig refuses it before the run)
                    raise ConfigError("a trial time limit is enforced in the local pool's workers, not on Ray: "
                                      "leave --trial-time-limit out with --executor ray")
                name = task.controller.name
                if name not in expected:  # once per controller: its files are hashed once, in the driver
                    expected[name] = expectation(task.controller)
                return remote.remote(task, expected[name])

            died = (ray.exceptions.WorkerCrashedError, ray.exceptions.OutOfMemoryError)
            cluster = tuple(getattr(ray.exceptions, name) for name in _CLUSTER_ERRORS
                            if isinstance(getattr(ray.exceptions, name, None), type))
            # times the cluster failed a task, by the trial it plays (a task's id would be reused by a later task once
            # the first is freed, and the later one then given fewer tries)
            failed: dict[tuple[str, str, int, int], int] = {}
            ahead = 2 * max(1, int(ray.cluster_resources().get("CPU", 1)))
            queue = iter(tasks)
            refs = {submit(task): task for task in itertools.islice(queue, ahead)}
            while refs:
                (done,), _ = ray.wait(list(refs), num_returns=1)
                task = refs.pop(done)
                try:
                    record, episode = ray.get(done)
                    if episode is not None and task.episode_path is not None:
                        _save_episode(episode, task.episode_path)  # here, before its record is handed on
                except died:
                    record = worker_died(task, "died again when Ray played it once more")
                except cluster as exc:
                    key = (task.controller.name, task.trial.band, task.trial.seed, task.trial.index)
                    tries = failed[key] = failed.get(key, 0) + 1
                    if tries > _RAY_CLUSTER_RETRIES:
                        raise ClusterError(
                            f"the Ray cluster failed the task of {_trial_name(task)} {tries} times "
                            f"({type(exc).__name__}: {without_colour(str(exc)).strip()}); it is the cluster's "
                            "failure (a node or an object lost, Ray's own error), not the controller's: the run stops "
                            "here, no trial recorded for it: the trials stored are kept, and --resume finishes the "
                            "run once the cluster is fixed") from None
                    refs[submit(task)] = task  # the cluster's failure: the trial is played again
                    continue
                except ray.exceptions.RayTaskError as exc:
                    cause = exc.cause
                    if isinstance(cause, ClusterError):  # the worker's refusal: the run stops, said plainly
                        raise ClusterError(without_colour(str(cause.args[0]))) from None
                    if not isinstance(cause, BaseException):
                        raise
                    # a fault in wbc's own code on the worker: raised as itself, with the worker's traceback as
                    # a note, without the colour codes Ray writes into it for a terminal
                    cause.add_note(f"raised on a Ray worker:\n{without_colour(str(exc))}")
                    raise cause from None
                yield record
                nxt = next(queue, None)
                if nxt is not None:
                    refs[submit(nxt)] = nxt
        finally:
            self.close()


_CONNECT_TIMEOUT_S = 10.0
"""How long a Ray cluster's address may take to accept a TCP connection before the run is refused [s]."""


def _reach(address: str, named: str, *, timeout_s: float = _CONNECT_TIMEOUT_S) -> None:
    """Refuse a ``host:port`` (or ``ray://host:port``) that accepts no TCP connection within `timeout_s`.

    ``auto`` and other addresses without a port are left to Ray.

    Raises:
        ClusterError: the address cannot be reached; the message names it (`named`) and the error.
    """
    target = address.removeprefix("ray://").rstrip("/")
    host, _, port = target.rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as exc:
        raise ClusterError(f"cannot reach the Ray cluster at {named} within {timeout_s:g} s: "
                           f"{exc.strerror or exc}; check the head's address and port (`ray status` on the head) "
                           "and that this machine can reach it; nothing was played") from None


_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
"""The signals whose handlers ``ray.init`` replaces and `RayExecutor` puts back."""


def _signal_handlers() -> dict[int, Any]:
    """This process's handlers of `_SIGNALS` (none outside the main thread, where none can be set)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {signum: signal.getsignal(signum) for signum in _SIGNALS}


def _restore_signal_handlers(handlers: dict[int, Any]) -> None:
    """Put back `handlers` (`_signal_handlers`); one Python did not set (None) is left as it is."""
    if threading.current_thread() is not threading.main_thread():
        return
    for signum, handler in handlers.items():
        if handler is not None:
            signal.signal(signum, handler)


EXECUTORS = ("local", "ray")
