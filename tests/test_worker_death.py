"""A worker process that dies costs only the trial it was playing; one a controller's thread keeps alive is stopped.

A controller that exits its process (``os._exit``), or is killed by a signal or for its memory, breaks the local
pool and every trial then in flight with it. The arena plays each of those again alone: the one whose worker dies
again is that controller's error, the others keep their records, and the run goes on in a fresh pool. A worker a
controller's non-daemon thread keeps alive after its trials is terminated, with a warning, instead of hanging the run.
"""

import os
import subprocess
import sys
import textwrap

import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN

from wbc.arena import executors
from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.trial_record import TrialRecord
from wbc.cli import main
from wbc.errors import ConfigError

EXITS = STAND_PLUGIN.format(doc="The stand hold that exits its process on its fifth tick.", reset="pass",
                            act="if self.ticks == 5:\n                __import__('os')._exit(3)",
                            counters="return {}")

SPINS = STAND_PLUGIN.format(doc="The stand hold that leaves a thread running in its process.",
                            reset="__import__('threading').Thread(target=__import__('time').sleep, args=(3600,), "
                                  "daemon=False).start()",
                            act="pass", counters="return {}")


def _run(tmp_path, controllers, out):
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    return run_arena(ArenaConfig(controllers=controllers, scenario=scenario, trials=3, out_dir=tmp_path / out,
                                 workers=2, progress=False))


def test_a_controller_that_exits_its_worker_costs_its_own_trials_only(plugin_package, tmp_path):
    plugin_package("diepkg", {"exits": EXITS})
    result = _run(tmp_path, ("stand", "diepkg.exits:make"), "run")
    by = {(r.controller, r.trial): r for r in result.records}
    assert len(by) == 6  # every trial recorded: stand's played again where the pool broke under them
    assert all(by[("stand", i)].success for i in range(3))
    for i in range(3):
        died = by[("diepkg.exits:make", i)]
        assert died.outcome == "controller_error" and f"trial {i}: the worker process playing it died" in died.error
    (errors,) = result.controller_errors
    assert errors.controller == "diepkg.exits:make"


def test_a_worker_kept_alive_by_a_controllers_thread_is_stopped_with_a_warning(plugin_package, tmp_path, capsys,
                                                                               monkeypatch):
    plugin_package("spinpkg", {"spins": SPINS})
    monkeypatch.setattr(executors, "_LINGER_S", 0.5)
    result = _run(tmp_path, ("spinpkg.spins:make",), "run")
    assert len(result.records) == 3 and all(r.success for r in result.records)
    assert "still ran 0.5 s after their trials ended" in capsys.readouterr().err


def test_a_worker_that_the_pools_own_thread_reaps_is_not_taken_for_a_lingering_one(tmp_path, capsys, monkeypatch):
    """The pool's thread reaps its workers; a wait here for the same worker gets ECHILD, where a poll reads None.

    Modelled by polls from this thread that always read so: the run's shut-down must not take the worker for one still
    running (it warned of a controller's thread, and signalled a process id no longer the worker's).
    """
    import threading
    from multiprocessing import popen_fork

    poll = popen_fork.Popen.poll

    def lost_the_reap(self, flag=os.WNOHANG):
        if threading.current_thread() is threading.main_thread() and self.returncode is None:
            return None  # what popen_fork's poll returns on ECHILD
        return poll(self, flag)

    signalled = []
    monkeypatch.setattr(executors, "_LINGER_S", 600.0)  # a bound only: however loaded the machine, never reached
    monkeypatch.setattr(popen_fork.Popen, "poll", lost_the_reap)
    monkeypatch.setattr(popen_fork.Popen, "terminate", lambda self: signalled.append(self.pid))
    result = _run(tmp_path, ("stand",), "run")
    assert len(result.records) == 3 and all(r.success for r in result.records)
    assert "still ran" not in capsys.readouterr().err and signalled == []


def _command(tmp_path, module: str, source: str, *args: str) -> subprocess.CompletedProcess:
    """``python -m wbc.cli ARGS`` in `tmp_path`, beside the plug-in `module` (`source`) and the short scenario."""
    (tmp_path / f"{module}.py").write_text(textwrap.dedent(source).lstrip())
    (tmp_path / "short.toml").write_text(SHORT_SCENARIO)
    return subprocess.run([sys.executable, "-m", "wbc.cli", *args, "--scenario", "short.toml", "--out", "out",
                           "--quiet"], cwd=tmp_path, capture_output=True, text=True, timeout=300)


def test_with_one_worker_the_command_line_still_plays_in_a_worker_process(tmp_path):
    # --workers 1 on the command line: a controller that ends its process costs its own trials, not the run
    done = _command(tmp_path, "exits", EXITS, "compare", "exits:make", "stand", "--trials", "2", "--workers", "1")
    assert done.returncode == 1, done.stderr  # a controller failed: status 1, and the report is written
    by = {(r.controller, r.trial): r for r in TrialRecord.read_csv(tmp_path / "out" / "trials.csv")}
    assert len(by) == 4 and all(by[("stand", i)].success for i in range(2))
    assert all(by[("exits:make", i)].outcome == "controller_error" for i in range(2))
    assert (tmp_path / "out" / "report.md").is_file()


def test_in_process_a_controller_that_ends_the_process_ends_the_run(tmp_path):
    # --in-process asks for it (a debugger, a profiler): the trials recorded before it are kept
    done = _command(tmp_path, "exits", EXITS, "compare", "stand", "exits:make", "--trials", "2", "--workers", "1",
                    "--in-process")
    assert done.returncode == 3  # the plug-in's os._exit(3)
    records = TrialRecord.read_csv(tmp_path / "out" / "trials.csv")
    assert [(r.controller, r.trial) for r in records] == [("stand", 0)]


def test_in_process_refuses_what_needs_a_worker_process(capsys):
    for extra in (["--trial-time-limit", "60"], ["--workers", "2"], ["--executor", "ray"]):
        assert main(["run", "stand", "--scenario", "scenarios/push.toml", "--in-process", *extra]) == 2
        assert "--in-process" in capsys.readouterr().err


def test_the_command_ends_past_a_thread_a_controller_left_running_in_its_own_process(tmp_path):
    # --in-process plays in the command's own process: the thread would have kept it alive after the report
    done = _command(tmp_path, "spins", SPINS, "run", "spins:make", "--trials", "1", "--workers", "1", "--in-process")
    assert done.returncode == 0, done.stderr
    assert "thread(s) still running at the end" in done.stderr and "exiting without waiting for them" in done.stderr
    assert (tmp_path / "out" / "report.md").is_file()


EXITS_LOGGED = STAND_PLUGIN.format(doc="The stand hold that exits its process on its fifth tick; each reset is logged "
                                       "to $ATTEMPTS.",
                                   reset="open(__import__('os').environ['ATTEMPTS'], 'a').write('x')",
                                   act="if self.ticks == 5:\n                __import__('os')._exit(3)",
                                   counters="return {}")


def test_on_ray_a_controller_that_exits_its_worker_costs_its_own_trials_only(plugin_package, tmp_path, monkeypatch):
    pytest.importorskip("ray")
    root = plugin_package("raydiepkg", {"exits": EXITS_LOGGED})
    monkeypatch.setenv("PYTHONPATH", str(root))  # Ray's workers import the plug-in from their environment
    attempts = tmp_path / "attempts"
    monkeypatch.setenv("ATTEMPTS", str(attempts))
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    result = run_arena(ArenaConfig(controllers=("stand", "raydiepkg.exits:make"), scenario=scenario, trials=2,
                                   out_dir=tmp_path / "ray", executor="ray", progress=False))
    by = {(r.controller, r.trial): r for r in result.records}
    assert len(by) == 4 and by[("stand", 0)].success and by[("stand", 1)].success
    for i in range(2):
        died = by[("raydiepkg.exits:make", i)]
        assert died.outcome == "controller_error" and "died again when Ray played it once more" in died.error
    assert attempts.read_text() == "xxxx"  # each trial played twice, not once nor Ray's default four times


HANGS = STAND_PLUGIN.format(doc="The stand hold that hangs on its fifth tick; each reset is logged to $ATTEMPTS.",
                            reset="open(__import__('os').environ['ATTEMPTS'], 'a').write('x')",
                            act="if self.ticks == 5:\n                __import__('threading').Event().wait()",
                            counters="return {}")


@pytest.mark.parametrize(("workers", "trials"), [(1, 1), (2, 2)])
def test_a_controller_that_hangs_costs_its_own_trial_under_a_trial_time_limit(plugin_package, tmp_path, monkeypatch,
                                                                              workers, trials):
    # one worker: a time limit plays the trials in a worker process all the same, so that the hung one can be ended;
    # two: the standing trials in flight when a hung one's worker is ended go back to the fresh pool. The limit is far
    # above what a standing trial takes on any machine
    plugin_package("hangpkg", {"hangs": HANGS})
    attempts = tmp_path / "attempts"
    monkeypatch.setenv("ATTEMPTS", str(attempts))
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    result = run_arena(ArenaConfig(controllers=("stand", "hangpkg.hangs:make"), scenario=scenario, trials=trials,
                                   out_dir=tmp_path / "run", workers=workers, progress=False, trial_time_limit_s=10.0))
    by = {(r.controller, r.trial): r for r in result.records}
    assert len(by) == 2 * trials and all(by[("stand", i)].success for i in range(trials))
    for i in range(trials):
        hung = by[("hangpkg.hangs:make", i)]
        assert hung.outcome == "controller_error"
        assert f"trial {i}: ran past the trial time limit of 10 s (--trial-time-limit)" in hung.error
        # judged on what it played before it hung, as a controller that raises is: the 4 ticks at 50 Hz of the 1 s
        # episode it completed before it hung in its fifth call (it was 0, as if it had never stood)
        assert hung.ttf == pytest.approx(4 * (1 / 50) / 1.0)
    # an overrun trial is not played again; with two workers the second hung trial may have been beside the first
    # when its worker was ended, and is then played once more in the fresh pool (where it overruns itself)
    assert trials <= len(attempts.read_text()) <= (1 if workers == 1 else 2 * trials - 1)
    (errors,) = result.controller_errors
    assert errors.controller == "hangpkg.hangs:make"


def test_the_watchdog_ends_the_worker_only_when_the_trial_overruns(tmp_path):
    exits = []
    flag = tmp_path / "flag"
    # the trial ends first: the clock never runs out
    with executors._Watchdog(5.0, str(flag), wait=lambda event, timeout: event.wait(), exit_=exits.append) as dog:
        pass
    dog._thread.join(timeout=60)
    assert not dog._thread.is_alive() and exits == [] and not flag.exists()
    # the clock runs out first: the flag is left, naming the limit and how far the trial got (no episode begun: not
    # known), and the process ended with its own status
    executors.forget_played()
    waited = []
    dog = executors._Watchdog(5.0, str(flag), wait=lambda event, timeout: waited.append(timeout) or False,
                              exit_=exits.append)
    with dog:
        dog._thread.join(timeout=60)
    assert waited == [5.0] and exits == [executors.OVERRUN_EXIT] and flag.read_text() == "5.0\nNone\n"
    flag.unlink()
    # the clock runs out as the trial ends: the trial's end, taken first, stands
    exits.clear()
    with executors._Watchdog(5.0, str(flag), wait=lambda event, timeout: event.wait() and False,
                             exit_=exits.append) as dog:
        pass
    dog._thread.join(timeout=60)
    assert exits == [] and not flag.exists()
    # a flag that cannot be written does not keep a hung trial's worker alive
    dog = executors._Watchdog(5.0, str(tmp_path / "gone" / "flag"), wait=lambda event, timeout: False,
                              exit_=exits.append)
    with dog:
        dog._thread.join(timeout=60)
    assert exits == [executors.OVERRUN_EXIT]


@pytest.mark.parametrize("limit", [0.0, 0.5, -1.0, float("nan"), float("inf"), True, "10"])
def test_a_trial_time_limit_must_be_a_number_of_seconds_from_one(tmp_path, limit):
    with pytest.raises(ConfigError, match="--trial-time-limit must be a number of seconds from 1 to"):
        ArenaConfig(controllers=("stand",), scenario=tmp_path / "x.toml", trial_time_limit_s=limit)


def test_a_trial_time_limit_is_refused_with_a_live_view_and_on_ray(tmp_path):
    with pytest.raises(ConfigError, match="a viewed run"):
        ArenaConfig(controllers=("stand",), scenario=tmp_path / "x.toml", trial_time_limit_s=10.0,
                    observer=lambda *a: None)
    with pytest.raises(ConfigError, match="enforced in the local pool's workers, not on Ray"):
        ArenaConfig(controllers=("stand",), scenario=tmp_path / "x.toml", trial_time_limit_s=10.0, executor="ray")


def _worker_sees() -> tuple[str | None, str | None, bool]:
    import os
    import sys

    import mujoco  # noqa: F401 - what a worker imports to simulate

    return os.environ.get("MUJOCO_GL"), os.environ.get("OPENBLAS_NUM_THREADS"), "glfw" in sys.modules


def test_a_worker_starts_with_its_blas_single_threaded_and_mujocos_rendering_off(monkeypatch):
    """Importing MuJoCo with its rendering on loads GLFW, whose library check runs a Python subprocess in each worker;
    a run stopped while its workers started printed that subprocess's broken-pipe traceback. A MUJOCO_GL the user
    sets is kept, and this process's environment is given back."""
    monkeypatch.delenv("MUJOCO_GL", raising=False)
    with executors.worker_environment(), executors.spawn_pool(1) as pool:
        assert pool.submit(_worker_sees).result(timeout=120) == ("disable", "1", False)
    assert "MUJOCO_GL" not in os.environ
    monkeypatch.setenv("MUJOCO_GL", "egl")
    with executors.worker_environment(), executors.spawn_pool(1) as pool:
        assert pool.submit(_worker_sees).result(timeout=120)[0] == "egl"
    assert os.environ["MUJOCO_GL"] == "egl"
