"""Named reward terms of the batched env: ``_reward_<name>`` for each key of `RewardScales`.

Each term maps a `StepData` (one policy step of N environments) to (N,) values; the env sums
``scale * policy_dt * term`` over the active terms and logs every term's episode sum under ``rew/<name>``.
The paper lists velocity and yaw tracking, base orientation, action rate, work and action norm; the others are
legged_gym's A1 terms (``legged_gym/envs/base/legged_robot.py``, scales of ``legged_gym/envs/a1/a1_config.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.errors import ConfigError
from wbc.learned.env.env_config import EnvConfig
from wbc.robots.description import ARM_JOINTS

__all__ = ["Rewards", "StepData"]


@dataclass(frozen=True, kw_only=True)
class StepData:
    """What the reward terms see of one policy step, batched over N environments.

    Attributes:
        base_linvel_in_body: (N, 3) [m/s].
        base_angvel_in_body: (N, 3) [rad/s].
        gravity_in_body: (N, 3) unit gravity direction in the trunk frame.
        command: (N, 3) (vx, vy, yaw rate).
        q: (N, n) joint positions at the end of the step [rad].
        dq: (N, n) joint velocities at the end of the step [rad/s].
        dq_before: (N, n) joint velocities at the start of the step [rad/s].
        power: (N,) mean over the step's physics steps of sum |tau dq| [W] (None when no term needs it).
        torque_sq: (N,) mean over the step of sum tau^2 [N^2 m^2] (None when no term needs it).
        action: (N, n) this step's actions.
        last_action: (N, n) the previous step's actions.
        first_contact: (N, 4) feet touching down this step.
        air_time: (N, 4) air time of the feet touching down this step (zero elsewhere) [s].
        terminated: (N,) the episode ended by a fall this step.
        base_height: (N,) trunk origin above the ground level of the robot's spawn point [m] (the ground itself on
            flat terrain).
    """

    base_linvel_in_body: np.ndarray
    base_angvel_in_body: np.ndarray
    gravity_in_body: np.ndarray
    command: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    dq_before: np.ndarray
    power: np.ndarray | None
    torque_sq: np.ndarray | None
    action: np.ndarray
    last_action: np.ndarray
    first_contact: np.ndarray
    air_time: np.ndarray
    terminated: np.ndarray
    base_height: np.ndarray | None = None


class Rewards:
    """The active reward terms of an `EnvConfig`.

    Args:
        config: env configuration (scales, tracking width, limits).
        lower: (n,) joint lower limits [rad].
        upper: (n,) joint upper limits [rad].
        default_q: (n,) nominal joint positions [rad].

    Raises:
        ConfigError: a scale has no matching ``_reward_*`` method.
    """

    def __init__(self, config: EnvConfig, lower: np.ndarray, upper: np.ndarray, default_q: np.ndarray) -> None:
        self.config = config
        self.dt = config.policy_dt
        self.scales = config.rewards.active()
        for name in self.scales:
            if not hasattr(self, f"_reward_{name}"):
                raise ConfigError(f"reward term {name!r} has no Rewards._reward_{name}")
        mid, half = 0.5 * (lower + upper), 0.5 * (upper - lower) * config.soft_dof_pos_limit
        # legs only: the arm rests folded near its limits and sags past them under gravity
        self.soft_lower, self.soft_upper = (mid - half)[:12], (mid + half)[:12]
        self.default_q = default_q
        self.num_legs_joints = 12

    def compute(self, s: StepData) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Total reward (N,) and each term's weighted contribution (N,)."""
        total = np.zeros(s.q.shape[0])
        terms = {}
        for name, scale in self.scales.items():
            value = getattr(self, f"_reward_{name}")(s) * (scale * self.dt)
            terms[name] = value
            if name != "termination":
                total += value
        if self.config.only_positive_rewards:
            total = np.maximum(total, 0.0)
        # the termination term is added after the clipping (legged_gym's order): clipped, a fall penalty would vanish
        if "termination" in terms:
            total += terms["termination"]
        return total, terms

    # -- terms ------------------------------------------------------------------------------------------------------
    def _reward_tracking_lin_vel(self, s: StepData) -> np.ndarray:
        err = np.sum((s.command[:, :2] - s.base_linvel_in_body[:, :2]) ** 2, axis=1)
        return np.exp(-err / self.config.tracking_sigma)

    def _reward_tracking_ang_vel(self, s: StepData) -> np.ndarray:
        err = (s.command[:, 2] - s.base_angvel_in_body[:, 2]) ** 2
        return np.exp(-err / self.config.tracking_sigma)

    def _reward_lin_vel_z(self, s: StepData) -> np.ndarray:
        return s.base_linvel_in_body[:, 2] ** 2

    def _reward_ang_vel_xy(self, s: StepData) -> np.ndarray:
        return np.sum(s.base_angvel_in_body[:, :2] ** 2, axis=1)

    def _reward_orientation(self, s: StepData) -> np.ndarray:
        return np.sum(s.gravity_in_body[:, :2] ** 2, axis=1)

    def _reward_torques(self, s: StepData) -> np.ndarray:
        return s.torque_sq

    def _reward_dof_acc(self, s: StepData) -> np.ndarray:
        return np.sum(((s.dq - s.dq_before) / self.dt) ** 2, axis=1)

    def _reward_action_rate(self, s: StepData) -> np.ndarray:
        return np.sum((s.action - s.last_action) ** 2, axis=1)

    def _reward_work(self, s: StepData) -> np.ndarray:
        return s.power

    def _reward_action_norm(self, s: StepData) -> np.ndarray:
        return np.sum(s.action ** 2, axis=1)

    def _reward_feet_air_time(self, s: StepData) -> np.ndarray:
        gain = np.sum((s.air_time - self.config.feet_air_time_target) * s.first_contact, axis=1)
        moving = np.linalg.norm(s.command[:, :2], axis=1) > 0.1
        return gain * moving

    def _reward_dof_pos_limits(self, s: StepData) -> np.ndarray:
        below = np.clip(self.soft_lower - s.q[:, :12], 0.0, None)
        above = np.clip(s.q[:, :12] - self.soft_upper, 0.0, None)
        return np.sum(below + above, axis=1)

    def _reward_arm_deviation(self, s: StepData) -> np.ndarray:
        if s.q.shape[1] <= self.num_legs_joints:
            return np.zeros(s.q.shape[0])
        return np.sum((s.q[:, ARM_JOINTS] - self.default_q[ARM_JOINTS]) ** 2, axis=1)

    def _reward_base_height(self, s: StepData) -> np.ndarray:
        return np.square(s.base_height - self.config.base_height_target)

    def _reward_termination(self, s: StepData) -> np.ndarray:
        return s.terminated.astype(np.float64)
