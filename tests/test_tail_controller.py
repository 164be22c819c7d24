"""`mpc-tail`: the MPC that swings its arm as a tail, re-plans when it detects a push, and feeds the arm's planned
torque forward."""

from __future__ import annotations

import re

import numpy as np
import pytest

from wbc.arena.runner import run_episode
from wbc.control.registry import get_controller
from wbc.errors import ConfigError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.mpc.config_table import tail_config_from_table
from wbc.mpc.controller import MpcControllerConfig
from wbc.mpc.tail_controller import OverriddenSettingError, TailControllerConfig, TailMpcController, ready_pose
from wbc.mpc.tail_mpc import TailMpcConfig, TailPlan
from wbc.robots.description import ARM_JOINTS
from wbc.robots.registry import get_robot
from wbc.scenario.push import Push
from wbc.scenario.trial import CommandSchedule

PUSH_START, PUSH_S = 1.5, 0.09


def _pushed(arm_moves: bool, force=(0.0, 350.0, 0.0), seconds=2.3):
    """mpc-tail standing on a1-wx200, pushed sideways at `PUSH_START`: the episode, the controller, and per tick
    (time, the arm's planned accelerations at that tick, push re-plans so far)."""
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    ctrl = TailMpcController(sim.desc, TailControllerConfig(tail=TailMpcConfig(arm_moves=arm_moves)))
    log = []

    def watch(t, robot, c, command):
        plan = c.plan
        acc = plan.arm_acceleration[c._plan_step()].copy() if isinstance(plan, TailPlan) else np.zeros(3)
        log.append((t, acc, c.push_replans))

    with sim:
        sim.reset(seed=0)
        sim.apply_push(Push(force_in_world=np.array(force), offset_in_base=np.zeros(3), start=PUSH_START,
                            duration=PUSH_S))
        episode = run_episode(sim, ctrl, CommandSchedule(), seconds, observer=watch)
    return episode, ctrl, log


def test_mpc_tail_is_registered_with_its_arm_actuated_and_a_ready_pose_from_its_leverage():
    spec = get_controller("mpc-tail")
    assert spec.arm_mode == "actuated"
    # the raised tail of the leverage analysis (tests/test_tail_model.py, on a grid 0.05 rad apart from this one's):
    # shoulder back, elbow up, waist centred
    waist, shoulder, elbow = ready_pose("a1-wx200")
    assert waist == 0.0 and shoulder == pytest.approx(-1.15, abs=0.05) and elbow == pytest.approx(-1.25, abs=0.05)


def test_a_push_is_re_planned_for_at_once_and_the_arm_swings_against_it():
    episode, ctrl, log = _pushed(arm_moves=True)
    assert not episode.fell
    assert ctrl.pushes_detected == 1 and ctrl.push_replans == 1
    # the push's re-plan comes within 20 ms of its start (the MPC's own clock re-plans every 32 ms)
    replanned_at = next(t for t, _, n in log if n == 1)
    assert 0.0 < replanned_at - PUSH_START <= 0.020
    # before the push the plan keeps the arm near its ready pose; from the push on it swings it hard
    quiet = max(np.abs(a).max() for t, a, _ in log if 1.0 < t < PUSH_START)
    swing = max(np.abs(a).max() for t, a, _ in log if PUSH_START < t < PUSH_START + 0.4)
    assert swing > 50.0 and swing > 5 * quiet


def test_the_ablation_that_holds_the_arm_plans_no_arm_motion_under_the_same_push():
    episode, ctrl, log = _pushed(arm_moves=False)
    assert ctrl.pushes_detected == 1 and ctrl.push_replans == 1
    # the arm stays under its PD hold at the ready pose: its accelerations are boxed to zero
    assert max(np.abs(a).max() for _, a, _ in log) < 1e-9
    np.testing.assert_array_equal(ctrl._arm_target, ctrl.ready_q)


def test_the_arms_command_follows_the_plan_with_its_inverse_dynamics_torque_fed_forward():
    sim = MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated"))
    ctrl = TailMpcController(sim.desc)
    with sim:
        sim.reset(seed=0)
        for _ in range(40):  # past a few updates: the arm moves from its stowed pose towards the ready pose
            state = sim.read()
            command = ctrl.act(state, CommandSchedule().at(ctrl.t))
            sim.write(command)
            sim.advance(ctrl.dt)
    plan = ctrl.plan
    assert isinstance(plan, TailPlan)
    k = ctrl._plan_step()
    acc = plan.arm_acceleration[k]
    assert np.abs(acc).max() > 0.1  # the plan is moving the arm
    tail = ctrl._tail_now
    np.testing.assert_allclose(command.tau[ARM_JOINTS], tail.mass_matrix @ acc + tail.bias, rtol=1e-12,
                               atol=1e-12)
    # position and speed on the planned path at the end of this command's period
    into = ctrl.t - ctrl.plan_t - k * ctrl.tail_config.tail.dt
    start = ctrl._x0[12:] if k == 0 else plan.states[k - 1, 12:]
    np.testing.assert_allclose(command.dq[ARM_JOINTS], start[3:] + acc * into, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(command.q[ARM_JOINTS], start[:3] + start[3:] * into + 0.5 * acc * into**2,
                               rtol=1e-12, atol=1e-12)


def test_a_settings_file_runs_the_tail_mpc_with_the_arm_held_and_refuses_a_bad_pose(tmp_path):
    path = tmp_path / "held.toml"
    path.write_text("ready_q = [0.0, -1.1, -1.2]\n[tail]\narm_moves = false\n[observer]\n")
    spec = get_controller("wbc.mpc.config_table:make_tail", config=path)
    ctrl = spec.make(get_robot("a1-wx200", "actuated"))
    assert isinstance(ctrl, TailMpcController)
    assert ctrl.tail_config.tail.arm_moves is False and ctrl.tail_mpc.config.arm_moves is False
    np.testing.assert_array_equal(ctrl.ready_q, [0.0, -1.1, -1.2])
    with pytest.raises(ConfigError, match=r"^ready_q must be 3 finite angles"):
        tail_config_from_table({"ready_q": [0.0, 1.0]})
    with pytest.raises(ConfigError, match=r"^ready_q must be a number or an array of numbers"):
        tail_config_from_table({"ready_q": "up"})
    with pytest.raises(ConfigError, match=r"^\[tail\] arm_move: unknown key; valid keys in \[tail\]: .*"):
        tail_config_from_table({"tail": {"arm_move": False}})


@pytest.mark.parametrize(("table", "named"), [
    ({"base": {"mpc": {"mu": 0.1, "qp_solver": "proxsuite"}}},
     ["base.mpc.mu (use tail.mu)", "base.mpc.qp_solver (the tail MPC solves with DAQP)"]),
    ({"base": {"mpc": {"weight_rpy": [1.0, 1.0, 1.0], "pyramid": "outer"}}},
     ["base.mpc.weight_rpy (use tail.weight_rpy)", "base.mpc.pyramid (use tail.pyramid)"]),
    ({"base": {"arm_kp": 200.0, "arm_kd": 5.0}}, ["base.arm_kp (use arm_kp)", "base.arm_kd (use arm_kd)"]),
    ({"base": {"replan_every": 8, "mpc": {"dt": 0.016}}}, ["base.replan_every (", "use tail.dt", "base.mpc.dt"]),
])
def test_base_settings_the_tail_controller_sets_itself_are_refused_naming_their_tail_equivalent(table, named):
    with pytest.raises(ConfigError, match="sets these base settings itself") as caught:
        tail_config_from_table(table)
    for text in named:
        assert text in str(caught.value)
    with pytest.raises(ConfigError, match=re.escape("base.arm_kp (use arm_kp)")):  # the Python API too
        TailControllerConfig(base=MpcControllerConfig(arm_kp=200.0))
    # settings the tail controller keeps, and the tail's own, are taken
    assert tail_config_from_table({"base": {"velocity_ki": 2.0}, "tail": {"mu": 0.1}}).tail.mu == 0.1


def test_a_base_setting_the_tail_sets_itself_is_refused_once_in_its_own_class():
    # the settings' own refusal, reworded to the file's keys, keeps its class: said once, not again as "besides"
    with pytest.raises(OverriddenSettingError) as caught:
        tail_config_from_table({"base": {"arm_kp": 200.0}})
    assert str(caught.value).count("sets these base settings itself") == 1 and "besides" not in str(caught.value)


def test_a_tail_step_that_is_not_whole_control_ticks_is_refused_with_advice_that_applies():
    with pytest.raises(ConfigError, match="^" + re.escape("[tail] dt must be a whole number of control "
                                                          "ticks")) as caught:
        tail_config_from_table({"tail": {"dt": 0.033}})
    assert "e.g. 0.032" in str(caught.value) and "replan_every" not in str(caught.value)
    assert tail_config_from_table({"tail": {"dt": 0.03}}).tail.dt == 0.03


_COMPILE_PROBE = """
import json
import numpy as np
from wbc.arena import divergence
from wbc.arena.runner import run_episode
from wbc.control.registry import get_controller
from wbc.hardware import robot as robot_module
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.mpc import observer, tail_compiled
from wbc.scenario.push import Push
from wbc.scenario.trial import CommandSchedule

kernels = (robot_module.within_bounds, divergence._joints_possible, observer.stance_force_sum,
           observer._residual_step, tail_compiled.arm_path_rows)
spec = get_controller("mpc-tail")
with MujocoRobot(MujocoRobotConfig(arm_mode=spec.arm_mode)) as sim:
    controller = spec.make(sim.desc)
    loaded = [len(k.signatures) for k in kernels]
    sim.reset(seed=0)
    sim.apply_push(Push(force_in_world=np.array([0.0, 300.0, 0.0]), offset_in_base=np.zeros(3), start=0.4,
                        duration=0.09))
    episode = run_episode(sim, controller, CommandSchedule(vx=0.3), 0.8, divergence=divergence.DivergenceCheck())
print(json.dumps({"fell": bool(episode.fell), "pushes": controller.pushes_detected, "loaded": loaded,
                  "after": [len(k.signatures) for k in kernels]}))
"""


def test_nothing_compiles_during_a_pushed_mpc_tail_episode():
    # the per-tick compiled passes load when the robot connects and the controller is made, never at a tick; a
    # fresh interpreter, so that no earlier test has loaded them
    import json
    import subprocess
    import sys

    out = json.loads(subprocess.run([sys.executable, "-c", _COMPILE_PROBE], capture_output=True, text=True,
                                    check=True).stdout)
    assert not out["fell"] and out["pushes"] == 1  # the observer's path ran
    assert out["after"] == out["loaded"] and min(out["loaded"]) >= 1
