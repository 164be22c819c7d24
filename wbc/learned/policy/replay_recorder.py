"""`record_replay`: a short rollout of an exported policy, written as a replay file beside its weights.

The policy (`LearnedController`, the numpy inference the arena runs) walks on flat ground in MuJoCo under a command
that ramps up forward, sideways and in yaw, and takes one sideways push, so that every observation term moves
(angular velocity, gravity direction, each command entry, joint positions and velocities, the previous action); each
tick's robot state, command, observation frame and action are recorded (`wbc.learned.policy.replay_file` for the
format). ``wbc train`` calls it when a run ends and the ONNX export when it writes a model, so the weights travel with
the pairs that say what their observation means; ``wbc check-controller NAME --replay FILE`` replays them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wbc.errors import ConfigError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.learned.policy.composite_policy import load_composite
from wbc.learned.policy.controller import LearnedController
from wbc.learned.policy.replay_file import Replay, replay_path_for, save_replay
from wbc.robots.registry import get_robot
from wbc.scenario.push import Push
from wbc.scenario.trial import CommandSchedule

__all__ = ["DEFAULT_COMMAND", "default_pushes", "record_replay"]

DEFAULT_COMMAND = CommandSchedule(vx=0.3, vy=0.1, yaw_rate=0.2, ramp_s=0.5)
"""The recording's command: every entry non-zero and different, so a command entry out of place is seen."""


def default_pushes() -> tuple[Push, ...]:
    """The recording's push: 150 N to the robot's left for 0.05 s at 1 s, so the trunk rotates and the legs react."""
    return (Push.horizontal(150.0, math.pi / 2, (0.05, 0.0, 0.0), start=1.0, duration=0.05),)


def record_replay(policy: str | Path, out: str | Path | None = None, *, seconds: float = 2.0, seed: int = 0,
                  command: CommandSchedule | None = None, pushes: Sequence[Push] | None = None) -> Path:
    """Roll the policy out in simulation and write its replay file.

    Args:
        policy: the exported policy (``.npz``, ``.json`` or their stem; single or composite).
        out: the replay file (default: beside the policy, ``<stem>.replay.npz``, `replay_path_for`).
        seconds: rollout length [s]; the recording stops earlier if the robot falls.
        seed: the simulator's seed.
        command: the velocity command over the rollout (default: `DEFAULT_COMMAND`).
        pushes: pushes during the rollout (default: `default_pushes`).

    Returns:
        The replay file's path.

    Raises:
        PolicyFileError: the policy file is missing or malformed.
        ConfigError: `seconds` is not positive.
    """
    if not seconds > 0:
        raise ConfigError(f"record_replay: seconds must be > 0, got {seconds}")
    meta = load_composite(policy).meta
    desc = get_robot(meta["robot"], meta["arm_mode"])
    schedule = command if command is not None else DEFAULT_COMMAND
    robot = MujocoRobot(MujocoRobotConfig(robot=desc.name, arm_mode=desc.arm_mode))
    ctrl = LearnedController(desc, policy_path=policy)
    period = 1.0 / ctrl.rate_hz
    rows: dict[str, list] = {k: [] for k in ("tick", "time", "q", "dq", "tau_est", "imu_quat", "gyro_in_body",
                                            "accel_in_body", "foot_force", "command", "obs", "actions")}
    layout: tuple[tuple[str, int, int], ...] = ()
    with robot:
        robot.reset(seed=seed)
        for push in pushes if pushes is not None else default_pushes():
            robot.apply_push(push)
        ctrl.reset()
        for k in range(int(round(seconds / period))):
            state, cmd = robot.read(), schedule.at(k * period)
            terms = ctrl.observation_terms(state, cmd)
            out_cmd = ctrl.act(state, cmd)
            if not layout:
                at, spans = 0, []
                for name, values in terms:
                    spans.append((name, at, at + values.size))
                    at += values.size
                layout = tuple(spans)
            for key in ("tick", "time", "q", "dq", "tau_est", "imu_quat", "gyro_in_body", "accel_in_body",
                        "foot_force"):
                rows[key].append(np.copy(getattr(state, key)))
            rows["command"].append(cmd.as_array())
            rows["obs"].append(np.concatenate([v for _, v in terms]))
            rows["actions"].append(ctrl.last_action.copy())
            robot.write(out_cmd)
            robot.advance(period)
            if robot.fallen():
                break
    n = len(desc.joint_names)
    replay = Replay(
        path="", robot=desc.name, arm_mode=desc.arm_mode, rate_hz=ctrl.rate_hz, source=str(ctrl.path),
        states={k: np.asarray(rows[k]) for k in ("tick", "time", "q", "dq", "tau_est", "imu_quat", "gyro_in_body",
                                                 "accel_in_body", "foot_force")},
        command=np.asarray(rows["command"]), obs=np.asarray(rows["obs"]),
        obs_terms=tuple(name for name, _, _ in layout), obs_slices=tuple((a, b) for _, a, b in layout),
        actions=np.asarray(rows["actions"]), action_joints=desc.joint_names,
        default_q=np.asarray(ctrl.default_q, dtype=np.float64),
        action_scale=np.full(n, ctrl.action_scale, dtype=np.float64))
    return save_replay(out if out is not None else replay_path_for(policy), replay)
