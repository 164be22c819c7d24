"""Configuration of the batched training environment: robot, motor law, observations, rewards, randomisation.

Defaults follow legged_gym's A1 setup (``legged_gym/envs/a1/a1_config.py``) where the paper is silent: PD targets
``q* = q_default + action_scale * a`` with Kp 20, Kd 0.5 on the legs, policy at 50 Hz, reward scales multiplied by
the policy period, negative totals clipped to zero. Training steps the physics at legged_gym's 5 ms (`decimation` 4
per 20 ms policy step), not the evaluation's 2 ms: 2.5x fewer physics steps, about twice the control steps per
second. The policy only sees 50 Hz observations, and the arena evaluates it at 2 ms, so the transfer across the two
steps is part of every reported result. The runs and measurements behind these settings are in
``docs/learning-notes.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from wbc.errors import ConfigError
from wbc.learned.policy.observations import ObsScales
from wbc.robots.description import check_arm_mode, joint_gains

__all__ = ["DomainRandomisation", "EnvConfig", "ObsNoise", "RewardScales", "SOLVERS"]

SOLVERS = ("newton", "cg")
"""MuJoCo constraint solvers the training env can use (`EnvConfig.solver`)."""


@dataclass(frozen=True, kw_only=True)
class RewardScales:
    """Weights of the named reward terms; each key `k` is computed by ``Rewards._reward_k``.

    Every weight is multiplied by the policy period (0.02 s) so that returns do not depend on the control rate.
    A zero weight switches the term off (it is not even computed).

    `termination` (legged_gym's A1: 0) is -100, i.e. -2 per fall, added after the positive clipping: without it,
    under discounting, a fall costs only the lost future of a reward clipped at zero, and policies traded falls for
    speed.

    `base_height` (legged_gym's term, off there and here by default) penalises (h - `EnvConfig.base_height_target`)^2,
    h the trunk's height above the ground; no task uses it.
    """

    tracking_lin_vel: float = 1.0
    tracking_ang_vel: float = 0.5
    lin_vel_z: float = -2.0
    ang_vel_xy: float = -0.05
    orientation: float = -1.0
    torques: float = -2e-4
    dof_acc: float = -2.5e-7
    action_rate: float = -0.01
    work: float = -1e-3
    action_norm: float = -1e-3
    feet_air_time: float = 1.0
    dof_pos_limits: float = -10.0
    arm_deviation: float = 0.0
    base_height: float = 0.0
    termination: float = -100.0

    def active(self) -> dict[str, float]:
        """The non-zero terms, name -> weight."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) != 0.0}


@dataclass(frozen=True, kw_only=True)
class ObsNoise:
    """Uniform noise half-widths added to the policy observation during training (unscaled units)."""

    dof_pos: float = 0.01  # [rad]
    dof_vel: float = 1.5  # [rad/s]
    ang_vel: float = 0.2  # [rad/s]
    gravity: float = 0.05


@dataclass(frozen=True, kw_only=True)
class DomainRandomisation:
    """Physical parameters drawn per model variant; every episode runs on a variant drawn uniformly.

    A pool of `num_variants` compiled models is built once (each with its own masses, friction, motor strength and,
    on rough ground, its own terrain); `mujoco.rollout` steps each environment with its variant's model.

    Attributes:
        num_variants: size of the pool.
        payload_kg: extra trunk mass interval [kg].
        payload_com_m: half-width of the payload's position box around the trunk origin [m].
        friction: sliding friction interval.
        motor_strength: interval of the motor torque multiplier (one value per joint).
    """

    num_variants: int = 32
    payload_kg: tuple[float, float] = (-1.0, 2.0)
    payload_com_m: float = 0.05
    friction: tuple[float, float] = (0.5, 1.25)
    motor_strength: tuple[float, float] = (0.9, 1.1)


@dataclass(frozen=True, kw_only=True)
class EnvConfig:
    """The batched environment.

    Attributes:
        robot: robot registry name.
        arm_mode: ``none``, ``locked`` or ``actuated``.
        scenario: scenario file whose bands `bands` supply commands and pushes.
        bands: the scenario bands to train on, used in turn (push: ``in`` only, the paper trains in distribution).
        pushes: apply the scenario's pushes (stage 1 trains without them).
        terrain: ``scenario`` (the scenario's ground) or ``flat``.
        num_envs: parallel environments.
        seed: seeds the variants, resets, noise and the scenario's trial stream.
        timestep: physics step [s] (legged_gym's 5 ms; the evaluation steps at 2 ms).
        decimation: physics steps per policy step.
        solver: MuJoCo's constraint solver, ``newton`` or ``cg``. Newton, not the arena's CG: on the contact-rich
            states of training (rough ground, random early actions, falls) it needs a few iterations where CG needs
            many, for the same answer within the solver tolerance, and is faster per physics step.
        nthread: threads of `mujoco.rollout`.
        episode_s: episode length [s]; None: the scenario's duration.
        action_scale: joint target offset per unit action [rad].
        clip_actions: actions are clipped to +-clip_actions.
        leg_kp, leg_kd, arm_kp, arm_kd: PD gains of the motor law [N m / rad], [N m s / rad].
        init_joint_noise: uniform half-width of the initial joint offsets [rad].
        tracking_sigma: width of the exponential tracking rewards [(m/s)^2]. 0.1, not legged_gym's 0.25: the push
            task commands 0 or 0.3 m/s, and at 0.25 standing still earns exp(-0.09 / 0.25) = 70 % of the tracking
            reward of a 0.3 m/s command (41 % at 0.1); legged_gym's commands span +-1 m/s.
        feet_air_time_target: air time rewarded above this, penalised below [s]. 0.2 s, not legged_gym's 0.5 s: at
            0.3 m/s an A1 steps with 0.2-0.25 s of air time, and a 0.5 s target charges every touchdown about -0.3,
            which makes stepping cost more than the tracking it earns.
        soft_dof_pos_limit: fraction of the joint range beyond which `dof_pos_limits` penalises.
        base_height_target: trunk height the `base_height` reward term asks for [m].
        only_positive_rewards: clip each step's total reward at zero from below.
        teacher_arm_mode: if set, also emit the ``teacher`` observation of a policy on that arm mode.
        command_ranges: None (commands from the scenario's trials), or ((vx lo, hi), (vy lo, hi), (yaw rate lo, hi))
            [m/s, m/s, rad/s]: each episode's command drawn uniformly from these instead (the scenario still gives
            the ramp and the pushes). Used by stage 1, the walking prior, see `wbc.learned.train.stages`.
        standing_share: with `command_ranges`, the share of episodes commanded to stand (all three zero): a uniform
            draw almost never asks for standing, and a walking prior that never stood walks on when told to stop.
        rewards, obs_scales, noise, domain: sub-configurations.
        train_seed_offset: the scenario's trial seeds used for training start here (evaluations use 0, 1, ...).
        trial_pool: episodes cycle through this many distinct trials of the scenario (drawn once, then cached).
    """

    robot: str = "a1-wx200"
    arm_mode: str = "actuated"
    scenario: str = "scenarios/push.toml"
    bands: tuple[str, ...] = ("in",)
    pushes: bool = True
    terrain: str = "scenario"
    num_envs: int = 1024
    seed: int = 0
    timestep: float = 0.005
    decimation: int = 4
    solver: str = "newton"
    nthread: int = 2
    episode_s: float | None = None
    action_scale: float = 0.25
    clip_actions: float = 10.0
    leg_kp: float = 20.0
    leg_kd: float = 0.5
    arm_kp: float = 10.0
    arm_kd: float = 0.3
    init_joint_noise: float = 0.1
    tracking_sigma: float = 0.1
    feet_air_time_target: float = 0.2
    soft_dof_pos_limit: float = 0.9
    base_height_target: float = 0.28
    only_positive_rewards: bool = True
    teacher_arm_mode: str | None = None
    command_ranges: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] | None = None
    standing_share: float = 0.0
    rewards: RewardScales = field(default_factory=RewardScales)
    obs_scales: ObsScales = field(default_factory=ObsScales)
    noise: ObsNoise = field(default_factory=ObsNoise)
    domain: DomainRandomisation = field(default_factory=DomainRandomisation)
    train_seed_offset: int = 100_000
    trial_pool: int = 4096

    def __post_init__(self) -> None:
        check_arm_mode(self.arm_mode)
        if self.teacher_arm_mode is not None:
            check_arm_mode(self.teacher_arm_mode)
        if self.solver not in SOLVERS:
            raise ConfigError(f"EnvConfig.solver must be one of {', '.join(SOLVERS)}, got {self.solver!r}")
        if self.terrain not in ("scenario", "flat"):
            raise ConfigError(f"EnvConfig.terrain must be 'scenario' or 'flat', got {self.terrain!r}")
        if not self.bands:
            raise ConfigError("EnvConfig.bands must name at least one band of the scenario")
        if min(self.num_envs, self.decimation, self.nthread, self.trial_pool) < 1:
            raise ConfigError("EnvConfig: num_envs, decimation, nthread and trial_pool must be >= 1")
        if not 0 < self.timestep <= 0.01:
            raise ConfigError(f"EnvConfig.timestep must be in (0, 0.01] s, got {self.timestep}")
        if self.command_ranges is not None and (len(self.command_ranges) != 3 or any(
                len(r) != 2 or r[0] > r[1] for r in self.command_ranges)):
            raise ConfigError(f"EnvConfig.command_ranges must be three (lo, hi) pairs with lo <= hi, got "
                              f"{self.command_ranges}")
        if not 0.0 <= self.standing_share <= 1.0:
            raise ConfigError(f"EnvConfig.standing_share must be in [0, 1], got {self.standing_share}")
        if self.domain.num_variants < 1:
            raise ConfigError("EnvConfig.domain.num_variants must be >= 1")

    @property
    def policy_dt(self) -> float:
        """Policy period [s]."""
        return self.timestep * self.decimation

    def gains(self, num_joints: int) -> tuple[np.ndarray, np.ndarray]:
        """(kp, kd) of the motor law for `num_joints` actuated joints: the 12 legs' first, then the arm's."""
        return joint_gains(num_joints, self.leg_kp, self.leg_kd, self.arm_kp, self.arm_kd)
