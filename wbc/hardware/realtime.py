"""Real-time scheduling for a process that talks to motors: what it asks the OS for, and what it got.

A link thread (500 Hz), an arm bus (200 Hz) and an emulator standing in for the robot's processors sleep most of
each period and must wake on time. On a computer that also computes (a controller, a build, a browser), the OS's
fair scheduler hands the CPU to whoever has waited longest, and a thread that woke on time can wait tens of
milliseconds for it: long enough for a servo to miss its answer and a watchdog to fire. `request_realtime` asks the
OS, once, at start-up, before the process starts its threads (Linux gives each new thread its creator's policy):

- real-time scheduling (``SCHED_FIFO`` by default, or ``SCHED_RR``) at a modest priority: a thread that wakes
  pre-empts every ordinary one at once. The loops sleep every period, so they cannot starve the machine; a priority
  well below the kernel's own threads (which run at 50 on a PREEMPT_RT kernel) is used by default;
- a CPU of its own where the process may run on several (``sched_setaffinity``), so that its caches stay warm and it
  never queues behind another real-time process pinned elsewhere;
- locked memory (``mlockall(MCL_CURRENT | MCL_FUTURE)``): no page of it is swapped out or faulted in lazily in the
  middle of a cycle.

Each is tried on its own; a refusal (no ``CAP_SYS_NICE`` and ``RLIMIT_RTPRIO`` 0, no ``CAP_IPC_LOCK`` and a small
``RLIMIT_MEMLOCK``, a CPU not in the allowed set, not Linux) is recorded with its reason, and the process runs on as
before with ordinary scheduling. The `RealtimeGrant` says what was asked, what was granted, and why not: ``wbc hw run``
writes it to ``hardware.json`` and its report, ``wbc hw emulate`` prints it. What a team must grant a user for it is in
the docs (real-time scheduling): ``CAP_SYS_NICE`` and ``CAP_IPC_LOCK``, or ``rtprio`` and ``memlock`` limits.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import resource
import sys
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field

from wbc.errors import ConfigError

__all__ = [
    "AUTO_CPU",
    "CONTROLLER_PRIORITY_BELOW",
    "DEFAULT_RT_PRIORITY",
    "NO_REALTIME",
    "RealtimeGrant",
    "RealtimeRequest",
    "controller_realtime",
    "request_realtime",
]

DEFAULT_RT_PRIORITY = 50
"""The default real-time priority (1..99): above every ordinary process, below the kernel's own interrupt threads on
a PREEMPT_RT kernel (which also run at 50: a tie goes to whoever runs first)."""
CONTROLLER_PRIORITY_BELOW = 10
"""How far below the devices' priority the controller's loop asks for (`controller_realtime`)."""
AUTO_CPU = -1
"""`RealtimeRequest.cpu`: choose a CPU (`RealtimeRequest.place`: the last, or the first, of the allowed set)."""
_MCL_CURRENT, _MCL_FUTURE = 1, 2
_CAP_IPC_LOCK, _CAP_SYS_NICE = 14, 23
_POLICIES = {"fifo": "SCHED_FIFO", "rr": "SCHED_RR"}


@dataclass(frozen=True, kw_only=True)
class RealtimeRequest:
    """What a process asks the OS for (see the module docstring).

    Attributes:
        priority: the real-time priority, 1..99; None asks for no real-time scheduling.
        policy: ``fifo`` (``SCHED_FIFO``: runs until it sleeps) or ``rr`` (``SCHED_RR``: round robin among equals).
        cpu: the CPU to run on; None: wherever the OS likes; `AUTO_CPU`: one chosen by `place` where the process may
            run on more than one CPU (on a single one there is nothing to choose).
        place: with `AUTO_CPU`: ``last`` or ``first`` CPU of the allowed set. The I/O process takes the last; an
            emulator, which stands in for the robot's own processors, the first, so that the two are not stacked.
        lock_memory: lock the process's memory (current and future pages) in RAM.
    """

    priority: int | None = DEFAULT_RT_PRIORITY
    policy: str = "fifo"
    cpu: int | None = AUTO_CPU
    place: str = "last"
    lock_memory: bool = True

    def __post_init__(self) -> None:
        if self.priority is not None and not (isinstance(self.priority, int) and 1 <= self.priority <= 99):
            raise ConfigError(f"RealtimeRequest.priority must be an integer in [1, 99] or None (no real-time "
                              f"scheduling), got {self.priority!r}")
        if self.policy not in _POLICIES:
            raise ConfigError(f"RealtimeRequest.policy must be one of {sorted(_POLICIES)}, got {self.policy!r}")
        if self.cpu is not None and not (isinstance(self.cpu, int) and self.cpu >= AUTO_CPU):
            raise ConfigError(f"RealtimeRequest.cpu must be a CPU number >= 0, AUTO_CPU (-1) or None, got "
                              f"{self.cpu!r}")
        if self.place not in ("last", "first"):
            raise ConfigError(f"RealtimeRequest.place must be 'last' or 'first', got {self.place!r}")

    @property
    def asks_nothing(self) -> bool:
        """True if nothing is asked (the process runs as an ordinary one, on purpose)."""
        return self.priority is None and self.cpu is None and not self.lock_memory


NO_REALTIME = RealtimeRequest(priority=None, cpu=None, lock_memory=False)
"""Ask for nothing: ordinary scheduling, any CPU, memory not locked (``--no-realtime``)."""


@dataclass(frozen=True, kw_only=True)
class RealtimeGrant:
    """What a process asked for and what the OS granted (each part tried on its own).

    Attributes:
        pid: the process.
        asked: the request, in words (``SCHED_FIFO 50, CPU 1, locked memory``).
        scheduling: the policy and priority in force afterwards (``SCHED_FIFO 50``, or ``SCHED_OTHER``).
        cpus: the CPUs the process may run on afterwards.
        memory_locked: True if ``mlockall`` succeeded.
        refused: one line per part asked for and not granted, with the OS's reason.
    """

    pid: int
    asked: str
    scheduling: str
    cpus: tuple[int, ...]
    memory_locked: bool
    refused: tuple[str, ...] = field(default_factory=tuple)

    @property
    def realtime(self) -> bool:
        """True if the process runs under a real-time policy."""
        return self.scheduling.startswith(("SCHED_FIFO", "SCHED_RR"))

    def describe(self) -> str:
        """One line: what was asked, what was granted, and why not."""
        memory = "locked" if self.memory_locked else "not locked"
        got = f"{self.scheduling}, CPU {_cpu_list(self.cpus)}, memory {memory}"
        text = f"asked {self.asked}; got {got}"
        if self.refused:
            text += "; refused: " + "; ".join(self.refused)
        return text

    def to_dict(self) -> dict:
        """The grant as plain data (``hardware.json``)."""
        out = asdict(self)
        out["cpus"] = list(self.cpus)
        out["refused"] = list(self.refused)
        out["realtime"] = self.realtime
        return out

    @classmethod
    def from_dict(cls, data: dict) -> RealtimeGrant:
        """The grant `to_dict` wrote (e.g. sent by the I/O process)."""
        return cls(pid=int(data["pid"]), asked=str(data["asked"]), scheduling=str(data["scheduling"]),
                   cpus=tuple(int(c) for c in data["cpus"]), memory_locked=bool(data["memory_locked"]),
                   refused=tuple(str(r) for r in data["refused"]))


def _cpu_list(cpus: tuple[int, ...]) -> str:
    return ",".join(str(c) for c in cpus) if cpus else "?"


def _capability(bit: int) -> bool | None:
    """True if the process holds capability `bit` (effective set), None where that cannot be read."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("CapEff:"):
                    return bool(int(line.split()[1], 16) >> bit & 1)
    except OSError:
        return None
    return None


def _limit(name: str) -> str:
    which = getattr(resource, name, None)
    if which is None:
        return f"{name} unknown"
    soft, _ = resource.getrlimit(which)
    return f"{name} {'unlimited' if soft == resource.RLIM_INFINITY else soft}"


def _why(exc: OSError, capability: int, cap_name: str, limit: str) -> str:
    held = _capability(capability)
    cap = {True: f"holds {cap_name}", False: f"no {cap_name}", None: f"{cap_name} unknown"}[held]
    return f"{exc.strerror or exc} ({cap}, {_limit(limit)})"


def _scheduling_now() -> str:
    if not hasattr(os, "sched_getscheduler"):
        return "unknown (not Linux)"
    policy = os.sched_getscheduler(0)
    names = {os.SCHED_OTHER: "SCHED_OTHER", os.SCHED_FIFO: "SCHED_FIFO", os.SCHED_RR: "SCHED_RR"}
    name = names.get(policy, f"policy {policy}")
    if policy in (os.SCHED_FIFO, os.SCHED_RR):
        return f"{name} {os.sched_getparam(0).sched_priority}"
    return name


def _allowed_cpus() -> tuple[int, ...]:
    return tuple(sorted(os.sched_getaffinity(0))) if hasattr(os, "sched_getaffinity") else ()


def _lock_memory() -> OSError | None:
    libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
    if libc.mlockall(_MCL_CURRENT | _MCL_FUTURE) == 0:
        return None
    errno = ctypes.get_errno()
    return OSError(errno, os.strerror(errno))


def request_realtime(request: RealtimeRequest) -> RealtimeGrant:
    """Ask the OS for what `request` names, for this process; never raises for a refusal.

    Call it before the process starts its threads: on Linux the policy and the CPU set are the calling thread's,
    and threads started later inherit them. Call it after the process's slow start-up (imports, building, the first
    call of compiled code): what runs at a real-time priority holds off every other thread of that priority on its
    CPU. The memory is locked first, before the priority changes, for the same reason.

    Args:
        request: the priority, CPU and memory locking to ask for.

    Returns:
        What was asked, what is in force now, and each refusal with its reason.
    """
    refused: list[str] = []
    asked: list[str] = []
    linux = sys.platform.startswith("linux") and hasattr(os, "sched_setscheduler")
    # the memory first, at the priority the caller has: locking it faults in every page the process maps (some
    # 50 ms of CPU for an interpreter with numpy and MuJoCo loaded), work that a real-time priority would let hold
    # off every other thread of that priority on the CPU
    locked, lock_refusal = False, None
    if request.lock_memory and linux:
        error = _lock_memory()
        locked = error is None
        if error is not None:
            lock_refusal = "locked memory: " + _why(error, _CAP_IPC_LOCK, "CAP_IPC_LOCK", "RLIMIT_MEMLOCK")
    allowed = _allowed_cpus()
    cpu = request.cpu
    if cpu == AUTO_CPU:
        cpu = (allowed[-1] if request.place == "last" else allowed[0]) if len(allowed) > 1 else None
        asked.append(f"CPU {cpu} (the {request.place} of {_cpu_list(allowed)})" if cpu is not None else
                     f"a CPU of its own (none to choose: CPU {_cpu_list(allowed)} only)")
    elif cpu is not None:
        asked.append(f"CPU {cpu}")
    if cpu is not None:
        if not linux:
            refused.append(f"CPU {cpu}: not Linux")
        else:
            try:
                os.sched_setaffinity(0, {cpu})
            except OSError as exc:
                refused.append(f"CPU {cpu}: {exc.strerror or exc} (allowed: CPU {_cpu_list(allowed)})")
    if request.priority is not None:
        policy = _POLICIES[request.policy]
        asked.insert(0, f"{policy} {request.priority}")
        if not linux:
            refused.append(f"{policy}: not Linux")
        else:
            try:
                os.sched_setscheduler(0, getattr(os, policy), os.sched_param(request.priority))
            except OSError as exc:
                refused.append(f"{policy} {request.priority}: " + _why(exc, _CAP_SYS_NICE, "CAP_SYS_NICE",
                                                                      "RLIMIT_RTPRIO"))
    if request.lock_memory:  # listed after the scheduling and the CPU
        asked.append("locked memory")
        if not linux:
            refused.append("locked memory: not Linux")
        elif lock_refusal is not None:
            refused.append(lock_refusal)
    return RealtimeGrant(pid=os.getpid(), asked=", ".join(asked) or "nothing (ordinary scheduling)",
                         scheduling=_scheduling_now() if linux else "unknown (not Linux)", cpus=_allowed_cpus(),
                         memory_locked=locked, refused=tuple(refused))


@contextlib.contextmanager
def controller_realtime(request: RealtimeRequest) -> Iterator[RealtimeGrant]:
    """Ask for `request` for the calling thread (a controller's loop) while the block runs; restore it afterwards.

    The devices' process (`request_realtime`) sleeps most of each period; a controller's loop computes for most of
    it and writes its command before the devices' write deadline. Under ordinary scheduling, on a busy computer, the
    fair scheduler can hold such a thread off the CPU for longer than that deadline, and the robot is damped for a
    pause that was not the controller's. Asked at a priority below the devices' (`CONTROLLER_PRIORITY_BELOW`), the
    loop pre-empts every ordinary process and never the devices: a controller's loop in ros2_control is run the same
    way. A loop that cannot keep its period still runs late, not starved; the kernel's real-time throttling (95 % of
    each second by default) leaves the rest of the machine a share.

    Only this thread's policy and CPU set change, and threads it starts meanwhile inherit them; both are restored
    when the block ends. Memory is locked only if `request` asks (the whole process's, and unlocked afterwards).

    Args:
        request: what to ask for (`NO_REALTIME`: nothing; the block runs as it would without this).

    Yields:
        What was asked and granted.
    """
    linux = sys.platform.startswith("linux") and hasattr(os, "sched_setscheduler")
    before = (os.sched_getscheduler(0), os.sched_getparam(0), _allowed_cpus()) if linux else None
    grant = request_realtime(request)
    try:
        yield grant
    finally:
        if before is not None:
            policy, param, cpus = before
            with contextlib.suppress(OSError):
                os.sched_setscheduler(0, policy, param)
            if cpus:
                with contextlib.suppress(OSError):
                    os.sched_setaffinity(0, set(cpus))
        if grant.memory_locked:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
            libc.munlockall()
