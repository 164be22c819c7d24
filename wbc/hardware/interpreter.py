"""How a process that talks to motors asks the Python interpreter to share itself among its threads.

A robot link (`wbc.hardware.unitree.UnitreeRobot`: 500 Hz), an arm bus (`wbc.hardware.dynamixel.DynamixelArm`:
200 Hz) and a controller share one interpreter lock. A thread that wants the lock while another computes waits for
the interpreter's switch interval, 5 ms by default: longer than the link's whole period. Measured over the wire
against the emulator (the MPC at 500 Hz on go1-arm, arm actuated, on a 2-core VM), the link thread overran its period
on 16 % of its sends and the arm bus failed 8 % of its reads with the default interval, 7.5 % and 4 % with this
module's. `realtime_switch_interval` shortens the interval, so that a link thread waits about that long at most for
its turn; the commands that talk to motors (`wbc hw run`, `wbc hw emulate`, `wbc hw check`, the hardware benches)
call it once at start, and a script of your own that drives a real robot should too. It costs the computing thread
some switching overhead and changes nothing else.

The other stall is the garbage collector's. A full (generation 2) collection traverses every container object alive,
holding the interpreter lock the whole time, and most of them were made at start-up: the imported modules, the
models, the controller. Measured on the 2-core VM, one full collection of a freshly started emulator (47 000 tracked
objects) took 35 ms; over the wire (learned controller, a1-wx200, arm actuated) the emulator's took up to 146 ms and
the host's up to 165 ms, stalls during which the arm's bus answered nothing and the host read nothing, so that its
retries and pings failed together and a no-answer fault latched. `freeze_heap`, called once everything is built and
before the loop starts, moves the objects alive then into the collector's permanent generation: later collections
traverse only what was made since (the same measurement: 0.003 ms). Garbage made later is still collected.

A third cost is memory. numpy's and scipy's BLAS each start a pool of worker threads, one per further CPU, with
buffers of their own; a process that locks its memory (`wbc.hardware.realtime`) locks those too. A process that
talks to motors does no parallel linear algebra: started with `SINGLE_THREAD_BLAS_ENV` in its environment, it has
no pool. Measured on the 2-core VM, the I/O process of `ProcessRobot` (legs only) ran 4 threads with 577 MB locked,
and 2 threads (its main thread and the link's) with 495 MB locked once started so; a pool's worker locks some 40 MB.

`child_process_env` gives what every process wbc starts itself takes in its environment (the arena's workers, the I/O
process, the benches' emulators): that, and MuJoCo's rendering off, since none of them renders.
"""

from __future__ import annotations

import contextlib
import gc
import os
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path

__all__ = ["REALTIME_SWITCH_INTERVAL_S", "SINGLE_THREAD_BLAS_ENV", "child_process_env", "freeze_heap", "frozen_heap",
           "realtime_switch_interval", "wbc_interpreter_env"]

REALTIME_SWITCH_INTERVAL_S = 0.0005  # [s] a quarter of the link's 2 ms period

SINGLE_THREAD_BLAS_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
"""The environment in which a process's BLAS (numpy's, scipy's) starts single-threaded: no pool of worker threads.
It acts when the library loads, so it is given to a process when it is started (`child_process_env`)."""


def child_process_env(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """The variables a process that wbc starts itself takes on top of `base` (default: this process's environment).

    `SINGLE_THREAD_BLAS_ENV`, and ``MUJOCO_GL=disable`` unless `base` sets ``MUJOCO_GL``: none of these processes
    renders, and importing MuJoCo otherwise loads GLFW, whose library check runs a Python subprocess in every process
    (~25 ms) and, when its parent is killed meanwhile (a run stopped as its workers start), prints that subprocess's
    broken-pipe traceback. A ``MUJOCO_GL`` set by the user is kept (a plug-in that renders in a worker).
    """
    base = os.environ if base is None else base
    env = dict(SINGLE_THREAD_BLAS_ENV)
    if "MUJOCO_GL" not in base:
        env["MUJOCO_GL"] = "disable"
    return env


def wbc_interpreter_env(overrides: Mapping[str, str] | None = None) -> dict[str, str]:
    """This process's environment for a fresh interpreter that runs this very wbc (``python -c``, ``python -m``).

    Its root comes first on ``PYTHONPATH``, so the child imports the package this process imported, wherever that
    is; `overrides` (such as `child_process_env`) are set on top.
    """
    root = str(Path(__file__).resolve().parents[2])
    path = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)
    return dict(os.environ, **(overrides or {}), PYTHONPATH=path)


def realtime_switch_interval(interval_s: float = REALTIME_SWITCH_INTERVAL_S) -> float:
    """Set the interpreter's thread switch interval to at most `interval_s` [s]; return the previous interval.

    A shorter interval already set is kept (never lengthened).

    Raises:
        ValueError: `interval_s` is not positive.
    """
    if not interval_s > 0:
        raise ValueError(f"realtime_switch_interval: the interval must be > 0 s, got {interval_s}")
    previous = sys.getswitchinterval()
    sys.setswitchinterval(min(previous, interval_s))
    return previous


def freeze_heap() -> int:
    """Collect the garbage, then exempt every object alive from later collections (see the module docstring).

    Call it once the process has built what it keeps (before a real-time loop starts); calling it again also
    exempts what was built since. Reference cycles made of frozen objects are never freed: what is frozen must be
    what the process keeps anyway.

    Returns:
        How many objects are now frozen.
    """
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


@contextlib.contextmanager
def frozen_heap() -> Iterator[int]:
    """`freeze_heap` for the span of a `with` block, for a library call that talks to motors and then returns.

    On leaving, the objects frozen are handed back to the collector (`gc.unfreeze`), so that what the call built and
    dropped is freed; when the heap was already frozen on entry (the caller froze it, for its own loop), it stays so,
    since the collector cannot tell one freeze from another.

    Yields:
        How many objects are frozen.
    """
    already = gc.get_freeze_count() > 0
    count = freeze_heap()
    try:
        yield count
    finally:
        if not already:
            gc.unfreeze()
