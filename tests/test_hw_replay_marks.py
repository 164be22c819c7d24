"""A hardware trial's replay: its safety marks at trial time, its own length, its end and its operator's keys."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from wbc.arena.episode import Episode, OperatorLog, SafetyLog
from wbc.arena.hw_trial import HardwareTrialConfig, run_hardware_trial
from wbc.arena.operator import ScriptedKeys
from wbc.arena.results import episode_path
from wbc.viz.errors import ViewerError
from wbc.viz.replay import load_stored_episode
from wbc.viz.signals import TrialSignals

SHORT = """
[scenario]
name = "hwreplay"
version = 2
description = "a long scenario played for a short hardware trial"
robot = "a1-wx200"
duration_s = 20.0

[terrain]
kind = "flat"

[commands]
[[commands.options]]
vx = 0.0

[pushes]
first_s = [5.0, 5.0]
interval_s = [5.0, 5.0]
duration_s = 0.05
offset_m = 0.1

[[bands]]
name = "soft"
push_force_n = [100.0, 120.0]
"""


@pytest.fixture(scope="module")
def estopped(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated hardware trial of 0.3 s whose operator pressed ``p`` then ``e``."""
    root = tmp_path_factory.mktemp("hwreplay")
    scenario = root / "hwreplay.toml"
    scenario.write_text(SHORT)
    out = root / "hw"
    run_hardware_trial(HardwareTrialConfig(controller="stand", scenario=scenario, trial=0, seed=0, seconds=0.3,
                                           robot="go1-arm", arm_mode="none", simulate=True, out_dir=out,
                                           settle_s=0.0),
                       keys=ScriptedKeys([(0.1, "p"), (0.2, "e")]))
    return out


def _marks(out: Path) -> list[tuple[float, str, str]]:
    stored = load_stored_episode(out, 0)
    record = stored.record
    signals = TrialSignals.of_episode(stored.controller, stored.episode, outcome=record.outcome, error=record.error)
    return [(m.t, m.kind, m.label) for m in signals.marks]


def test_the_safety_marks_are_at_trial_time_and_the_file_says_each_clock(estopped: Path) -> None:
    info = json.loads((estopped / "hardware.json").read_text())
    assert info["trial_started_s"] > 0.1  # the stand-up before the trial
    assert set(info["clocks"]) >= {"safety_events", "operator_events", "episode_safety_events"}
    stored = load_stored_episode(estopped, 0)
    damped = [t for t, _, b, _, _ in stored.episode.safety_events.rows() if b == "damped"]
    assert len(damped) == 1 and 0.19 <= damped[0] <= 0.25  # the e-stop pressed at 0.2 s, not 0.2 s + the stand-up
    layer = [e["time"] for e in info["safety_events"] if e["to_state"] == "damped"]
    assert layer[0] - info["trial_started_s"] == pytest.approx(damped[0])


def test_an_old_results_directory_is_moved_to_trial_time(estopped: Path, tmp_path: Path) -> None:
    old = tmp_path / "old"
    shutil.copytree(estopped, old)
    info = json.loads((old / "hardware.json").read_text())
    del info["clocks"]  # as written before the episode's safety times were moved
    (old / "hardware.json").write_text(json.dumps(info))
    stored = load_stored_episode(estopped, 0)
    path = episode_path(old, stored.controller, "soft", 0, 0)
    ep = Episode.load(str(path))
    shifted = ep.safety_events.shifted(info["trial_started_s"])
    dataclasses.replace(ep, safety_events=shifted).save(str(path))
    again = load_stored_episode(old, 0)
    np.testing.assert_allclose(again.episode.safety_events.time, stored.episode.safety_events.time)


def test_the_replay_lasts_the_trial_played_not_the_scenarios(estopped: Path) -> None:
    stored = load_stored_episode(estopped, 0)
    assert stored.trial.duration_s == pytest.approx(0.3)


def test_an_estop_is_marked_as_the_operators_stop_with_the_keys(estopped: Path) -> None:
    marks = _marks(estopped)
    kinds = [k for _, k, _ in marks]
    assert "fall" not in kinds and not any("fell" in label for _, _, label in marks)
    (end,) = [label for _, k, label in marks if k == "end"]
    assert "operator stop" in end
    keys = [(round(t, 1), label) for t, k, label in marks if k == "operator"]
    assert [label for _, label in keys] == ["operator key p: push", "operator key e: estop"]


def test_the_end_mark_says_the_outcome() -> None:
    t = np.linspace(0.002, 1.0, 500)
    base = dict(duration_s=1.0, control_dt=0.002, t=t, command=np.zeros((500, 3)), v_base_in_yaw=np.zeros((500, 2)),
                yaw_rate=np.zeros(500), roll=np.zeros(500), pitch=np.zeros(500), power=np.zeros(500),
                arm_q=np.zeros((500, 3)), qpos=np.tile([0, 0, 0.3, 1, 0, 0, 0] + [0.0] * 12, (500, 1)),
                act_s=np.zeros(500))
    tripped = Episode(**base, fell=True, fall_time_s=0.5, safety_events=SafetyLog(
        time=np.array([0.5]), from_state=np.array(["run"]), to_state=np.array(["damped"]),
        reason=np.array(["tilt"]), detail=np.array([""])), operator_events=OperatorLog())
    fell = Episode(**base, fell=True, fall_time_s=0.5, safety_events=SafetyLog.of([]))
    ok = Episode(**base, fell=False, fall_time_s=float("nan"))

    def ends(ep: Episode, **kw: str) -> list[str]:
        s = TrialSignals("mpc")
        s.mark_episode(ep, **kw)
        return [m.label for m in s.marks if m.kind in ("fall", "end")]

    assert ends(tripped) == ["mpc: safety trip: tilt"]
    assert ends(fell) == ["mpc fell"]
    assert ends(ok) == []
    assert ends(ok, outcome="controller_error", error="act raised\nmore") == ["mpc: controller error: act raised"]


def test_the_errors_name_the_file_the_field_and_the_hardware_remedy(estopped: Path, tmp_path: Path) -> None:
    with pytest.raises(ViewerError, match=r"hardware\.json: a file, not a results directory: --episode takes the "
                                          r"directory it is in"):
        load_stored_episode(estopped / "hardware.json", 0)
    spot = tmp_path / "spot"
    shutil.copytree(estopped, spot)
    config = json.loads((spot / "run.json").read_text())
    config["config"]["robot"] = "spot"
    (spot / "run.json").write_text(json.dumps(config))
    with pytest.raises(ViewerError, match=r"run\.json: field robot: unknown robot 'spot'"):
        load_stored_episode(spot, 0)
    gone = tmp_path / "gone"
    shutil.copytree(estopped, gone)
    shutil.rmtree(gone / "episodes")
    with pytest.raises(ViewerError, match=r"missing; a `wbc hw run` stores its trial's episode there") as caught:
        load_stored_episode(gone, 0)
    assert "--save-episodes" not in str(caught.value)
