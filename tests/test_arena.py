"""The arena: runner, metrics, executors, results store, resume, CLI."""

import csv
import dataclasses
import json
import math
import os
import pickle
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import STAND_PLUGIN, untimed_summary

from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.episode import Episode
from wbc.arena.metrics import compute_metrics
from wbc.arena.runner import run_episode
from wbc.arena.sim_trial import run_trial
from wbc.arena.trial_record import MACHINE_TIMED, TrialRecord
from wbc.cli.main import main
from wbc.control.registry import CONTROLLERS
from wbc.control.stand import StandController
from wbc.errors import ConfigError, EpisodeFileError, MissingCapabilityError, WbcError
from wbc.hardware.capabilities import FallDetector, TruthSource
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.robot import Robot
from wbc.learned.policy import shipped_weights
from wbc.robots.registry import get_robot
from wbc.scenario.push import Push
from wbc.scenario.scenario import load_scenario

SCENARIOS_DIR = Path(__file__).resolve().parent.parent / "scenarios"
SCENARIOS = sorted(SCENARIOS_DIR.glob("*.toml"))
SCENARIOS = [p for p in SCENARIOS if p.name != "published.toml"]

SMALL = """
[scenario]
name = "small"
version = 1
description = "a short push test"
robot = "a1-wx200"
duration_s = 3.0

[terrain]
kind = "fractal"
amplitude_m = 0.03

[domain]
friction = [0.7, 1.0]

[commands]
ramp_s = 0.5
[[commands.options]]
vx = 0.0
[[commands.options]]
vx = 0.3

[pushes]
first_s = [0.8, 1.2]
interval_s = [1.0, 1.5]
duration_s = 0.05
offset_m = 0.12

[[bands]]
name = "soft"
push_force_n = [50.0, 150.0]

[[bands]]
name = "hard"
push_force_n = [600.0, 900.0]
"""


@pytest.fixture
def small(tmp_path):
    path = tmp_path / "small.toml"
    path.write_text(SMALL)
    return path


def _metrics(records):
    """Every field but those timed on the machine's clock, as the stored text, in a stable order."""
    timed = {TrialRecord.header().index(name) for name in MACHINE_TIMED}
    assert TrialRecord.header().index("wall_s") in timed
    return sorted(tuple(c for i, c in enumerate(r.to_row()) if i not in timed) for r in records)


def _run(small, out, **kw):
    cfg = ArenaConfig(controllers=("stand", "stand-noarm"), scenario=small, seeds=(0, 1), trials=3, out_dir=out,
                      progress=False, **kw)
    return run_arena(cfg)


def test_same_seed_same_metrics_across_runs_and_worker_counts(small, tmp_path):
    a = _run(small, tmp_path / "a", workers=1)
    b = _run(small, tmp_path / "b", workers=1)
    c = _run(small, tmp_path / "c", workers=2)
    ra, rb, rc = (TrialRecord.read_csv(r.out_dir / "trials.csv") for r in (a, b, c))
    assert len(ra) == 2 * 2 * 2 * 3
    assert _metrics(ra) == _metrics(rb) == _metrics(rc)
    # the summary too, to the last bit, whatever order the two workers finished their trials in (but for the deadline
    # misses, which the machine's load decides)
    assert len({untimed_summary(r.out_dir / "summary.json") for r in (a, b, c)}) == 1
    # the bands discriminate: the soft pushes are survived more often than the hard ones
    soft = [r.success for r in ra if r.band == "soft"]
    hard = [r.success for r in ra if r.band == "hard"]
    assert sum(soft) > sum(hard)
    summary = json.loads((a.out_dir / "summary.json").read_text())
    assert set(summary["controllers"]) == {"stand", "stand-noarm"}
    assert summary["scenario"]["hash"] == load_scenario(small).hash
    assert (a.out_dir / "report.md").exists() and (a.out_dir / "run.json").exists()
    run = json.loads((a.out_dir / "run.json").read_text())
    assert "packages" in run["environment"] and "git_revision" in run["environment"]


def test_local_and_ray_executors_agree(small, tmp_path):
    pytest.importorskip("ray")
    local = _run(small, tmp_path / "local", workers=2)
    ray = _run(small, tmp_path / "ray", executor="ray")
    local_rows, ray_rows = (TrialRecord.read_csv(r.out_dir / "trials.csv") for r in (local, ray))
    assert _metrics(local_rows) == _metrics(ray_rows)
    assert untimed_summary(local.out_dir / "summary.json") == untimed_summary(ray.out_dir / "summary.json")


def test_sigkilled_sweep_resumes_without_duplicates_or_reruns(small, tmp_path):
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "wbc.cli", "compare", "stand", "stand-noarm", "--scenario", str(small),
           "--trials", "6", "--seeds", "2", "--workers", "1", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    trials_csv = out / "trials.csv"
    deadline = time.time() + 120
    while time.time() < deadline:
        if trials_csv.exists() and trials_csv.read_text().count("\n") >= 5:  # header + 4 trials
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    before = TrialRecord.read_csv(trials_csv)
    assert 4 <= len(before) < 2 * 2 * 2 * 6
    # a torn line, as a kill in the middle of a write would leave
    with trials_csv.open("a") as f:
        f.write("stand,small,abc,soft,0")
    cfg = ArenaConfig(controllers=("stand", "stand-noarm"), scenario=small, seeds=(0, 1), trials=6, out_dir=out,
                      workers=1, resume=True, progress=False)
    result = run_arena(cfg)
    after = TrialRecord.read_csv(trials_csv)
    keys = [r.run_key for r in after]
    assert len(keys) == len(set(keys)) == 2 * 2 * 2 * 6
    assert result.played == len(after) - len(before)  # nothing finished was played again
    # finished rows kept as they were, wall times included
    assert _metrics(after[: len(before)]) == _metrics(before)
    assert [r.wall_s for r in after[: len(before)]] == [r.wall_s for r in before]
    # resuming a finished run plays nothing; resuming with other options is refused
    assert run_arena(cfg).played == 0
    with pytest.raises(Exception, match="different configuration"):
        run_arena(dataclasses.replace(cfg, trials=7))
    with pytest.raises(Exception, match="--resume"):
        run_arena(dataclasses.replace(cfg, resume=False))


def test_fall_is_detected_and_metrics_follow(small):
    sc = load_scenario(small)
    falls = 0
    for i in range(3):
        trial = sc.trial("hard", 0, i)
        record, episode = run_trial(trial, "stand")
        assert record.success == (not episode.fell)
        if episode.fell:
            falls += 1
            assert 0 < record.ttf < 1 and record.fall_time_s == pytest.approx(record.ttf * 3.0)
            assert episode.t[-1] == pytest.approx(episode.fall_time_s)
        # the episode logs, as numbers, exactly the pushes that began before it ended
        met = [p for p in trial.pushes if p.start < episode.survived_s]
        assert len(episode.pushes) == len(met) >= 1
        np.testing.assert_array_equal(episode.pushes.start, [p.start for p in met])
        np.testing.assert_array_equal(episode.pushes.duration, [p.duration for p in met])
        np.testing.assert_array_equal(episode.pushes.force_in_world, [p.force_in_world for p in met])
        np.testing.assert_array_equal(episode.pushes.offset_in_base, [p.offset_in_base for p in met])
    assert falls >= 1
    record, episode = run_trial(sc.trial("soft", 0, 0), "stand")
    assert record.success and record.ttf == 1.0 and math.isnan(record.fall_time_s)
    assert len(episode.t) == 150  # 3 s at 50 Hz


def test_metrics_are_pure_functions_of_the_episode():
    k = 100
    t = np.arange(1, k + 1) * 0.02
    command = np.tile([0.3, 0.0, 0.5], (k, 1))
    ep = Episode(duration_s=4.0, control_dt=0.02, fell=True, fall_time_s=2.0, t=t, command=command,
                 v_base_in_yaw=np.tile([0.2, 0.0], (k, 1)), yaw_rate=np.full(k, 0.25), roll=np.full(k, 0.1),
                 pitch=np.full(k, -0.2), power=np.full(k, 50.0),
                 arm_q=np.outer(np.arange(k), [0.01, 0.0, 0.0]), qpos=np.zeros((k, 22)), act_s=np.full(k, 1e-3))
    m = compute_metrics(ep)
    assert m["success"] is False and m["ttf"] == 0.5
    assert m["vlin_err"] == pytest.approx(0.1) and m["vang_err"] == pytest.approx(0.25)
    assert m["max_roll_deg"] == pytest.approx(np.degrees(0.1)) and m["max_pitch_deg"] == pytest.approx(np.degrees(0.2))
    assert m["energy_j"] == pytest.approx(50.0 * 0.02 * k)
    assert m["arm_travel_rad"] == pytest.approx(0.01 * (k - 1))


class _Blind(Robot):
    """A robot that offers no capability beyond the interface (no truth, no fall detection), as hardware may not."""

    def __init__(self, inner: MujocoRobot) -> None:
        super().__init__()
        self.inner = inner

    joint_names = property(lambda self: self.inner.joint_names)
    limits = property(lambda self: self.inner.limits)

    def _connect(self):
        self.inner.connect()

    def _close(self):
        pass

    def _read(self):
        return self.inner.read()

    def _send(self, cmd):
        self.inner.write(cmd)

    def _advance(self, dt):
        self.inner.advance(dt)


class _ActClock:
    """A clock the test moves: each reading 1 us after the last, and what a controller spends (`spend`) on top."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        self.now += 1e-6
        return self.now

    def spend(self, seconds: float) -> None:
        self.now += seconds


class _SlowEveryTenth:
    """The stand controller, taking 5 ms longer on every tenth tick (of `clock`'s time)."""

    def __init__(self, desc, clock: _ActClock) -> None:
        self.inner = StandController(desc)
        self.rate_hz = self.inner.rate_hz
        self.ticks = 0
        self.clock = clock

    def reset(self):
        self.inner.reset()
        self.ticks = 0

    def act(self, state, command):
        self.ticks += 1
        if self.ticks % 10 == 0:
            self.clock.spend(0.005)
        return self.inner.act(state, command)

    def counters(self):
        return {}


def test_the_loop_runs_on_any_robot_and_times_every_act(small):
    trial = load_scenario(small).trial("soft", 0, 0)
    sim = MujocoRobot(MujocoRobotConfig(terrain=trial.terrain))
    sim.connect()
    blind = _Blind(sim)
    blind.connect()
    assert not isinstance(blind, TruthSource | FallDetector)
    with pytest.raises(MissingCapabilityError, match="TruthSource.*truth="):
        run_episode(blind, StandController(sim.desc), trial.command, 1.0)
    with pytest.raises(MissingCapabilityError, match="FallDetector.*fallen="):
        run_episode(blind, StandController(sim.desc), trial.command, 1.0, truth=sim.base_truth)
    sim.reset(seed=trial.terrain_seed, domain=trial.domain)
    direct = run_episode(sim, StandController(sim.desc), trial.command, 1.0, clock=_ActClock())
    sim.reset(seed=trial.terrain_seed, domain=trial.domain)
    ticks = []
    clock = _ActClock()
    through = run_episode(blind, _SlowEveryTenth(sim.desc, clock), trial.command, 1.0, truth=sim.base_truth,
                          fallen=sim.fallen, observer=lambda t, robot, ctrl, cmd: ticks.append(t), clock=clock)
    # the same loop, the same physics: only where truth and falls come from differ
    np.testing.assert_array_equal(through.qpos, direct.qpos)
    assert len(ticks) == len(through.t) == len(through.act_s) == 50 and not through.fell
    # the runner timed every act call on the clock it was given: the slow ticks show, and count as deadline misses
    # against a 5 ms budget; the others, and every tick of the direct run, took the clock's one step
    slow = np.zeros(50, dtype=bool)
    slow[9::10] = True
    np.testing.assert_allclose(through.act_s[slow], 0.005 + 1e-6, rtol=1e-9)
    np.testing.assert_allclose(through.act_s[~slow], 1e-6, rtol=1e-6)
    np.testing.assert_allclose(direct.act_s, 1e-6, rtol=1e-6)
    assert through.deadline_misses(0.005) == 5 and direct.deadline_misses() == 0


def test_episode_round_trips_through_npz(small, tmp_path):
    _, ep = run_trial(load_scenario(small).trial("soft", 1, 0), "stand")
    assert len(ep.pushes) >= 1
    ep.save(str(tmp_path / "ep.npz"))
    back = Episode.load(str(tmp_path / "ep.npz"))
    for name in ("t", "command", "v_base_in_yaw", "yaw_rate", "roll", "pitch", "power", "arm_q", "qpos", "act_s"):
        assert np.array_equal(getattr(back, name), getattr(ep, name)), name
    for name in ("start", "duration", "force_in_world", "offset_in_base"):
        assert np.array_equal(getattr(back.pushes, name), getattr(ep.pushes, name)), name
    assert (back.fell, back.duration_s, back.control_dt) == (ep.fell, ep.duration_s, ep.control_dt)
    # a file without the push arrays (pushes were text before) is refused, naming the field and the fix
    with np.load(tmp_path / "ep.npz") as z:
        old = {k: z[k] for k in z.files if not k.startswith("push_")}
    np.savez(tmp_path / "old.npz", **old, events=np.array(["1.0|push|force_in_world=[1.0, 0.0, 0.0]"]))
    with pytest.raises(EpisodeFileError, match=r"old\.npz: field push_start missing.*--save-episodes"):
        Episode.load(str(tmp_path / "old.npz"))


@pytest.mark.parametrize("scenario", SCENARIOS, ids=lambda p: p.stem)
@pytest.mark.parametrize("controller", list(CONTROLLERS))
def test_every_controller_holds_up_through_the_first_second_of_every_scenario(scenario, controller, tmp_path):
    sc = load_scenario(scenario)
    weights = shipped_weights(get_robot(sc.robot, CONTROLLERS[controller].arm_mode),
                              "crouched" if controller.endswith("-crouched") else None)
    if controller.startswith("learned") and not weights.exists():
        pytest.skip(f"no shipped weights {weights.name} for {sc.robot} yet")
    trial = dataclasses.replace(sc.trial(sc.bands[-1], 0, 0), duration_s=1.0)
    if not CONTROLLERS[controller].drives(sc.robot):  # a policy trained for one robot only (mpc-distilled)
        with pytest.raises(ConfigError, match=f"controller {controller} drives"):
            run_arena(ArenaConfig(scenario=scenario, controllers=(controller,), trials=1, progress=False,
                                  out_dir=tmp_path / "out"))
        return
    record, episode = run_trial(trial, controller)
    # the record is this trial's, as played
    assert (record.controller, record.scenario, record.scenario_hash) == (controller, sc.name, sc.hash)
    assert (record.band, record.seed, record.trial) == trial.key
    # the pushes of its one second only: those after the end of the shortened trial are not counted
    within = [p for p in trial.pushes if p.start < trial.duration_s]
    assert (record.n_pushes, record.push_force_n) == (
        len(within), max((float(np.linalg.norm(p.force_in_world)) for p in within), default=0.0))
    assert (record.vx_cmd, record.vy_cmd, record.yaw_rate_cmd) == (trial.command.vx, trial.command.vy,
                                                                     trial.command.yaw_rate)
    assert (record.friction, record.payload_kg) == (trial.domain.friction, trial.domain.payload_mass)
    # every shipped controller keeps every scenario's robot up for its first second (no push comes that early)
    assert record.success and record.ttf == 1.0 and math.isnan(record.fall_time_s) and not episode.fell
    assert len(episode.t) == len(episode.act_s) == round(1.0 / episode.control_dt) and np.all(episode.act_s > 0)
    assert all(np.isfinite(record[k]) for k in ("vlin_err", "vang_err", "energy_j", "max_roll_deg"))
    assert record.energy_j > 0 and record.max_roll_deg < 10
    # standing still, the tracking error is the commanded speed itself; a walker follows the command
    speed = float(np.mean(np.linalg.norm(episode.command[:, :2], axis=1)))
    if controller.startswith("stand"):
        assert record.vlin_err == pytest.approx(speed, abs=0.1)
    elif speed > 0.3:
        assert record.vlin_err < 0.5 * speed


def test_stand_rides_out_a_gentle_push_and_falls_under_a_strong_one():
    base = dataclasses.replace(load_scenario(SCENARIOS_DIR / "push.toml").trial("in", 0, 0), duration_s=2.0)
    quiet, quiet_ep = run_trial(dataclasses.replace(base, pushes=()), "stand")
    assert quiet.success and quiet.ttf == 1.0 and math.isnan(quiet.fall_time_s) and len(quiet_ep.pushes) == 0
    sideways = [Push.horizontal(f, math.pi / 2, (0.0, 0.0, 0.0), 0.5, 0.1) for f in (100.0, 1000.0)]
    gentle, gentle_ep = run_trial(dataclasses.replace(base, pushes=sideways[:1]), "stand")
    assert gentle.success and gentle.ttf == 1.0 and gentle.push_force_n == 100.0 and len(gentle_ep.pushes) == 1
    strong, strong_ep = run_trial(dataclasses.replace(base, pushes=sideways[1:]), "stand")
    assert not strong.success and strong_ep.fell and strong.push_force_n == 1000.0
    # it falls after the push, and the episode stops there
    assert 0.6 < strong.fall_time_s < 2.0 and strong.ttf == pytest.approx(strong.fall_time_s / 2.0)
    assert strong_ep.t[-1] == pytest.approx(strong.fall_time_s) and len(strong_ep.t) < len(quiet_ep.t)
    assert strong.max_roll_deg > 45 > quiet.max_roll_deg


def test_a_trial_that_ends_with_the_robot_upside_down_in_the_air_is_a_fall_at_its_end():
    """A push up and off-centre flings the robot over; the trial ends before it lands, nothing but its feet touched
    the ground: success by the contact rule alone (it was so reported, the trunk rolled 175 degrees). Given a second
    more, it lands on its back, a fall by contact."""
    base = dataclasses.replace(load_scenario(SCENARIOS_DIR / "push.toml").trial("in", 0, 0), duration_s=1.3)
    fling = Push(force_in_world=np.array([0.0, 0.0, 1000.0]), offset_in_base=np.array([0.0, 0.3, 0.0]), start=1.0,
                 duration=0.1)
    flung, flung_ep = run_trial(dataclasses.replace(base, pushes=(fling,)), "stand")
    assert not flung.success and flung.outcome == "fall" and flung_ep.fell
    assert flung.fall_time_s == pytest.approx(1.3) and flung_ep.t[-1] == pytest.approx(1.3)
    assert flung.max_roll_deg > 90
    landed, _ = run_trial(dataclasses.replace(base, pushes=(fling,), duration_s=4.0), "stand")
    assert not landed.success and 1.3 < landed.fall_time_s < 4.0
    quiet, _ = run_trial(dataclasses.replace(base, pushes=()), "stand")
    assert quiet.success and math.isnan(quiet.fall_time_s)


def test_cli_reports_broken_scenarios_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(SMALL.replace("duration_s = 0.05", "duration_s = -0.05"))
    assert main(["run", "stand", "--scenario", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "duration_s" in err and "Traceback" not in err
    assert main(["run", "walker", "--scenario", str(bad)]) == 2
    assert "stand" in capsys.readouterr().err


def test_cli_run_prints_the_table_and_writes_the_directory(small, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["compare", "stand", "stand-locked", "--scenario", str(small), "--trials", "2", "--band", "soft",
                 "--out", str(out), "--quiet", "--workers", "1"]) == 0
    text = capsys.readouterr().out
    assert "stand-locked" in text and "95% CI" in text
    # one seed: each cell is the mean and its interval over trials, never a spread of ± 0.00 over one seed
    assert "±" not in text and re.search(r"\d+\.\d\d \[\d+\.\d\d, \d+\.\d\d\]", text)
    # it ends with the most telling trial and the command that shows both controllers' runs of it on one page
    watch = re.search(r"^  .*wbc(?:\.cli)? view (stand|stand-locked) (stand|stand-locked) --scenario (\S+) "
                      r"--band soft --seed 0 --trial [01]( --at [0-9.]+)?$", text, re.MULTILINE)
    assert watch and watch[1] != watch[2] and watch[3] == str(small), text[-600:]
    with (out / "trials.csv").open() as f:
        assert len(list(csv.DictReader(f))) == 4
    assert main(["run", "stand", "--scenario", str(small), "--trials", "1", "--band", "soft", "--json",
                 "--out", str(tmp_path / "j"), "--workers", "1"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["controllers"]["stand"]["bands"]["soft"]["trials"] == 1


def test_controllers_on_different_arms_are_said_to_play_different_robots(small, tmp_path, capsys):
    """Every controller plays the same trials, each on the robot its arm mode builds: a comparison of a controller
    without an arm and one with it was printed and paired as any other, the robots' difference (1.8 kg) said nowhere
    but in run.json. The run says so before it plays and under its verdict, and the report names each one's robot."""
    out = tmp_path / "arms"
    assert main(["compare", "stand-noarm", "stand-locked", "--scenario", str(small), "--trials", "1", "--band",
                 "soft", "--out", str(out), "--quiet", "--workers", "1"]) == 0
    printed = capsys.readouterr()
    said = re.search(r"stand-noarm: a1-wx200 with no arm \((\d+\.\d\d) kg\); stand-locked: a1-wx200 with its arm "
                     r"locked \((\d+\.\d\d) kg\)", printed.err)
    assert said and float(said[1]) < float(said[2]), printed.err  # the arm's mass, carried by one of them only
    assert "wbc: note: the controllers play different robots" in printed.err
    after = " ".join(printed.out[printed.out.index("verdict ("):].split())
    assert "note: the controllers play different robots" in after and "play them in one arm mode" in after
    report = (out / "report.md").read_text()
    assert (f"- **robots**: stand-noarm: a1-wx200 with no arm ({said[1]} kg); stand-locked: a1-wx200 with its arm "
            f"locked ({said[2]} kg) (NOT the same robot for every controller)") in report
    # the verdict in report.md carries the note as the printed one does, and summary.json says it
    verdict = report.split("## Verdict")[1].split("## Results")[0]
    assert "**Note:** the controllers play different robots" in verdict and "play them in one arm mode" in verdict
    summary = json.loads((out / "summary.json").read_text())
    assert summary["same_robot"] is False and summary["robots_note"].startswith("the controllers play different")
    assert summary["robots"] == {"stand-noarm": f"a1-wx200 with no arm ({said[1]} kg)",
                                 "stand-locked": f"a1-wx200 with its arm locked ({said[2]} kg)"}
    assert after.count("note: the controllers play different robots") == 1  # once, under the verdict
    # the same arm mode: one robot, nothing to say
    assert main(["compare", "stand", "mpc", "--scenario", str(small), "--trials", "1", "--band", "soft",
                 "--out", str(tmp_path / "same"), "--quiet", "--workers", "1"]) == 0
    printed = capsys.readouterr()
    assert "different robots" not in printed.out + printed.err
    assert "(NOT the same robot" not in (tmp_path / "same" / "report.md").read_text()
    same = json.loads((tmp_path / "same" / "summary.json").read_text())
    assert same["same_robot"] is True and same["robots_note"] is None


def test_damaged_shipped_weights_are_refused_before_the_run_not_in_each_trial(tmp_path, monkeypatch, capsys):
    """Shipped weights are read in each trial's worker: a weights file changed since its export (its checksum) made
    every trial of `learned` a controller error (0 % success beside mpc's, and a verdict), where a damaged
    ``policy:PATH`` file is refused before the run. A registry controller's weights are checked in the plan too."""
    spec = CONTROLLERS["learned"]
    src = shipped_weights(get_robot("a1-wx200", "actuated"))
    npz = tmp_path / src.name
    npz.with_suffix(".json").write_text(src.with_suffix(".json").read_text())
    with np.load(src) as data:
        arrays = dict(data)
    name = sorted(arrays)[0]
    arrays[name] = arrays[name] + 1e-3  # one array changed by a little, as a bad copy or an edit would
    np.savez(npz, **arrays)
    monkeypatch.setitem(CONTROLLERS, "learned", dataclasses.replace(
        spec, files=tuple(dataclasses.replace(f, path=str(npz if f.role == "weights" else npz.with_suffix(".json")))
                          for f in spec.files if "a1-wx200" in f.path)))
    out = tmp_path / "run"
    assert main(["compare", "mpc", "learned", "--scenario", "scenarios/push.toml", "--trials", "1", "--band", "in",
                 "--out", str(out), "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert str(npz.with_suffix(".json")) in err or str(npz) in err, err
    assert "sha256" in err or "checksum" in err, err
    assert not out.exists()  # refused before the results directory was made: no trial played


def test_no_push_and_debug_truth_are_recorded_with_the_run(small, tmp_path):
    cfg = ArenaConfig(controllers=("mpc",), scenario=small, seeds=(0,), trials=1, bands=("hard",),
                      out_dir=tmp_path / "np", progress=False, workers=1, no_push=True, debug_truth=True)
    result = run_arena(cfg)
    records = TrialRecord.read_csv(result.out_dir / "trials.csv")
    assert len(records) == 1
    # the hard band's pushes topple the robot; without them it survives, and the row says how it was run
    assert records[0].success and records[0].n_pushes == 0 and records[0].debug_truth is True
    run = json.loads((result.out_dir / "run.json").read_text())
    assert run["config"]["no_push"] is True and run["config"]["debug_truth"] is True
    assert "GROUND TRUTH" in (result.out_dir / "report.md").read_text()
    with pytest.raises(WbcError, match="ground-truth debug switch"):
        run_trial(load_scenario(small).trial("soft", 0, 0), "stand", debug_truth=True)


def test_controllers_are_resolved_once_in_the_parent(small, tmp_path, monkeypatch):
    """run_arena resolves each name once (a policy file is read there) and the tasks carry the spec to the workers."""
    import wbc.arena.compare as compare
    import wbc.arena.sim_trial as sim_trial
    from wbc.arena.executors import TrialTask, run_task
    from wbc.control.registry import get_controller
    from wbc.robots.registry import get_robot as robot_named

    name = f"policy:{shipped_weights(robot_named('a1-wx200', 'locked'))}"
    resolved = []

    def counting(n):
        resolved.append(n)
        return get_controller(n)

    def refuse(n):
        raise AssertionError(f"a worker resolved {n!r} again")

    monkeypatch.setattr(compare, "get_controller", counting)
    monkeypatch.setattr(sim_trial, "get_controller", refuse)
    cfg = ArenaConfig(controllers=("stand", name), scenario=small, seeds=(0,), trials=2, out_dir=tmp_path / "r",
                      workers=1, progress=False)
    records = TrialRecord.read_csv(run_arena(cfg).out_dir / "trials.csv")
    assert len(records) == 2 * 2 * 2 and sorted(resolved) == sorted(["stand", name])
    # a task, resolved policy included, pickles for spawned processes and Ray, and plays the same there
    task = TrialTask(trial=load_scenario(small).trial("soft", 0, 1), controller=get_controller(name))
    played = run_task(pickle.loads(pickle.dumps(task)))
    assert _metrics([played]) == _metrics([r for r in records if r.run_key == (name, "soft", 0, 1)])


def test_a_policy_file_enters_the_arena_as_policy_path(small, tmp_path, capsys):
    """``policy:PATH`` runs an exported policy on the same trials: the shipped pi2 file = learned-locked."""
    from wbc.robots.registry import get_robot as robot_named

    weights = shipped_weights(robot_named("a1-wx200", "locked"))
    name = f"policy:{weights}"
    cfg = ArenaConfig(controllers=("learned-locked", name), scenario=small, seeds=(0,), trials=1, bands=("soft",),
                      out_dir=tmp_path / "p", workers=1, progress=False, save_episodes=True)
    records = TrialRecord.read_csv(run_arena(cfg).out_dir / "trials.csv")
    by_name = {r.controller: r for r in records}
    assert set(by_name) == {"learned-locked", name}
    same = [dataclasses.replace(r, controller="") for r in (by_name[name], by_name["learned-locked"])]
    assert _metrics(same[:1]) == _metrics(same[1:])
    assert len(list((tmp_path / "p" / "episodes").glob("*/*.npz"))) == 2  # one folder per controller, path-safe
    # a policy for another robot is refused before any trial, naming both robots
    turn = Path(__file__).resolve().parent.parent / "scenarios" / "turn.toml"
    assert main(["run", name, "--scenario", str(turn), "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert "a1-wx200" in err and "go1-arm" in err and "Traceback" not in err
    # a missing file is named
    missing = tmp_path / "nothing" / "policy"
    assert main(["run", f"policy:{missing}", "--scenario", str(small), "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert "nothing" in err and "not found" in err and "Traceback" not in err


def test_a_policy_file_is_read_once_per_run_not_once_per_trial(small, tmp_path, monkeypatch):
    import wbc.learned.policy.composite_policy as composite
    from wbc.robots.registry import get_robot as robot_named

    reads = []
    original = composite.load_composite

    def counting(path, *a, **kw):
        reads.append(str(path))
        return original(path, *a, **kw)

    monkeypatch.setattr(composite, "load_composite", counting)
    monkeypatch.setattr("wbc.control.registry.load_composite", counting)
    monkeypatch.setattr("wbc.learned.policy.controller.load_composite", counting)
    weights = shipped_weights(robot_named("a1-wx200", "locked"))
    cfg = ArenaConfig(controllers=(f"policy:{weights}",), scenario=small, seeds=(0,), trials=3, bands=("soft",),
                      out_dir=tmp_path / "once", workers=1, progress=False)
    assert run_arena(cfg).played == 3
    assert reads == [str(weights)]


def test_a_controller_that_changes_the_state_it_is_given_does_not_change_what_is_recorded(plugin_package, small):
    # the same hold as stand, which then zeroes the arrays of the state it was handed: the episode log reads the
    # robot's frame before the controller acts, so the metrics are stand's to the bit
    plugin_package("mutpkg", {"zeroes": STAND_PLUGIN.format(
        doc="The stand hold that zeroes the state it is given.", reset="pass",
        act="state.q[:] = 0.0\n            state.dq[:] = 0.0\n            state.tau_est[:] = 0.0",
        counters="return {}")})
    trial = load_scenario(small).trial("hard", 0, 0)
    ours, _ = run_trial(trial, "mutpkg.zeroes:make")
    theirs, _ = run_trial(trial, "stand")
    skip = {TrialRecord.header().index(n) for n in ("controller", *MACHINE_TIMED)}
    assert [c for i, c in enumerate(ours.to_row()) if i not in skip] == [
        c for i, c in enumerate(theirs.to_row()) if i not in skip]
    assert ours.arm_travel_rad > 0.0 and ours.energy_j > 0.0
