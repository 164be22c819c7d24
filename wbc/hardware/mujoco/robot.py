"""`MujocoRobot`: the simulated robot behind the `Robot` interface.

The motor law runs inside MuJoCo's step (see `wbc.robots.mujoco_model`), so `advance` calls ``mj_step`` with
``nstep`` and no Python in between, except while a push acts (its torque about the CoM is refreshed every physics
step as the trunk moves), where a delayed command arrives (the run is split at that step) and over the last steps of
a run whose sensor frames a delayed `read` may still ask for.

Delays (`DomainParams.actuation_delay`, ``sensing_delay``: the config's ``domain``, or those `reset` or `set_domain`
is given), both rounded to whole physics steps (`wbc.hardware.mujoco.physics.delay_steps`; 2 ms at the default
step): a command written at step k reaches the motors at step k + Na and the motor law runs at every step under the
command that last arrived (before the first one arrives, under the one before it: at reset, the zero-gain hold);
`read` at step k returns the sensors as measured at step k - Ns (the frame at reset until Ns steps have passed), its
``time`` the measurement's and its ``tick`` the step it was read at. With both delays zero, nothing of this runs.

Domain parameters, the motor law's actuator parameters, the spawn pose and the pushes' rounding and wrench are those
of `wbc.hardware.mujoco.physics`, which the training env applies too.

What `read` returns is what the real robot's sensors give (joint encoders, motor torque estimate, IMU, foot force
sensors, optionally noisy); simulator truth (base pose and velocity, contacts, applied force) is only reachable
through `sim_truth()`, for metrics.

Within one frame the readings are not all of one instant: ``q`` and ``dq`` are the state after the last physics step,
while ``tau_est``, the IMU (``imu_quat``, ``gyro_in_body``, ``accel_in_body``) and ``foot_force`` are what MuJoCo
computed at the start of that step (its actuator forces and sensors, evaluated before integrating), one physics step
(2 ms at the default step) older than the joints. This holds with or without a sensing delay (the delay shifts the
whole frame). A real IMU has a latency of its own; this one is a property of the simulation, kept because every
published result was computed with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from wbc.errors import ConfigError
from wbc.hardware.mujoco.fall_rule import foot_geoms, near_feet, touches_off_foot
from wbc.hardware.mujoco.latency import CommandQueue, SensorHistory
from wbc.hardware.mujoco.physics import (
    NominalModel,
    PushTable,
    apply_domain,
    apply_motor_rows,
    apply_terrain,
    base_body_id,
    delay_steps,
    foot_touch_adr,
    initial_qpos,
    motor_ctrl,
    push_steps,
    push_wrench,
    sensor_slices,
    set_motor_gains,
    spawn_height,
)
from wbc.hardware.mujoco.scene import TERRAIN_GEOM, build_scene
from wbc.hardware.robot import Robot
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import RobotDescription
from wbc.robots.joint_table import JointTable, joint_table
from wbc.robots.registry import get_robot
from wbc.scenario.domain import DomainParams, SensorNoise
from wbc.scenario.push import Push
from wbc.scenario.terrain import TerrainConfig
from wbc.types import BaseTruth, MotorCommand, RobotState

__all__ = ["MujocoRobotConfig", "MujocoRobot", "SimTruth"]


_NEVER = 2**62  # a physics step no episode reaches


@dataclass(frozen=True, kw_only=True)
class MujocoRobotConfig:
    """Configuration of the simulated robot.

    Attributes:
        robot: registry name (``a1-wx200``, ``go1-arm``).
        arm_mode: ``none``, ``locked`` or ``actuated``.
        arm_mass_scale: scales the arm's mass and inertia (finite, positive).
        terrain: ground shape.
        timestep: physics step [s].
        noise: sensor noise added by `read`.
        domain: the physical parameters (delays included) a `reset` without its own applies; nominal by default.
            A robot built for someone else's loop (an emulator's) is made heavy, slippery or late here.
    """

    robot: str = "a1-wx200"
    arm_mode: str = "actuated"
    arm_mass_scale: float = 1.0
    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    timestep: float = 0.002
    noise: SensorNoise = field(default_factory=SensorNoise)
    domain: DomainParams = field(default_factory=DomainParams)

    def __post_init__(self) -> None:
        if not 0 < self.timestep <= 0.01:
            raise ConfigError(f"MujocoRobotConfig.timestep must be in (0, 0.01] s, got {self.timestep}")
        scale = self.arm_mass_scale
        # here, not at connect, where MuJoCo's compiler would refuse the arm's masses without naming the field
        if isinstance(scale, bool) or not isinstance(scale, int | float) or not math.isfinite(scale) or scale <= 0:
            raise ConfigError(f"MujocoRobotConfig.arm_mass_scale must be a finite positive number, got {scale!r}")

    def description(self) -> RobotDescription:
        """The robot description this config names."""
        return get_robot(self.robot, self.arm_mode, arm_mass_scale=self.arm_mass_scale)


@dataclass(frozen=True)
class SimTruth:
    """Simulator ground truth, for metrics and debugging only (a real robot has none of this).

    Attributes:
        time: simulation time [s].
        base_position_in_world: trunk origin, shape (3,) [m].
        base_quat: trunk orientation (w, x, y, z).
        base_linvel_in_world: trunk origin velocity, shape (3,) [m/s].
        base_angvel_in_body: trunk angular velocity in the trunk frame, shape (3,) [rad/s].
        com_in_world: whole-robot centre of mass, shape (3,) [m].
        com_velocity_in_world: its velocity, shape (3,) [m/s].
        foot_contact: whether each foot (FR, FL, RR, RL) touches the ground, shape (4,).
        ground_contact_bodies: names of non-foot bodies touching the ground.
        external_force_in_world: push force acting now, shape (3,) [N].
        external_point_in_world: where it acts, shape (3,) [m] (the trunk origin when no push acts).
    """

    time: float
    base_position_in_world: np.ndarray
    base_quat: np.ndarray
    base_linvel_in_world: np.ndarray
    base_angvel_in_body: np.ndarray
    com_in_world: np.ndarray
    com_velocity_in_world: np.ndarray
    foot_contact: np.ndarray
    ground_contact_bodies: tuple[str, ...]
    external_force_in_world: np.ndarray
    external_point_in_world: np.ndarray


_BAD_QPOS, _BAD_QVEL, _BAD_QACC = (int(mujoco.mjtWarning.mjWARN_BADQPOS), int(mujoco.mjtWarning.mjWARN_BADQVEL),
                                   int(mujoco.mjtWarning.mjWARN_BADQACC))
"""MuJoCo's warnings of a state it could not integrate (and reset after)."""


class MujocoRobot(Robot):
    """A robot simulated by MuJoCo.

    Args:
        config: what to simulate.
    """

    def __init__(self, config: MujocoRobotConfig | None = None) -> None:
        super().__init__()
        self.config = config if config is not None else MujocoRobotConfig()
        self._noisy = self.config.noise.enabled  # the config is frozen: asked once, not at every read
        self.desc = self.config.description()
        self._joint_names = self.desc.joint_names
        self._num_joints = len(self._joint_names)
        self._limits = joint_table(self.desc)
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._steps = 0
        self._checked_dt, self._checked_steps = math.nan, 0  # the last period `_advance` checked, and its steps
        self._rng = np.random.default_rng(0)
        self._strength = np.ones(self.num_joints)
        self._pushes = PushTable(1, self.config.timestep)
        self._contacts_at = -1
        self._contacts = (np.zeros(0, dtype=int), np.zeros(0, dtype=bool))
        self._force_now = np.zeros(3)
        self._point_now = np.zeros(3)
        self._quiet_until = -1  # physics steps before this one run without a push (see `_advance`)
        self._act_lag = 0  # [physics steps] actuation delay
        self._queue = CommandQueue()
        self._history: SensorHistory | None = None  # the sensing delay's frames; None: no sensing delay

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """Actuated joints, house order."""
        return self._joint_names

    @property
    def num_joints(self) -> int:
        """Number of actuated joints."""
        return self._num_joints

    @property
    def limits(self) -> JointTable:
        """Motor limits."""
        return self._limits

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return self._steps * self.config.timestep

    def _connect(self) -> None:
        self.model = build_scene(self.desc, self.config.terrain, timestep=self.config.timestep)
        self.data = mujoco.MjData(self.model)
        m = self.model
        # views of MuJoCo's buffers (fixed for the model's life), kept rather than fetched from the structs per tick
        d = self.data
        self._biasprm, self._ctrl = m.actuator_biasprm, d.ctrl
        self._qpos, self._qvel, self._geom_xpos = d.qpos, d.qvel, d.geom_xpos
        self._joint_q, self._joint_dq = d.qpos[7:], d.qvel[6:]
        self._motor_force, self._sensordata = d.actuator_force, d.sensordata
        self._warning_counts = d.warning.number  # each warning's count (mjtWarning order), read by `instability`
        self._base_body = base_body_id(m)
        self._terrain_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, TERRAIN_GEOM)
        # index arrays, not slices: each field `read` returns is its own array, not a view into one sensordata copy
        sensors = {name: np.arange(s.start, s.stop) for name, s in sensor_slices(m).items()}
        self._quat_idx, self._gyro_idx, self._accel_idx = sensors["imu_quat"], sensors["imu_gyro"], sensors["imu_accel"]
        self._touch_idx = foot_touch_adr(m)
        self._foot_geoms = foot_geoms(m)
        self._is_foot_geom = np.zeros(m.ngeom, dtype=bool)
        self._is_foot_geom[self._foot_geoms] = True
        self._nominal = NominalModel.of(m)
        self._reset(0, None, None)
        self._load_compiled()

    def _load_compiled(self) -> None:
        """Call the compiled write and fall check once, on dummy arrays of the live ones' types and layouts.

        A compiled function's first call in a process loads it (~0.4 s; compiles it, seconds, on a machine's first
        run): here, at connect, rather than at the first write of a stream a real-time link waits on (an emulator
        answering a robot's client over UDP).
        """
        nu = self.num_joints
        apply_motor_rows(np.zeros((5, nu)), np.ones(nu), np.zeros((nu, 10)), np.zeros(nu))
        # MuJoCo's contact fields are strided views: the same layout as these
        touches_off_foot(np.zeros((2, 4), dtype=np.int32)[:, :2], np.zeros((2, 6))[:, :3], self._terrain_geom,
                         self._is_foot_geom, self._foot_geoms, np.zeros((self.model.ngeom, 3)))

    def _close(self) -> None:
        self.model = None
        self.data = None

    def _read(self) -> RobotState:
        # tau_est and sensordata (IMU, foot forces) are MuJoCo's values from the start of the last mj_step, one
        # physics step older than q and dq (see the module docstring); kept as is: changing it moves every result
        noise = self.config.noise
        n = self.num_joints
        if self._history is None:
            q, dq, tau = self._joint_q.copy(), self._joint_dq.copy(), self._motor_force.copy()
            sd = self._sensordata.copy()
            measured = self.time
        else:
            frame = self._history.frame(self._steps)
            q, dq, tau, sd = frame.q, frame.dq, frame.tau, frame.sensordata
            measured = frame.step * self.config.timestep
        quat, gyro, accel = sd[self._quat_idx], sd[self._gyro_idx], sd[self._accel_idx]
        feet = sd[self._touch_idx]
        if self._noisy:
            rng = self._rng
            q += rng.normal(0.0, noise.q, n)
            dq += rng.normal(0.0, noise.dq, n)
            gyro += rng.normal(0.0, noise.gyro, 3)
            accel += rng.normal(0.0, noise.accel, 3)
            feet = np.maximum(feet + rng.normal(0.0, noise.foot_force, 4), 0.0)
            if noise.orientation > 0:
                half = 0.5 * rng.normal(0.0, noise.orientation, 3)
                dqt = np.r_[1.0, half] / np.linalg.norm(np.r_[1.0, half])
                res = np.empty(4)
                mujoco.mju_mulQuat(res, quat, dqt)
                quat = res
        return RobotState(
            tick=self._steps, time=measured, q=q, dq=dq, tau_est=tau, imu_quat=quat,
            gyro_in_body=gyro, accel_in_body=accel, foot_force=feet,
        )

    def _send(self, cmd: MotorCommand) -> None:
        if self._act_lag == 0 and not self._queue:
            # the motors take it now: gains and control written into MuJoCo's buffers by one compiled call
            apply_motor_rows(cmd.rows, self._strength, self._biasprm, self._ctrl)
        else:
            self._queue.push(self._steps + self._act_lag, cmd.kp, cmd.kd, motor_ctrl(cmd.q, cmd.dq, cmd.tau, cmd.kp,
                                                                                     cmd.kd))

    def _apply(self, kp: np.ndarray, kd: np.ndarray, ctrl: np.ndarray) -> None:
        """Hand a command to the motors: from the next physics step on, the motor law runs under it."""
        set_motor_gains(self.model, self._strength, kp, kd)
        self.data.ctrl[:] = ctrl

    def _advance(self, dt: float) -> None:
        # the closed loop advances by one period tick after tick: checked once, not at every tick of the hot path
        if dt == self._checked_dt and type(dt) is float:
            n = self._checked_steps
        else:
            n = self.physics_steps(dt)
            if type(dt) is float:
                self._checked_dt, self._checked_steps = dt, n
        m, d = self.model, self.data
        end = self._steps + n
        queue, history = self._queue, self._history
        if end <= self._quiet_until and history is None and not queue:
            # every step of this advance is known to be push-free (and no push force is left applied), no command
            # is on its way and no frame must be kept: the steps alone (the closed loop's usual tick)
            mujoco.mj_step(m, d, nstep=n)
            self._steps = end
            return
        # steps from `keep` on have frames a later read may ask for (see `SensorHistory`)
        keep = end - history.lag if history is not None else end + 1
        while self._steps < end:
            if queue:
                arrived = queue.due(self._steps)
                if arrived is not None:
                    self._apply(arrived.kp, arrived.kd, arrived.ctrl)
            active = self._active_pushes(self._steps)
            if active is None:
                # run without Python until a push starts, a delayed command arrives or a frame must be kept
                stop = end
                if self._pushes.count[0]:
                    nxt = self._pushes.next_start(0, self._steps)
                    if nxt is not None:
                        stop = min(stop, nxt)
                if queue:
                    stop = min(stop, queue.next_arrival())
                if history is not None:
                    stop = min(stop, max(keep, self._steps + 1))
                k = stop - self._steps
                d.xfrc_applied[self._base_body] = 0.0
                self._force_now[:] = 0.0
                mujoco.mj_step(m, d, nstep=k)
                self._steps += k
                if self._steps >= keep:
                    history.record(self._steps, d.qpos[7:], d.qvel[6:], d.actuator_force, d.sensordata)
                continue
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            rot = d.xmat[self._base_body].reshape(3, 3)
            points = np.array([d.xpos[self._base_body] + rot @ offset for offset in self._pushes.offset[0, active]])
            force, torque = push_wrench(self._pushes.force[0, active], points - d.xipos[self._base_body],
                                        np.ones(len(points)))
            self._point_now = points[-1]
            d.xfrc_applied[self._base_body, :3] = force
            d.xfrc_applied[self._base_body, 3:] = torque
            self._force_now = force
            mujoco.mj_step(m, d)
            self._steps += 1
            if self._steps >= keep:
                history.record(self._steps, d.qpos[7:], d.qvel[6:], d.actuator_force, d.sensordata)
        if self._active_pushes(self._steps) is None:
            d.xfrc_applied[self._base_body] = 0.0
            self._force_now = np.zeros(3)
            # quiet (no push force) until the next scheduled push starts
            nxt = self._pushes.next_start(0, self._steps) if self._pushes.count[0] else None
            self._quiet_until = _NEVER if nxt is None else nxt

    # -- simulation-only API --------------------------------------------------------------------------------------
    def physics_steps(self, dt: float) -> int:
        """The number of physics steps `dt` seconds span; `advance` takes only a whole, positive number of them.

        A period that is not one (a 300 Hz loop's 1/300 s over 2 ms steps) would otherwise run more or less robot
        time than the caller counts, unseen: refused, with the nearest valid periods. A relative tolerance of 1e-9
        takes the floating-point error of periods such as ``1 / 50``.

        Raises:
            ConfigError: `dt` is not a finite number, or not a whole number (at least 1) of physics steps.
        """
        step = self.config.timestep
        if (isinstance(dt, bool) or not isinstance(dt, int | float | np.integer | np.floating)
                or not math.isfinite(dt) or dt <= 0):
            raise ConfigError(f"MujocoRobot.advance: dt must be a finite positive number of seconds, got {dt!r}")
        ratio = dt / step
        n = round(ratio)
        if n < 1 or abs(ratio - n) > 1e-9 * n:
            below, above = max(1, math.floor(ratio)) * step, max(1, math.ceil(ratio)) * step
            nearest = f"{below:g} s" if below == above else f"{below:g} s or {above:g} s"
            raise ConfigError(f"MujocoRobot.advance: dt {dt:g} s is not a whole number of physics steps of {step:g} s "
                              f"(MujocoRobotConfig.timestep); the nearest valid dt: {nearest}")
        return int(n)

    def reset(self, seed: int = 0, *, domain: DomainParams | None = None, qpos: np.ndarray | None = None) -> None:
        """Put the robot back at its standing pose, with the terrain and randomisation of `seed`.

        Args:
            seed: seeds the terrain (fractal), the sensor noise and nothing else (an integer).
            domain: physical parameters (default: the config's, nominal unless set there).
            qpos: initial configuration, shape (``model.nq``,), finite (defaults: standing at the nominal pose above
                the terrain).

        Raises:
            ConfigError: `seed` is not an integer, or `qpos` is not a finite array of the model's ``nq`` numbers
                (checked before anything is reset).
            RobotNotConnectedError: not connected.
        """
        self._require_connected("reset")
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
            raise ConfigError(f"MujocoRobot.reset: seed must be an integer, got {seed!r}")
        if qpos is not None:
            nq = self.model.nq
            try:
                qpos = np.asarray(qpos, dtype=float)
            except (TypeError, ValueError):
                raise ConfigError(f"MujocoRobot.reset: qpos must be an array of {nq} numbers, got "
                                  f"{type(qpos).__name__}") from None
            if qpos.shape != (nq,):
                raise ConfigError(f"MujocoRobot.reset: qpos must have shape ({nq},) (base position, quaternion, "
                                  f"joints), got {qpos.shape}")
            if not np.all(np.isfinite(qpos)):
                raise ConfigError(f"MujocoRobot.reset: qpos holds a non-finite value at index "
                                  f"{int(np.argmin(np.isfinite(qpos)))}")
        self._reset(seed, domain, qpos)

    def _reset(self, seed: int, domain: DomainParams | None, qpos: np.ndarray | None) -> None:
        m, d = self.model, self.data
        self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5E45]))
        ground = apply_terrain(m, self.config.terrain, seed)
        self.set_domain(domain if domain is not None else self.config.domain)
        mujoco.mj_resetData(m, d)
        d.qpos[:] = (initial_qpos(m.nq, spawn_height(self.desc.stand_height, ground), self.desc.nominal_q)
                     if qpos is None else qpos)
        self._pushes.clear(0)
        self._quiet_until = -1  # the first advance takes the full path and finds the next push
        self._steps = 0
        self._contacts_at = -1
        self._force_now = np.zeros(3)
        self._point_now = d.qpos[:3].copy()
        self._queue.clear()
        hold = MotorCommand.hold(self.desc.nominal_q, 0.0, 0.0)
        self._apply(hold.kp, hold.kd, motor_ctrl(hold.q, hold.dq, hold.tau, hold.kp, hold.kd))
        mujoco.mj_forward(m, d)
        self._seed_history()

    def set_domain(self, domain: DomainParams) -> None:
        """Apply physical parameters (payload, friction, motor strength, delays) on top of the nominal model.

        The same function (`wbc.hardware.mujoco.physics.apply_domain`) writes the training env's model variants.
        Delays take effect at once: commands already on their way arrive as scheduled, later ones after the new
        actuation delay (never before an earlier one); a new sensing delay starts its history at the current frame.
        """
        self._strength = apply_domain(self.model, self.data, self._nominal, payload_kg=domain.payload_mass,
                                      payload_com=domain.payload_com, friction=domain.friction,
                                      motor_strength=domain.motor_strength)
        dt = self.config.timestep
        self._act_lag = delay_steps(domain.actuation_delay, dt)
        sense = delay_steps(domain.sensing_delay, dt)
        if sense != (0 if self._history is None else self._history.lag):
            self._history = SensorHistory(sense, self.model.nu, self.model.nsensordata) if sense else None
            self._seed_history()

    @property
    def actuation_delay_steps(self) -> int:
        """The actuation delay in physics steps (`DomainParams.actuation_delay`, rounded)."""
        return self._act_lag

    @property
    def sensing_delay_steps(self) -> int:
        """The sensing delay in physics steps (`DomainParams.sensing_delay`, rounded)."""
        return 0 if self._history is None else self._history.lag

    def apply_push(self, push: Push) -> None:
        """Schedule a push; it acts from ``push.start`` (simulation time) for ``push.duration``.

        Raises:
            ConfigError: the push starts before the current physics step (it would never act in full: refused
                rather than dropped); one at the current time is taken.
            RobotNotConnectedError: not connected.
        """
        self._require_connected("apply_push")
        start, _ = push_steps(push.start, push.duration, self.config.timestep)
        if start < self._steps:
            raise ConfigError(f"MujocoRobot.apply_push: the push starts at {push.start:g} s, before the robot's time "
                              f"{self.time:g} s; schedule it at or after the current time")
        self._pushes.add(0, push)
        self._quiet_until = -1  # the next advance takes the full path and finds the next push again

    def sim_truth(self) -> SimTruth:
        """Ground truth of the simulator (for metrics and debugging; never hand this to a controller)."""
        self._require_connected("sim_truth")
        m, d = self.model, self.data
        mujoco.mj_subtreeVel(m, d)
        touching, at_foot = self._ground_contacts()
        mask = np.zeros(m.ngeom, dtype=bool)
        mask[touching] = True
        foot = mask[self._foot_geoms]
        others = sorted({mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, m.geom_bodyid[g])
                         for g, ok in zip(touching, at_foot, strict=True) if not ok})
        active = bool(np.any(self._force_now))
        return SimTruth(
            time=self.time,
            base_position_in_world=d.qpos[:3].copy(),
            base_quat=d.qpos[3:7].copy(),
            base_linvel_in_world=d.qvel[:3].copy(),
            base_angvel_in_body=d.qvel[3:6].copy(),
            com_in_world=d.subtree_com[self._base_body].copy(),
            com_velocity_in_world=d.subtree_linvel[self._base_body].copy(),
            foot_contact=foot,
            ground_contact_bodies=tuple(others),
            external_force_in_world=self._force_now.copy(),
            external_point_in_world=self._point_now.copy() if active else d.qpos[:3].copy(),
        )

    def base_truth(self) -> BaseTruth:
        """Truth: the trunk's pose and velocity (for metrics; never hand this to a controller)."""
        self._require_connected("base_truth")  # the views of a closed robot's buffers would read stale
        qpos, qvel = self._qpos, self._qvel
        return BaseTruth(qpos[:3].copy(), qpos[3:7].copy(), qvel[:3].copy(), qvel[3:6].copy())

    def fallen(self) -> bool:
        """Truth: the trunk or a non-foot link touches the ground (the paper's termination rule, `fall_rule`)."""
        self._require_connected("fallen")
        d = self.data
        if d.ncon == 0:
            return False
        contacts = d.contact
        return bool(touches_off_foot(contacts.geom, contacts.pos, self._terrain_geom, self._is_foot_geom,
                                     self._foot_geoms, self._geom_xpos))

    def instability(self) -> str | None:
        """What MuJoCo reported as unstable since the last reset (`SimulatorHealth`), or None.

        MuJoCo answers a position, velocity or acceleration it cannot integrate (NaN, inf or beyond 1e10) with a
        warning, resets its state to the model's initial one and carries on; the warning's count, which the reset
        keeps, is all that shows it happened. Three integer reads: cheap enough for every tick.
        """
        self._require_connected("instability")
        counts = self._warning_counts
        if not (counts[_BAD_QPOS] or counts[_BAD_QVEL] or counts[_BAD_QACC]):
            return None
        warning = self.data.warning
        what = ", ".join(f"{name} ({warning[i].number} time{'s' if warning[i].number > 1 else ''}, last at DOF "
                         f"{warning[i].lastinfo})" for name, i in (("a position", _BAD_QPOS), ("a velocity", _BAD_QVEL),
                                                                  ("an acceleration", _BAD_QACC))
                         if warning[i].number)
        return f"MuJoCo could not integrate {what}: NaN, inf or huge, and reset its own state"

    def base_rotation(self) -> np.ndarray:
        """Truth: trunk rotation matrix (body to world)."""
        self._require_connected("base_rotation")
        return quat_to_matrix(self.data.qpos[3:7])

    # -- internals ------------------------------------------------------------------------------------------------
    def _seed_history(self) -> None:
        """Start the sensing delay's history at the current frame (nothing without a sensing delay)."""
        if self._history is not None:
            d = self.data
            self._history.seed(self._steps, d.qpos[7:], d.qvel[6:], d.actuator_force, d.sensordata)

    def _ground_contacts(self) -> tuple[np.ndarray, np.ndarray]:
        """Robot geoms touching the ground now, and whether each contact is a foot's.

        A contact counts as a foot's if it is the foot sphere's, or if it lies within `fall_rule.FOOT_ZONE` of a foot
        centre (`wbc.hardware.mujoco.fall_rule`, the rule training's termination shares).
        """
        if self._contacts_at == self._steps:
            return self._contacts
        d = self.data
        if d.ncon == 0:
            touching, at_foot = np.zeros(0, dtype=int), np.zeros(0, dtype=bool)
        else:
            pairs = d.contact.geom[: d.ncon]
            touching = np.where(pairs[:, 0] == self._terrain_geom, pairs[:, 1], pairs[:, 0])
            at_foot = self._is_foot_geom[touching].copy()
            if not at_foot.all():
                at_foot |= near_feet(d.contact.pos[: d.ncon], d.geom_xpos[self._foot_geoms])
        self._contacts, self._contacts_at = (touching, at_foot), self._steps
        return touching, at_foot

    def _active_pushes(self, step: int) -> np.ndarray | None:
        """(P,) which of the scheduled pushes act at physics step `step`, or None when none does.

        Called once or twice per `advance`: without pushes it costs one integer test, not the table's batched form.
        """
        pushes = self._pushes
        if not pushes.count[0]:
            return None
        active = (pushes.start[0] <= step) & (step < pushes.stop[0])
        return active if active.any() else None
