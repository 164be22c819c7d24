"""`BatchedEnv`: N robots stepped together in C by `mujoco.rollout`, observations and rewards in vectorised numpy.

One policy step (50 Hz) is one ``rollout`` call of `decimation` physics steps for all N environments on `nthread`
threads, each environment with its own model variant (`ModelPool`) and its own controls: the motor law's
``ctrl = kp q*`` (constant over the step) and, while a push acts, the trunk's row of ``xfrc_applied`` (exact to the
physics step, `PushSchedule`). Everything else (observations, rewards, terminations, resets) is numpy over the batch.

Episodes follow the scenario: each reset draws the next trial of the scenario's band (its command schedule, ramp
included, and its pushes) from a training seed stream disjoint from evaluation seeds. An episode ends when the robot
falls by evaluation's rule (`wbc.hardware.mujoco.fall_rule`: a collision geom other than a foot touches the ground away
from the feet, a calf included; checked at every physics step), or times out at the scenario's duration.

The policy reads the IMU quaternion and gyro from the same sensors `MujocoRobot.read` reports (MuJoCo computes them
inside the step, one physics step before the final state), so training and deployment see identical signals; after
a reset, before any step, they are the free joint's quaternion and (zero) body angular velocity, which is what the
IMU site at the trunk origin with the trunk's axes measures.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import rollout

from wbc.errors import ConfigError
from wbc.hardware.mujoco.fall_rule import near_feet
from wbc.hardware.mujoco.physics import initial_qpos, motor_ctrl, spawn_height
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.env.model_pool import ModelPool
from wbc.learned.env.push_schedule import PushSchedule
from wbc.learned.env.rewards import Rewards, StepData
from wbc.learned.policy.observations import (
    ObsLayout,
    compatible_observation,
    policy_observation,
    privileged_observation,
    projected_gravity,
)
from wbc.robots.conventions import quat_to_matrices
from wbc.robots.joint_table import joint_table
from wbc.robots.registry import get_robot
from wbc.scenario.scenario import load_scenario
from wbc.scenario.terrain import TerrainConfig
from wbc.scenario.trial import Trial

__all__ = ["BatchedEnv", "StepResult"]


@dataclass(frozen=True)
class StepResult:
    """What `BatchedEnv.step` returns.

    Attributes:
        obs: (N, obs_size) float32 policy observations (after resets).
        privileged: (N, 9) float32 privileged observations (after resets).
        teacher: (N, teacher_size) float32 teacher observations, or None.
        reward: (N,) rewards of the step.
        terminated: (N,) episodes ended by a fall.
        time_out: (N,) episodes ended by the time limit.
        log: episode statistics of the environments that finished (name -> mean), possibly empty.
    """

    obs: np.ndarray
    privileged: np.ndarray
    teacher: np.ndarray | None
    reward: np.ndarray
    terminated: np.ndarray
    time_out: np.ndarray
    log: dict[str, float]


class BatchedEnv:
    """The batched training environment.

    Args:
        config: the environment.

    Raises:
        ConfigError: the scenario's robot differs from the config's.
        UnknownNameError: a band is not in the scenario (the message lists the valid ones).
    """

    def __init__(self, config: EnvConfig) -> None:
        self.config = config
        self.desc = get_robot(config.robot, config.arm_mode)
        self.scenario = load_scenario(config.scenario)
        if self.scenario.robot != config.robot:
            raise ConfigError(f"EnvConfig.robot is {config.robot!r} but scenario {config.scenario} is for "
                              f"{self.scenario.robot!r}; train on the scenario's robot")
        first = self.scenario.trial(config.bands[0], 0, 0)
        for band in config.bands[1:]:
            self.scenario.trial(band, 0, 0)  # unknown bands fail here, listing the valid ones
        terrain = first.terrain if config.terrain == "scenario" else TerrainConfig(kind="flat")
        self.rng = np.random.default_rng(np.random.SeedSequence([config.seed, 0x7A17]))
        self.pool = ModelPool(self.desc, terrain, config, self.rng)
        m = self.pool.model
        self.nq, self.nv, self.nu = m.nq, m.nv, m.nu
        self.num_envs = config.num_envs
        self.num_actions = self.desc.num_joints
        self.layout = ObsLayout(self.num_actions)
        self.teacher_layout = (None if config.teacher_arm_mode is None else
                               ObsLayout(get_robot(config.robot, config.teacher_arm_mode).num_joints))
        self.default_q = self.desc.nominal_q
        limits = joint_table(self.desc)
        self.torque_limit = limits.torque_limit
        self.q_lower, self.q_upper = limits.lower, limits.upper
        self.rewards = Rewards(config, limits.lower, limits.upper, self.default_q)
        self.episode_s = config.episode_s if config.episode_s is not None else self.scenario.duration_s
        self.max_episode_steps = int(round(self.episode_s / config.policy_dt))
        self.state_spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self.control_spec = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_XFRC_APPLIED
        self.nstate = mujoco.mj_stateSize(m, self.state_spec)
        self.ncontrol = mujoco.mj_stateSize(m, self.control_spec)
        self._qpos = slice(1, 1 + self.nq)
        self._qvel = slice(1 + self.nq, 1 + self.nq + self.nv)
        self._xfrc_base = slice(self.nu + 6 * self.pool.base_body, self.nu + 6 * self.pool.base_body + 6)
        template = mujoco.MjData(m)
        self._template = np.empty(self.nstate)
        mujoco.mj_getState(m, template, self._template, self.state_spec)
        self._datas = [mujoco.MjData(m) for _ in range(config.nthread)]
        n, dec = self.num_envs, config.decimation
        self.state = np.tile(self._template, (n, 1))
        self._control = np.zeros((n, dec, self.ncontrol))
        self._out = np.empty((n, dec, self.nstate))
        self._sens = np.empty((n, dec, m.nsensordata))
        self._tau = np.empty((n, dec, self.desc.num_joints))
        found = self.pool.fall_found_adr  # every 4th value of one block when the sensors are consecutive: a view
        regular = np.array_equal(found, np.arange(found[0], found[-1] + 1, 4))
        self._found = slice(int(found[0]), int(found[-1]) + 1, 4) if regular else found
        self._need_torques = bool({"work", "torques"} & set(self.rewards.scales))
        self._need_height = "base_height" in self.rewards.scales
        self.variant = np.zeros(n, dtype=np.int64)
        self._models = [m] * n
        self.strength = np.ones((n, self.num_actions))
        self.pushes = PushSchedule(n, config.timestep)
        self._command_target = np.zeros((n, 3))  # each trial's command after its ramp
        self._ramp_s = np.zeros(n)
        self.command = np.zeros((n, 3))
        self.episode_step = np.zeros(n, dtype=np.int64)
        self.episode_length_buf = self.episode_step  # rsl-rl's name, same array
        self.last_action = np.zeros((n, self.num_actions))
        self.imu_quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.gyro = np.zeros((n, 3))
        self._quat_adr = self.pool.sensor_slices["imu_quat"]
        self._gyro_adr = self.pool.sensor_slices["imu_gyro"]
        self.air_time = np.zeros((n, 4))
        self._episode_sums: dict[str, np.ndarray] = {k: np.zeros(n) for k in self.rewards.scales}
        self._trial_index = 0
        self._trials: dict[int, Trial] = {}
        self.total_steps = 0
        self.physics_wall_s = 0.0  # [s] spent in mujoco.rollout, wall clock
        self.physics_cpu_s = 0.0  # [s] CPU time of this process (all threads) during mujoco.rollout
        self.reset()

    # -- public API -------------------------------------------------------------------------------------------------
    def reset(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Reset every environment; returns (obs, privileged, teacher)."""
        self._reset_envs(np.arange(self.num_envs))
        return self._observe()

    def step(self, actions: np.ndarray) -> StepResult:
        """Advance every environment by one policy step.

        Args:
            actions: (N, num_actions) policy outputs; joint targets are ``default_q + action_scale * actions``.
        """
        cfg = self.config
        n, dec = self.num_envs, cfg.decimation
        a = np.clip(np.asarray(actions, dtype=np.float64), -cfg.clip_actions, cfg.clip_actions)
        # the robot interface clamps position targets to the joint range (`clamp_command`); so does training
        target = np.clip(self.default_q + cfg.action_scale * a, self.q_lower, self.q_upper)
        self.command = self._commands_now()
        # the policy's motor command: zero target velocity and feed-forward torque
        self._control[:, :, : self.nu] = motor_ctrl(target, 0.0, 0.0, self.pool.kp, self.pool.kd)[:, None, :]
        dq_before = self.state[:, 1 + self.nq + 6:].copy()  # a copy: the state is overwritten below
        rot0 = quat_to_matrices(self.state[:, 4:8])
        step0 = self.episode_step * dec
        wrench = self.pushes.wrench(step0, dec, rot0, self.pool.base_ipos[self.variant],
                                    self.state[:, 1 + self.nq + 3:1 + self.nq + 6])
        xf = self._control[:, :, self._xfrc_base]
        if wrench is None:
            xf[:] = 0.0
        else:
            xf[:, :, :3], xf[:, :, 3:] = wrench
        self._control[:, :, self._xfrc_base] = xf
        t0, c0 = time.perf_counter(), time.process_time()
        rollout.rollout(self._models, self._datas, self.state, self._control, control_spec=self.control_spec,
                        nstep=dec, state=self._out, sensordata=self._sens, persistent_pool=True, skip_checks=True)
        self.physics_wall_s += time.perf_counter() - t0
        self.physics_cpu_s += time.process_time() - c0
        self.state[:] = self._out[:, -1]
        self.imu_quat[:] = self._sens[:, -1, self._quat_adr]
        self.gyro[:] = self._sens[:, -1, self._gyro_adr]
        self.total_steps += n

        # physics-step quantities: torques of the motor law and mechanical power, averaged over the step
        qs = self._out[:, :, 1 + 7:1 + self.nq]
        dqs = self._out[:, :, 1 + self.nq + 6:]
        power = torque_sq = None
        if self._need_torques:
            k = self.strength[:, None, :]
            tau = np.subtract(target[:, None, :], qs, out=self._tau)
            tau *= self.pool.kp
            tau -= self.pool.kd * dqs
            tau *= k
            lim = k * self.torque_limit
            np.clip(tau, -lim, lim, out=tau)
            power = np.abs(tau * dqs).sum(axis=2).mean(axis=1)
            torque_sq = np.square(tau).sum(axis=2).mean(axis=1)
        fell = self._fallen()
        contact = self._sens[:, -1, self.pool.touch_adr] > 1.0

        qpos, qvel = self.state[:, self._qpos], self.state[:, self._qvel]
        rot = quat_to_matrices(qpos[:, 3:7])
        linvel_body = np.einsum("nji,nj->ni", rot, qvel[:, :3])
        self.air_time += cfg.policy_dt
        first_contact = contact & (self.air_time > cfg.policy_dt)
        air = np.where(first_contact, self.air_time, 0.0)
        self.air_time[contact] = 0.0
        data = StepData(
            base_linvel_in_body=linvel_body, base_angvel_in_body=qvel[:, 3:6],
            gravity_in_body=projected_gravity(qpos[:, 3:7]), command=self.command, q=qpos[:, 7:], dq=qvel[:, 6:],
            dq_before=dq_before, power=power, torque_sq=torque_sq, action=a, last_action=self.last_action,
            first_contact=first_contact, air_time=air, terminated=fell,
            base_height=qpos[:, 2] - self.pool.ground_height[self.variant] if self._need_height else None,
        )
        reward, terms = self.rewards.compute(data)
        for name, value in terms.items():
            self._episode_sums[name] += value
        self.last_action = a
        self.episode_step += 1
        time_out = (self.episode_step >= self.max_episode_steps) & ~fell
        done = fell | time_out
        log: dict[str, float] = {}
        if done.any():
            ids = np.flatnonzero(done)
            for name, sums in self._episode_sums.items():
                log[f"rew/{name}"] = float(sums[ids].mean() / self.episode_s)
                sums[ids] = 0.0
            log["episode/fall_rate"] = float(fell[ids].mean())
            log["episode/length_s"] = float(self.episode_step[ids].mean() * cfg.policy_dt)
            self._reset_envs(ids)
        obs, priv, teacher = self._observe()
        return StepResult(obs=obs, privileged=priv, teacher=teacher, reward=reward, terminated=fell,
                          time_out=time_out, log=log)

    def close(self) -> None:
        """Release the rollout thread pool."""
        rollout.shutdown_persistent_pool()

    # -- internals --------------------------------------------------------------------------------------------------
    def _fallen(self) -> np.ndarray:
        """(N,) robots that met evaluation's fall rule (`fall_rule`) at any physics step of the last step.

        Only the contact slots in use (rare: a fall geom on the ground) are tested against the foot centres, and only
        in the robots that have one, so the cost per step is one reduction over the slots' "found" values.
        """
        pool = self.pool
        fell = np.zeros(self.num_envs, dtype=bool)
        some = np.flatnonzero(self._sens[:, :, self._found].max(axis=(1, 2)) > 0)
        if some.size:
            sens = self._sens[some]
            n, k, s = np.nonzero(sens[:, :, self._found])
            pos = sens[n[:, None], k[:, None], pool.fall_pos_adr[s]]
            feet = sens[n[:, None, None], k[:, None, None], pool.foot_centre_adr[None]]
            fell[some[n[~near_feet(pos, feet)]]] = True
        return fell

    def _commands_now(self) -> np.ndarray:
        """(N, 3) command of every environment at its current episode time (the trial's ramp included)."""
        t = self.episode_step * self.config.policy_dt
        ramp = np.where(self._ramp_s > 0.0, np.minimum(1.0, t / np.maximum(self._ramp_s, 1e-9)), 1.0)
        return ramp[:, None] * self._command_target

    def _trial(self, index: int) -> Trial:
        """Training trial `index` (cached: sampling one costs about a millisecond, and resets are frequent early)."""
        trial = self._trials.get(index)
        if trial is None:
            cfg = self.config
            band = cfg.bands[index % len(cfg.bands)]
            trial = self.scenario.trial(band, cfg.train_seed_offset + cfg.seed, index)
            self._trials[index] = trial
        return trial

    def _reset_envs(self, ids: np.ndarray) -> None:
        cfg = self.config
        variants = self.rng.integers(0, len(self.pool.models), ids.size)
        self.variant[ids] = variants
        for i, v in zip(ids, variants, strict=True):
            self._models[i] = self.pool.models[v]
            trial = self._trial(self._trial_index % cfg.trial_pool)
            self._trial_index += 1
            c = trial.command
            self._command_target[i] = (c.vx, c.vy, c.yaw_rate)
            self._ramp_s[i] = c.ramp_s
            self.pushes.set(int(i), trial.pushes if cfg.pushes else ())
        if cfg.command_ranges is not None:  # the walking prior's commands (stage 1), not the scenario's
            lo, hi = np.asarray(cfg.command_ranges, dtype=np.float64).T
            self._command_target[ids] = self.rng.uniform(lo, hi, (ids.size, 3))
            if cfg.standing_share > 0.0:  # drawn only then: a run without standing commands draws as before
                standing = ids[self.rng.random(ids.size) < cfg.standing_share]
                self._command_target[standing] = 0.0
        self.strength[ids] = np.array([self.pool.variants[v].motor_strength for v in variants])
        noise = self.rng.uniform(-cfg.init_joint_noise, cfg.init_joint_noise, (ids.size, self.num_actions))
        qpos = initial_qpos(self.nq, spawn_height(self.desc.stand_height, self.pool.ground_height[variants]),
                            self.default_q + noise)
        state = np.tile(self._template, (ids.size, 1))
        state[:, self._qpos] = qpos
        self.state[ids] = state
        self.imu_quat[ids] = qpos[:, 3:7]
        self.gyro[ids] = 0.0
        self.episode_step[ids] = 0
        self.last_action[ids] = 0.0
        self.air_time[ids] = 0.0

    def _observe(self) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        cfg = self.config
        n, nj = self.num_envs, self.num_actions
        qpos, qvel = self.state[:, self._qpos], self.state[:, self._qvel]
        command = self._commands_now()
        nz = cfg.noise
        u = self.rng.uniform(-1.0, 1.0, (n, 6 + 2 * nj))
        gyro = self.gyro + nz.ang_vel * u[:, :3]
        q = qpos[:, 7:] + nz.dof_pos * u[:, 6:6 + nj]
        dq = qvel[:, 6:] + nz.dof_vel * u[:, 6 + nj:]
        obs = policy_observation(gyro_in_body=gyro, imu_quat=self.imu_quat, command=command, q=q, dq=dq,
                                 last_action=self.last_action, default_q=self.default_q, scales=cfg.obs_scales)
        obs[:, 3:6] += (nz.gravity * u[:, 3:6]).astype(np.float32)
        rot = quat_to_matrices(qpos[:, 3:7])
        force = self.pushes.force_at(self.episode_step * cfg.decimation)
        priv = privileged_observation(
            payload_kg=self.pool.payload_kg[self.variant], friction=self.pool.friction[self.variant],
            motor_strength=self.pool.strength[self.variant],
            base_linvel_in_body=np.einsum("nji,nj->ni", rot, qvel[:, :3]),
            push_force_in_body=np.einsum("nji,nj->ni", rot, force),
        )
        teacher = None if self.teacher_layout is None else compatible_observation(obs, self.layout,
                                                                                 self.teacher_layout)
        return obs, priv, teacher

