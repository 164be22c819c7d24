"""The benchmark scripts' own parts: what they build and the input they refuse (their figures are printed, not
asserted)."""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from wbc.learned.policy.controller import LearnedController
from wbc.learned.policy.policy_file import load_policy, save_policy
from wbc.robots.registry import get_robot
from wbc.types import RobotState, VelocityCommand

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_policy_call_floor_builds_a_playable_policy_of_the_shipped_form_with_the_networks_asked(tmp_path):
    floor = _script("policy_call_floor")
    assert floor.network("64,32:8:5") == ([64, 32], [8], 5)
    assert floor.network("8::1") == ([8], [], 1)
    for bad in ("8:1", ":1:1", "8:1:0", "8:1:201", "8,0:1:1", "a:1:1", "8:1:1:1"):
        with pytest.raises(argparse.ArgumentTypeError, match="give ACTOR:MEMORY:HISTORY"):
            floor.network(bad)
    source = load_policy(floor.SOURCE)
    save_policy(tmp_path / "p", floor.timing_policy(source, [16, 8], [4], 3, seed=0))
    pf = load_policy(tmp_path / "p")
    assert pf.meta["hidden_dims"] == [16, 8] and pf.meta["adaptation"]["hidden_dims"] == [4]
    assert pf.meta["adaptation"]["history"] == 3
    for key in ("obs_layout", "obs_scales", "kp", "kd", "default_q", "action_scale", "robot", "arm_mode"):
        assert pf.meta[key] == source.meta[key], key
    obs = source.arrays["obs_mean"].size
    assert pf.arrays["adaptation/0/weight"].shape == (4, 3 * obs)
    assert pf.arrays["policy/0/weight"].shape == (16, obs + pf.meta["extrinsics"]["dim"])
    assert pf.arrays["policy/2/weight"].shape == (pf.meta["num_actions"], 8)
    desc = get_robot("a1-wx200", "actuated")
    ctrl = LearnedController(desc, tmp_path / "p")
    n = desc.num_joints
    state = RobotState(tick=0, time=0.0, q=desc.nominal_q.copy(), dq=np.zeros(n), tau_est=np.zeros(n),
                       imu_quat=np.array([1.0, 0, 0, 0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.zeros(4))
    cmd = ctrl.act(state, VelocityCommand())
    # small random weights: the targets stay within a few hundredths of a radian of the policy's default pose
    assert np.all(np.abs(cmd.q - ctrl.default_q) < 0.05)
