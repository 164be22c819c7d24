"""`BaseEstimate`: the arena's (and a real robot's) base estimate from proprioception."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from wbc.estimation.base_estimate import BaseEstimate
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig


def _states(robot: str, n: int):
    """`n` states of the robot standing up in the simulator, as its sensors give them."""
    sim = MujocoRobot(MujocoRobotConfig(robot=robot, arm_mode="actuated"))
    with sim:
        sim.reset(seed=0)
        out = []
        for _ in range(n):
            state = sim.read()
            out.append(state)
            sim.write(_hold(sim, state))
            sim.advance(0.02)
    return sim.desc, out


def _hold(sim, state):
    from wbc.types import MotorCommand

    n = len(state.q)
    return MotorCommand(q=np.asarray(sim.desc.nominal_q, dtype=np.float64)[:n], dq=np.zeros(n), kp=np.full(n, 40.0),
                        kd=np.full(n, 1.0), tau=np.zeros(n))


@pytest.mark.parametrize("robot", ["go1-arm", "a1-wx200"])
def test_the_filters_compiled_step_loads_when_it_is_made_and_the_estimate_starts_fresh(robot, monkeypatch,
                                                                                       tmp_path):
    monkeypatch.chdir(tmp_path)
    desc, states = _states(robot, 30)
    warm = BaseEstimate(desc, 0.02)
    assert warm.latest is None
    monkeypatch.setattr(BaseEstimate, "_load_compiled", lambda self: None)
    cold = BaseEstimate(desc, 0.02)
    # the two synthetic updates left nothing behind: the same estimate, to the bit, as an estimate never warmed
    for state in states:
        a, b = warm.update(state), cold.update(state)
        np.testing.assert_array_equal(a.base_position_in_world, b.base_position_in_world)
        np.testing.assert_array_equal(a.base_linvel_in_world, b.base_linvel_in_world)


def test_a_new_process_has_the_filters_step_loaded_once_the_estimate_is_made():
    """Loaded before any robot is connected: a robot's first ticks do not wait for it (it cost 0.25 s at the
    stand-up's second tick, and the link damped the motors for it)."""
    code = ("from wbc.estimation.filter import steady_step; from wbc.estimation.base_estimate import BaseEstimate; "
            "from wbc.robots.registry import get_robot; before = len(steady_step.signatures); "
            "BaseEstimate(get_robot('go1-arm', 'actuated'), 0.02); print(before, len(steady_step.signatures))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.split() == ["0", "1"]
