"""A broken controller costs its own trials, never the comparison.

Plug-ins broken in each way a controller can break (it raises late in a trial, returns NaN, returns the wrong number
of joints, raises in ``reset``), and two that are only slow (late on every tick) or saturating (a torque the motors
cannot give), are compared with ``stand``: every ``stand`` trial is recorded exactly as when
``stand`` plays alone, every broken trial is recorded with the outcome ``controller_error`` and a message naming the
controller, the trial and the plug-in's own file and line, and the command ends with status 1 and one line per failing
controller. A controller failing on K trials in a row is stopped while the others finish, on the local pool and on
Ray, and a resumed run plays none of the recorded failures again. The slow and the saturating plug-ins fail nothing:
their late and clamped ticks are counted in every row and warned about, alike on both executors. Nor does the limp
one, which falls in every trial: a fall is a result, and the command exits 0.
"""

import dataclasses
import json
import math
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import SHORT_SCENARIO, STAND_PLUGIN, untimed_summary

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.episode import Episode, SafetyLog
from wbc.arena.error_guard import ErrorGuard
from wbc.arena.report import format_table
from wbc.arena.trial_record import MACHINE_TIMED, TrialRecord
from wbc.cli.main import main
from wbc.scenario.scenario import load_scenario

SCENARIO = SHORT_SCENARIO

BROKEN = {
    # after 0.5 s of the trial (the 26th tick at 50 Hz)
    "late": ("raises after half a second", "pass",
             'if self.ticks > 25: raise RuntimeError("lost track of the ground")  # MARK'),
    "nan": ("returns NaN", "pass",
            "out = MotorCommand(q=np.full(15, np.nan), dq=out.dq, kp=out.kp, kd=out.kd, tau=out.tau)  # MARK"),
    # built unchecked (`MotorCommand.trusted`, as a compiled controller may): the robot's write refuses it
    "nan_trusted": ("returns NaN in a command built unchecked", "pass",
                    "out = MotorCommand.trusted(np.vstack([out.q, out.dq, out.kp, out.kd, "
                    "np.r_[np.nan, out.tau[1:]]]))"),
    "short": ("returns 12 of 15 joints", "pass",
              "out = MotorCommand(q=out.q[:12], dq=out.dq[:12], kp=out.kp[:12], kd=out.kd[:12], tau=out.tau[:12])"),
    "reset": ("raises in reset", 'raise KeyError("no calibration")  # MARK', "pass"),
    # a plug-in that exits (sys.exit, or an argparse inside it): the command must go on, not end without a word
    "exits": ("calls sys.exit after half a second", "pass", "if self.ticks > 25: raise SystemExit(7)  # MARK"),
    # not errors: late on every tick (21 ms at a 20 ms period), and a torque the motors cannot give on every tick
    "slow": ("acts in 21 ms", "pass", '__import__("time").sleep(0.021)'),
    "saturating": ("asks for 1e5 N m", "pass",
                   "out = MotorCommand(q=out.q, dq=out.dq, kp=out.kp, kd=out.kd, tau=np.full(15, 1e5))"),
    # not an error either: limp (no gain, no torque), it falls in every trial
    "limp": ("lets go of every joint", "pass",
             "out = MotorCommand(q=out.q, dq=out.dq, kp=np.zeros(15), kd=np.zeros(15), tau=np.zeros(15))"),
    # fails every other trial this process plays (a counter kept across the controllers it builds)
    "flaky": ("fails every other trial", "pass",
              "if self.ticks == 1 and next(COUNT) % 2: raise ValueError(\"odd trial\")  # MARK"),
}
"""Plug-in module name -> (docstring, body of reset, body of act); MARK tags the line the error must name."""


@pytest.fixture
def broken(plugin_package):
    """A package `brokenpkg` of broken plug-ins on sys.path (and forgotten afterwards); its root directory."""
    modules = {}
    for name, (doc, reset, act) in BROKEN.items():
        text = textwrap.dedent(STAND_PLUGIN.format(doc=doc, reset=reset, act=act, counters="return {}")).lstrip()
        if name == "flaky":
            text = text.replace("import numpy as np\n", "import itertools\n\nimport numpy as np\n\nCOUNT = "
                                "itertools.count()\n")
        modules[name] = text
    return plugin_package("brokenpkg", modules)


@pytest.fixture
def scenario(tmp_path):
    path = tmp_path / "short.toml"
    path.write_text(SCENARIO)
    return path


@pytest.fixture(scope="module")
def stand_alone(tmp_path_factory):
    """The records of `stand` playing the scenario alone (2 trials, in this process)."""
    tmp = tmp_path_factory.mktemp("alone")
    path = tmp / "short.toml"
    path.write_text(SCENARIO)
    run_arena(ArenaConfig(controllers=("stand",), scenario=path, seeds=(0,), trials=2, out_dir=tmp / "o",
                          workers=1, progress=False))
    return TrialRecord.read_csv(tmp / "o" / "trials.csv")


def _metrics(records, controller):
    """Each record's stored cells but those timed on the machine's clock, by trial."""
    skip = {TrialRecord.header().index(name) for name in MACHINE_TIMED}
    return {r.pair_key: [c for i, c in enumerate(r.to_row()) if i not in skip] for r in records
            if r.controller == controller}


def _marked_line(root, module, marker="# MARK"):
    """``file:line`` of the line of `module` holding `marker`."""
    path = root / "brokenpkg" / f"{module}.py"
    (line,) = [i for i, text in enumerate(path.read_text().splitlines(), start=1) if marker in text]
    return f"{path}:{line}"


EXPECTED = {
    "late": ("act raised RuntimeError at tick 25 (t = 0.500 s): lost track of the ground", "# MARK"),
    "nan": ("act raised CommandError at tick 0 (t = 0.000 s): MotorCommand.q: non-finite value at joint index 0",
            "# MARK"),
    "nan_trusted": ("act returned a command the robot refused: CommandError at tick 0 (t = 0.000 s): "
                    "MujocoRobot.write: the command holds a non-finite value at tau[FR_hip_joint]; refused before it "
                    "reached a motor", "def act"),
    "short": ("act returned a command the robot refused: CommandError at tick 0 (t = 0.000 s): MujocoRobot.write: "
              "command has 12 joints, this robot has 15", "def act"),
    "reset": ("reset raised KeyError before the first tick: 'no calibration'", "# MARK"),
    "exits": ("act raised SystemExit at tick 25 (t = 0.500 s): 7", "# MARK"),
}
"""What each broken plug-in's error says, and the marker of the line it names."""

HINTS = {
    "short": '; 12 joints are the legs alone, and this robot\'s arm is actuated (15 joints, the arm mode a plain '
             'factory claims): a controller of the legs declares the arm modes it drives, ControllerPlugin(make=..., '
             'arm_modes=("none",))',
}
"""What the error says after the exception's message, on how to fix it, where the house can tell."""


@pytest.mark.parametrize("kind", sorted(EXPECTED))
def test_a_broken_plugin_costs_its_own_trials_only(kind, broken, scenario, stand_alone, tmp_path, capsys):
    name = f"brokenpkg.{kind}:make"
    out = tmp_path / "o"
    assert main(["compare", name, "stand", "--scenario", str(scenario), "--trials", "2", "--workers", "1",
                 "--out", str(out), "--quiet"]) == 1
    records = TrialRecord.read_csv(out / "trials.csv")
    # stand's trials are recorded exactly as when it plays alone
    assert _metrics(records, "stand") == _metrics(stand_alone, "stand") and len(_metrics(records, "stand")) == 2
    mine = [r for r in records if r.controller == name]
    assert len(mine) == 2
    what, marker = EXPECTED[kind]
    where = _marked_line(broken, kind, marker)
    for r in mine:
        # an error, not a fall: it counts against success, and says who, which trial, what, and where
        assert r.outcome == "controller_error" and r.success is False and math.isnan(r.fall_time_s)
        assert r.error.startswith(f"controller {name}, band soft, seed {r.seed}, trial {r.trial}: {what}")
        assert r.error.endswith(f" [{where}]")
        assert HINTS.get(kind, "") in r.error
        assert r.ttf == (0.5 if kind in ("late", "exits") else 0.0)
    # the command ends with status 1 and one line for the failing controller; no traceback
    captured = capsys.readouterr()
    # the table counts the errors in a column of their own: 2 trials, 2 errors; stand 2 trials, none
    header = next(line for line in captured.out.splitlines() if line.strip().startswith("controller"))
    assert header.split()[:3] == ["controller", "trials", "errors"]
    assert re.search(rf"^  {re.escape(name)}\s+2\s+2\s", captured.out, re.M)
    assert re.search(r"^  stand\s+2\s+0\s", captured.out, re.M)
    err = captured.err
    lines = [line for line in err.splitlines() if line.startswith("wbc: controller ")]
    assert lines == [f"wbc: controller {name}: 2 of 2 trial(s) failed with a controller error; first: {mine[0].error}"]
    assert "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["controllers"][name]["bands"]["soft"]["outcomes"]["controller_error"] == 2
    assert summary["controllers"]["stand"]["bands"]["soft"]["outcomes"]["controller_error"] == 0
    assert summary["controller_errors"][name]["errored"] == 2 and not summary["controller_errors"][name]["stopped"]
    assert "stand" not in summary["controller_errors"]


def test_a_controller_failing_k_trials_in_a_row_is_stopped_and_resume_replays_nothing(broken, scenario, tmp_path,
                                                                                        capsys):
    out = tmp_path / "o"
    cfg = ArenaConfig(controllers=("brokenpkg.late:make", "brokenpkg.flaky:make", "stand"), scenario=scenario,
                      seeds=(0,), trials=5, out_dir=out, workers=1, progress=False, max_consecutive_errors=2)
    result = run_arena(cfg)
    records = TrialRecord.read_csv(out / "trials.csv")
    by = {c: [r for r in records if r.controller == c] for c in cfg.controllers}
    # late fails every trial: stopped after two, its three others not played; the others play all five
    assert [r.trial for r in by["brokenpkg.late:make"]] == [0, 1]
    assert len(by["stand"]) == 5 and all(r.outcome != "controller_error" for r in by["stand"])
    # flaky fails every other trial: never two in a row, so it plays on
    assert [r.outcome == "controller_error" for r in by["brokenpkg.flaky:make"]] == [False, True, False, True, False]
    errors = {e.controller: e for e in result.controller_errors}
    assert list(errors) == ["brokenpkg.late:make", "brokenpkg.flaky:make"]
    late, flaky = errors["brokenpkg.late:make"], errors["brokenpkg.flaky:make"]
    assert (late.errored, late.recorded, late.stopped, late.not_played) == (2, 2, True, 3)
    assert (flaky.errored, flaky.recorded, flaky.stopped, flaky.not_played) == (2, 5, False, 0)
    assert "STOPPED after 2 consecutive errors, 3 trial(s) not played" in late.line()
    assert flaky.first.startswith("controller brokenpkg.flaky:make, band soft, seed 0, trial 1: act raised "
                                  "ValueError at tick 0")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["controller_errors"]["brokenpkg.late:make"]["not_played"] == 3
    # resumed, it plays nothing: the failures are finished trials, and late stays stopped
    again = run_arena(dataclasses.replace(cfg, resume=True))
    assert again.played == 0 and TrialRecord.read_csv(out / "trials.csv") == records
    assert again.controller_errors == result.controller_errors
    # through the command line: status 1 and one line per failing controller
    assert main(["compare", *cfg.controllers, "--scenario", str(scenario), "--trials", "5", "--workers", "1",
                 "--max-consecutive-errors", "2", "--out", str(out), "--resume", "--quiet"]) == 1
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("wbc: controller ")]
    assert lines == [f"wbc: {late.line()}", f"wbc: {flaky.line()}"]


def _record(controller, trial, failed):
    return SimpleNamespace(controller=controller, run_key=(controller, "soft", 0, trial),
                           outcome="controller_error" if failed else "success",
                           error=f"trial {trial} raised" if failed else "")


def test_errors_in_a_row_are_counted_in_the_runs_order_of_trials_not_the_order_they_finish():
    order = [("soft", 0, i) for i in range(6)]
    # trials 0, 2 and 3 fail and finish first; trial 1 succeeds last: never three in a row
    guard = ErrorGuard(["c"], 3, order)
    for trial, failed in ((0, True), (2, True), (3, True)):
        guard.observe(_record("c", trial, failed))
    assert not guard.stopped("c")  # trial 1 is still under way
    guard.observe(_record("c", 1, False))
    assert not guard.stopped("c")
    # trials 1, 2 and 0 fail, finishing in that order, with trial 3 under way: stopped at trial 2 once 0 is in
    guard = ErrorGuard(["c"], 3, order)
    guard.observe(_record("c", 1, True))
    guard.observe(_record("c", 2, True))
    assert not guard.stopped("c")
    guard.observe(_record("c", 0, True))
    assert guard.stopped("c")
    late = _record("c", 3, False)  # under way when it stopped: stored, and not counted, whatever its outcome
    guard.observe(late)
    assert not guard.counted(late) and guard.counted(_record("c", 2, True))
    (errors,) = guard.report([_record("c", i, True) for i in (1, 2, 0)] + [late], budget=6)
    assert (errors.errored, errors.recorded, errors.not_played, errors.beyond) == (3, 3, 3, 1)
    assert errors.first == "trial 0 raised"  # the first in the run's order, though trial 1's finished first
    assert "3 trial(s) not played (1 of them under way then: played, stored in trials.csv and not counted)" in \
        errors.line()


def test_a_controller_stopped_for_its_errors_is_counted_alike_on_one_worker_and_two(broken, scenario, tmp_path):
    summaries, counted = [], []
    for workers in (1, 2):
        cfg = ArenaConfig(controllers=("brokenpkg.late:make", "stand"), scenario=scenario, seeds=(0,), trials=5,
                          out_dir=tmp_path / f"w{workers}", workers=workers, progress=False, max_consecutive_errors=2)
        result = run_arena(cfg)
        (late,) = result.controller_errors
        assert (late.errored, late.recorded, late.stopped, late.not_played) == (2, 2, True, 3)
        counted.append([r.trial for r in result.records if r.controller == "brokenpkg.late:make"])
        summaries.append(untimed_summary(cfg.out_dir / "summary.json"))
    assert counted == [[0, 1], [0, 1]] and summaries[0] == summaries[1]


def test_errors_are_recorded_alike_on_the_local_pool_and_on_ray(broken, scenario, stand_alone, tmp_path):
    pytest.importorskip("ray")
    names = ("brokenpkg.late:make", "brokenpkg.nan:make", "brokenpkg.short:make", "stand")
    results = {}
    for executor, workers in (("local", 2), ("ray", None)):
        cfg = ArenaConfig(controllers=names, scenario=scenario, seeds=(0,), trials=2, out_dir=tmp_path / executor,
                          executor=executor, workers=workers, progress=False, max_consecutive_errors=0)
        result = run_arena(cfg)
        assert [(e.controller, e.errored, e.stopped) for e in result.controller_errors] == [
            ("brokenpkg.late:make", 2, False), ("brokenpkg.nan:make", 2, False), ("brokenpkg.short:make", 2, False)]
        results[executor] = TrialRecord.read_csv(tmp_path / executor / "trials.csv")
    for name in names:
        assert _metrics(results["local"], name) == _metrics(results["ray"], name)
    assert _metrics(results["ray"], "stand") == _metrics(stand_alone, "stand")
    assert all(re.search(r"brokenpkg.late:make, band soft, seed \d, trial \d: act raised RuntimeError", r.error)
               for r in results["ray"] if r.controller == "brokenpkg.late:make")


def test_slow_and_saturating_plugins_are_counted_not_failed_on_the_local_pool_and_on_ray(broken, scenario,
                                                                                          stand_alone, tmp_path):
    pytest.importorskip("ray")
    names = ("brokenpkg.slow:make", "brokenpkg.saturating:make", "stand")
    results = {}
    for executor, workers in (("local", 2), ("ray", None)):
        cfg = ArenaConfig(controllers=names, scenario=scenario, seeds=(0,), trials=2, out_dir=tmp_path / executor,
                          executor=executor, workers=workers, progress=False)
        result = run_arena(cfg)
        assert result.controller_errors == ()  # late and saturated commands are reported, not failures
        kinds = {(w.controller, w.kind) for w in result.summary.warnings}
        expected = {("brokenpkg.slow:make", "deadline_misses"), ("brokenpkg.saturating:make", "clamped_ticks")}
        assert expected <= kinds
        # a busy machine may make any controller late now and then (a wall-clock figure): only lateness may add to
        # what the two plug-ins cause on their own
        assert all(kind == "deadline_misses" for _, kind in kinds - expected), kinds
        results[executor] = TrialRecord.read_csv(tmp_path / executor / "trials.csv")
        by = {c: [r for r in results[executor] if r.controller == c] for c in names}
        assert all(r.deadline_misses == r.ticks > 0 and r.outcome != "controller_error" for r in by[names[0]])
        assert all(r.clamped_ticks == r.ticks > 0 and r.clamped_rows == f"tau={r.ticks}" for r in by[names[1]])
    for name in names:
        assert _metrics(results["local"], name) == _metrics(results["ray"], name)
    assert _metrics(results["ray"], "stand") == _metrics(stand_alone, "stand")


def test_a_controller_that_falls_in_every_trial_fails_no_command(broken, scenario, tmp_path, capsys):
    # a fall is a result, counted in the table: only a controller's error makes run and compare exit 1
    name = "brokenpkg.limp:make"
    for command in (["run", name], ["compare", name, "stand"]):
        out = tmp_path / command[0]
        assert main([*command, "--scenario", str(scenario), "--trials", "2", "--workers", "1", "--out", str(out),
                     "--quiet"]) == 0
        mine = [r for r in TrialRecord.read_csv(out / "trials.csv") if r.controller == name]
        assert [r.outcome for r in mine] == ["fall", "fall"] and not any(r.error for r in mine)
        assert "wbc: controller " not in capsys.readouterr().err


def _episode(fell, reasons=()):
    """A 10-tick episode of 1 s, fallen (at 0.2 s) or not, its safety layer tripped for each of `reasons`."""
    k = 10
    trips = [SimpleNamespace(time=0.1 * i, from_state="run", to_state="damped", reason=r, detail="")
             for i, r in enumerate(reasons)]
    return Episode(duration_s=1.0, control_dt=0.02, fell=fell, fall_time_s=0.2 if fell else math.nan,
                   t=np.arange(1, k + 1) * 0.02, command=np.zeros((k, 3)), v_base_in_yaw=np.zeros((k, 2)),
                   yaw_rate=np.zeros(k), roll=np.zeros(k), pitch=np.zeros(k), power=np.ones(k),
                   arm_q=np.zeros((k, 3)), qpos=np.zeros((k, 22)), act_s=np.full(k, 1e-3),
                   safety_events=SafetyLog.of(trips))


@pytest.mark.parametrize(("fell", "reasons", "outcome"), [
    (False, (), "success"),
    (True, (), "fall"),  # the simulator's fall rule
    (True, ("tilt",), "safety_trip"),  # a robot's safety layer, on a check of its own
    (True, ("over_power", "software_estop"), "safety_trip"),  # the first trip ended the episode
    (True, ("software_estop",), "operator_stop"),  # the console's e-stop key
    (True, ("remote_estop",), "operator_stop"),  # the remote's
])
def test_a_trials_outcome_tells_falls_trips_and_operator_stops_apart(scenario, fell, reasons, outcome):
    trial = load_scenario(scenario).trial("soft", 0, 0)
    record = TrialRecord.of_trial(trial, controller="x", episode=_episode(fell, reasons), counters={}, wall_s=0.0)
    assert record.outcome == outcome and record.success == (outcome == "success") and record.error == ""
    # a controller error is its own outcome: not a success, not a fall, played up to the error
    failed = TrialRecord.of_trial(trial, controller="x", episode=_episode(False), counters={}, wall_s=0.0,
                                  error="controller x, band soft, seed 0, trial 0: act raised ValueError")
    assert (failed.outcome, failed.success, failed.ttf) == ("controller_error", False, 0.2)
    assert math.isnan(failed.fall_time_s) and failed.error.endswith("ValueError")


def test_a_run_with_a_broken_controller_killed_mid_run_resumes_losing_nothing(broken, scenario, tmp_path):
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "wbc.cli", "compare", "brokenpkg.late:make", "stand", "--scenario", str(scenario),
           "--trials", "6", "--workers", "1", "--out", str(out), "--quiet"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(broken), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=env)
    trials_csv = out / "trials.csv"
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if trials_csv.exists() and trials_csv.read_text().count("\n") >= 4:  # header + 3 trials
            break
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    before = TrialRecord.read_csv(trials_csv)
    assert 3 <= len(before) < 6 + 3
    cfg = ArenaConfig(controllers=("brokenpkg.late:make", "stand"), scenario=scenario, trials=6, out_dir=out,
                      workers=1, resume=True, progress=False)
    result = run_arena(cfg)
    after = TrialRecord.read_csv(trials_csv)
    assert after[: len(before)] == before  # every finished trial kept as it was, its error included
    assert result.played == len(after) - len(before)  # none played again
    keys = [r.run_key for r in after]
    assert len(keys) == len(set(keys))
    # stand played all six; late, failing every trial, was stopped after three in a row, across the kill
    assert sorted(r.trial for r in after if r.controller == "stand") == list(range(6))
    late = [r for r in after if r.controller == "brokenpkg.late:make"]
    assert [r.trial for r in late] == [0, 1, 2] and all(r.outcome == "controller_error" for r in late)
    (errors,) = result.controller_errors
    assert (errors.errored, errors.stopped, errors.not_played) == (3, True, 3)


def test_a_rate_that_is_not_whole_physics_steps_is_refused_naming_the_nearest_that_are(plugin_package, scenario,
                                                                                        tmp_path, capsys):
    source = STAND_PLUGIN.format(doc="runs at 60 Hz", reset="pass", act="pass", counters="return {}")
    plugin_package("ratepkg", {"sixty": source.replace("self.rate_hz = self.inner.rate_hz", "self.rate_hz = 60.0")})
    assert main(["run", "ratepkg.sixty:make", "--scenario", str(scenario), "--trials", "1", "--out",
                 str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert ("controller 'ratepkg.sixty:make': period 1/60 s is not a multiple of the physics step 0.002 s; give the "
            "controller a rate that divides 500 Hz: the nearest are 62.5 Hz and 55.5556 Hz") in err
    assert "Traceback" not in err and not (tmp_path / "o" / "trials.csv").exists()


def test_a_factory_that_fails_while_the_trials_play_costs_its_trials(tmp_path, scenario, monkeypatch):
    # builds once (the arena's check before any trial), then raises: a factory that depends on something that went
    # away (a file, a device) fails where the trials are played, and those trials are recorded, not the run lost
    pkg = tmp_path / "fragile"
    pkg.mkdir()
    (pkg / "fragilepkg.py").write_text(textwrap.dedent('''
        """Builds once."""
        from wbc.control.stand import StandController

        BUILT = []


        def make(desc):
            if BUILT:
                raise FileNotFoundError("calibration.yaml went away")  # MARK
            BUILT.append(desc)
            return StandController(desc)
    ''').lstrip(), encoding="utf-8")
    monkeypatch.syspath_prepend(str(pkg))
    try:
        result = run_arena(ArenaConfig(controllers=("fragilepkg:make", "stand"), scenario=scenario, seeds=(0,),
                                       trials=2, out_dir=tmp_path / "o", workers=1, progress=False))
    finally:
        sys.modules.pop("fragilepkg", None)
    mine = [r for r in result.records if r.controller == "fragilepkg:make"]
    assert [r.outcome for r in mine] == ["controller_error"] * 2
    source = pkg / "fragilepkg.py"
    (line,) = [i for i, text in enumerate(source.read_text().splitlines(), start=1) if "# MARK" in text]
    for r in mine:
        assert r.error.startswith(f"controller fragilepkg:make, band soft, seed 0, trial {r.trial}: building it "
                                  "raised PluginFactoryError before the first tick: plug-in fragilepkg:make raised ")
        assert r.error.endswith(f"FileNotFoundError: calibration.yaml went away at {source}:{line}")
        assert r.ticks == 0 and r.ttf == 0.0
    assert len([r for r in result.records if r.controller == "stand"]) == 2
    assert [e.controller for e in result.controller_errors] == ["fragilepkg:make"]


def test_until_significant_with_a_controller_stopped_for_its_errors(broken, scenario, tmp_path):
    # late fails every trial and is stopped after two: those two rounds are whole and fed to the sequential test (two
    # discordant pairs settle nothing); the later rounds stay incomplete, so the test is fed no more, stand plays the
    # whole budget, and the run ends and says so
    cfg = ArenaConfig(controllers=("brokenpkg.late:make", "stand"), scenario=scenario, seeds=(0,), trials=4,
                      out_dir=tmp_path / "o", workers=1, progress=False, until_significant=True,
                      max_consecutive_errors=2)
    result = run_arena(cfg)
    by = {c: [r for r in result.records if r.controller == c] for c in cfg.controllers}
    assert [r.trial for r in by["brokenpkg.late:make"]] == [0, 1]
    assert [r.trial for r in by["stand"]] == [0, 1, 2, 3]
    (errors,) = result.controller_errors
    assert errors.stopped and errors.not_played == 2
    assert result.summary.sequential["rounds"] == 2 and not result.summary.sequential["settled"]
    table = format_table(result.summary)
    assert "NOT every difference settled after 2 rounds" in table and "STOPPED after 2 consecutive errors" in table


WEIRD = STAND_PLUGIN.format(
    doc="A stand controller whose act raises at its third tick with control characters and a long message.",
    reset="pass", counters="return {}",
    act=('if self.ticks == 3:\n'
         '                raise RuntimeError(\'line1, "q"\\nline2\\r\\n\\x00 \\x1b[31m naive \\u2713 \' + "x" * 5000)'))


def test_a_controllers_error_text_is_stored_escaped_and_printed_short(plugin_package, tmp_path, capsys) -> None:
    """A controller's exception text went into trials.csv raw (NUL bytes in a text file) and was printed whole on one
    line of stderr (5,000 characters, a NUL and a terminal escape in it). Its control characters are escaped in both;
    the printed line is cut and says where the whole text is, and trials.csv keeps it all, its rows trusted."""
    plugin_package("weirdplug", {"weird": WEIRD})
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    out = tmp_path / "out"
    assert main(["run", "weirdplug.weird:make", "--scenario", str(scenario), "--trials", "1", "--workers", "1",
                 "--quiet", "--out", str(out)]) == 1
    (line,) = [ln for ln in capsys.readouterr().err.splitlines() if "failed with a controller error" in ln]
    assert len(line) < 1500 and "\x00" not in line and "\x1b" not in line
    assert "\\x00 \\x1b[31m naive \u2713 " in line and "characters left out: the whole error is in trials.csv" in line
    assert re.search(r"weird\.py:[0-9]+\]$", line)  # the controller's own file:line, at the error's end, is kept
    data = (out / "trials.csv").read_bytes()
    assert b"\x00" not in data and b"\x1b" not in data
    (record,) = TrialRecord.read_csv(out / "trials.csv")  # every row's checksum holds
    assert record.outcome == "controller_error"
    assert 'line1, "q" / line2 / \\x00 \\x1b[31m naive \u2713 ' + "x" * 5000 in record.error


def test_a_trials_csv_written_before_with_raw_control_characters_still_loads(tmp_path) -> None:
    """Rows stored before errors were escaped hold them raw: they load as they were written, checksums and all."""
    import csv

    old = _a_record(error="controller c, band b, seed 0, trial 0: act raised RuntimeError: a\x00b\x1bc \u2713")
    path = tmp_path / "trials.csv"
    with path.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(TrialRecord.header())
        writer.writerow(old.to_row())
    assert b"\x00" in path.read_bytes()
    assert TrialRecord.read_csv(path) == [old]
    assert TrialRecord.read_csv(path)[0].error == old.error


def _a_record(**changes) -> TrialRecord:
    """A record of a controller error, its fields those of a real row read back."""
    from wbc.arena.trial_record import FIELDS

    kinds = {f.name: f.type for f in dataclasses.fields(TrialRecord)}
    values = {}
    for name in FIELDS:
        kind = kinds[name]
        values[name] = {"str": "", "int": 0, "float": 0.0, "bool": False}.get(kind if isinstance(kind, str) else
                                                                            kind.__name__, "")
    values.update(controller="c", scenario="s", scenario_hash="0" * 64, band="b", outcome="controller_error", ttf=0.5)
    values.update(changes)
    return TrialRecord(**values)
