"""`request_realtime`: what a process asks the OS for, what it got, and why not.

A refusal is injected by replacing the OS calls (never by changing this test process's own scheduling); the real
calls run in a child process, at the lowest real-time priority, so a granted request cannot starve the machine.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from wbc.errors import ConfigError
from wbc.hardware import realtime
from wbc.hardware.realtime import AUTO_CPU, NO_REALTIME, RealtimeGrant, RealtimeRequest, request_realtime

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="real-time scheduling is Linux's here")


def test_a_request_is_checked() -> None:
    for bad in (dict(priority=0), dict(priority=100), dict(policy="batch"), dict(cpu=-2), dict(place="middle")):
        with pytest.raises(ConfigError, match="RealtimeRequest"):
            RealtimeRequest(**bad)
    assert NO_REALTIME.asks_nothing and not RealtimeRequest().asks_nothing


def test_asking_nothing_changes_nothing_and_says_so() -> None:
    grant = request_realtime(NO_REALTIME)
    assert grant.asked.startswith("nothing") and grant.refused == () and not grant.memory_locked
    assert grant.pid == os.getpid()


@linux
def test_each_refusal_is_recorded_with_its_reason_and_the_process_runs_on(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: {0, 1, 2, 3})
    monkeypatch.setattr(os, "sched_setaffinity", lambda _pid, _cpus: (_ for _ in ()).throw(OSError(22, "Invalid "
                                                                                                         "argument")))
    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(realtime, "_lock_memory", lambda: OSError(12, "Cannot allocate memory"))
    grant = request_realtime(RealtimeRequest(priority=50, cpu=AUTO_CPU, place="last"))
    assert grant.asked == "SCHED_FIFO 50, CPU 3 (the last of 0,1,2,3), locked memory"
    assert len(grant.refused) == 3 and not grant.memory_locked
    cpu, fifo, memory = grant.refused
    assert cpu.startswith("CPU 3: Invalid argument")
    assert fifo.startswith("SCHED_FIFO 50: Operation not permitted") and "CAP_SYS_NICE" in fifo
    assert "RLIMIT_RTPRIO" in fifo
    assert memory.startswith("locked memory: Cannot allocate memory") and "RLIMIT_MEMLOCK" in memory
    assert "refused: CPU 3" in grant.describe()
    assert RealtimeGrant.from_dict(json.loads(json.dumps(grant.to_dict()))) == grant


@linux
def test_the_memory_is_locked_before_the_priority_rises(monkeypatch: pytest.MonkeyPatch) -> None:
    """Locking faults in every page the process maps (~50 ms of CPU): done at a real-time priority, it held off every
    other thread of that priority on the CPU."""
    calls: list[str] = []
    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: {0, 1})
    monkeypatch.setattr(os, "sched_setaffinity", lambda _pid, _cpus: calls.append("cpu"))
    monkeypatch.setattr(os, "sched_setscheduler", lambda *_: calls.append("priority"))
    monkeypatch.setattr(realtime, "_lock_memory", lambda: calls.append("memory"))
    grant = request_realtime(RealtimeRequest(priority=50, cpu=AUTO_CPU, place="last"))
    assert calls == ["memory", "cpu", "priority"]
    assert grant.asked == "SCHED_FIFO 50, CPU 1 (the last of 0,1), locked memory"
    assert grant.memory_locked and grant.refused == ()


@linux
def test_the_grant_is_what_the_os_reports_in_a_child_process() -> None:
    code = ("import json; from wbc.hardware.realtime import RealtimeRequest, request_realtime; "
            "g = request_realtime(RealtimeRequest(priority=1, cpu=None, lock_memory=False)); "
            "print(json.dumps(g.to_dict()))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    grant = RealtimeGrant.from_dict(json.loads(out.stdout))
    assert grant.asked == "SCHED_FIFO 1"
    if grant.realtime:  # root, CAP_SYS_NICE, or an rtprio limit: granted
        assert grant.scheduling == "SCHED_FIFO 1" and grant.refused == ()
    else:  # refused: said, with the reason, and the process ran on
        assert grant.scheduling == "SCHED_OTHER" and grant.refused[0].startswith("SCHED_FIFO 1: ")


@linux
def test_a_controllers_loop_asks_for_its_thread_only_and_gets_its_scheduling_back() -> None:
    code = ("import json, os, threading; from wbc.hardware.realtime import RealtimeRequest, controller_realtime; "
            "seen = {}; "
            "other = lambda: seen.setdefault('other', os.sched_getscheduler(0)); "
            "before = os.sched_getscheduler(0); "
            "ctx = controller_realtime(RealtimeRequest(priority=1, cpu=None, lock_memory=False)); "
            "g = ctx.__enter__(); inside = os.sched_getscheduler(0); "
            "t = threading.Thread(target=other); t.start(); t.join(); "
            "ctx.__exit__(None, None, None); after = os.sched_getscheduler(0); "
            "print(json.dumps(dict(grant=g.to_dict(), before=before, inside=inside, after=after, "
            "started=seen['other'], fifo=os.SCHED_FIFO, other_policy=os.SCHED_OTHER)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    seen = json.loads(out.stdout)
    grant = RealtimeGrant.from_dict(seen["grant"])
    assert grant.asked == "SCHED_FIFO 1" and seen["before"] == seen["other_policy"]
    if grant.realtime:  # granted: the loop's thread and the threads it starts run real-time
        assert seen["inside"] == seen["fifo"] and seen["started"] == seen["fifo"]
    else:  # refused: said, and the loop runs on as before
        assert seen["inside"] == seen["other_policy"] and grant.refused[0].startswith("SCHED_FIFO 1: ")
    assert seen["after"] == seen["before"]  # restored when the trial ends
