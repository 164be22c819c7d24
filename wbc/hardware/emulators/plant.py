"""`SharedPlant`: one simulated quadruped with its arm actuated, driven by two emulators (legs and arm) at once.

A real robot is one body with two links: the legs on Unitree's UDP wire, the arm on its Dynamixel bus. `SharedPlant`
is that body: one `MujocoRobot` (``a1-wx200`` or ``go1-arm``, arm actuated: 15 joints) under one lock. It keeps the
latest leg command (12 joints, from `write_legs`) and the latest arm command (3 joints, from `write_arm`), and the
simulator always runs their concatenation. `step(dt)` advances the physics. The leg emulator calls it in
lockstep with its commands, or its own real-time loop does. When nothing else steps it, `start_realtime` runs a
thread that does.

`legs` is the legs' side in the shape a leg emulator drives (`PlantLegs`: read, write, advance, reset, time,
base_truth, model); `read_arm` / `write_arm` are the arm's side (`ArmPlant`). An arm command may carry a torque bound
per joint (`tau_max`: a servo's current limit in current-based position mode). MuJoCo's actuator cannot change its
force range per command, so while such a bound is tighter than the motor's own limit, the arm's PD law is
evaluated in Python at every physics step and applied as a clamped torque. That costs one `write` per step, about
as much as the step itself.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import mujoco
import numpy as np

from wbc.errors import CommandError, ConfigError
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig, SimTruth
from wbc.types import BaseTruth, MotorCommand, RobotState

__all__ = ["ARM_JOINTS", "LEG_JOINTS", "PlantLegs", "SharedPlant", "SharedPlantConfig"]

LEG_JOINTS = 12
ARM_JOINTS = 3


@dataclass(frozen=True, kw_only=True)
class SharedPlantConfig:
    """Configuration of the shared simulated robot.

    Attributes:
        robot: ``a1-wx200`` or ``go1-arm`` (any registered robot with an arm), built with the arm actuated.
        timestep: physics step [s].
        seed: seed of the simulation (terrain and noise; flat and noiseless by default).
        realtime_period: physics time per tick of the real-time thread, paced at wall-clock speed [s].
    """

    robot: str = "a1-wx200"
    timestep: float = 0.002
    seed: int = 0
    realtime_period: float = 0.002

    def __post_init__(self) -> None:
        if not 0 < self.realtime_period <= 0.02:
            raise ConfigError(f"SharedPlantConfig.realtime_period must be in (0, 0.02] s, got {self.realtime_period}")


class SharedPlant:
    """One simulated robot with its arm actuated, shared by a leg emulator and an arm emulator. A context manager.

    Args:
        config: what to simulate.
        sim: the simulated robot (15 joints); None builds ``config.robot`` with the arm actuated.

    Raises:
        ConfigError: the robot does not have 12 legs and 3 arm joints.
    """

    def __init__(self, config: SharedPlantConfig | None = None, sim: MujocoRobot | None = None) -> None:
        self.config = config if config is not None else SharedPlantConfig()
        self.sim = sim if sim is not None else MujocoRobot(MujocoRobotConfig(
            robot=self.config.robot, arm_mode="actuated", timestep=self.config.timestep))
        if self.sim.num_joints != LEG_JOINTS + ARM_JOINTS:
            raise ConfigError(f"SharedPlant: the robot must have {LEG_JOINTS} leg and {ARM_JOINTS} arm joints "
                              f"(arm mode actuated), it has {self.sim.num_joints}")
        self._lock = threading.RLock()
        # before any link speaks, every motor is off: no torque (the servos start with the torque off too)
        self._legs = MotorCommand.damping(LEG_JOINTS, 0.0)
        self._arm = MotorCommand.damping(ARM_JOINTS, 0.0)
        self._arm_tau_max: np.ndarray | None = None
        self._applied: MotorCommand | None = None
        self._clamp_arm = False
        self._arm_limit = self.sim.limits.torque_limit[LEG_JOINTS:].copy()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.overruns = 0  # real-time ticks that started late by more than one period
        self.failure: BaseException | None = None
        self.legs = PlantLegs(self)

    # -- lifecycle ------------------------------------------------------------------------------------------------
    def start(self) -> SharedPlant:
        """Build the simulation at its standing pose (idempotent). The real-time thread is `start_realtime`."""
        with self._lock:
            if not self.sim.is_connected:
                self.sim.connect()
                self.sim.reset(self.config.seed)
                self._apply()
        return self

    def close(self) -> None:
        """Stop the real-time thread and release the simulation. Idempotent."""
        self.stop_realtime()
        with self._lock:
            self.sim.close()

    def __enter__(self) -> SharedPlant:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reset(self, seed: int | None = None, *, qpos: np.ndarray | None = None) -> None:
        """Put the robot back at its standing pose, or at configuration `qpos`; the latest commands stay in force.

        Args:
            seed: the simulation's seed (default: the config's).
            qpos: the full configuration (trunk position, quaternion w x y z, 15 joints) [m, rad].

        Raises:
            ConfigError: `qpos` has the wrong shape.
        """
        with self._lock:
            self.start()
            if qpos is not None and np.shape(qpos) != (self.sim.model.nq,):
                raise ConfigError(f"SharedPlant.reset: qpos must have shape ({self.sim.model.nq},), got "
                                  f"{np.shape(qpos)}")
            self.sim.reset(self.config.seed if seed is None else seed,
                           qpos=None if qpos is None else np.asarray(qpos, dtype=np.float64))
            self._apply()

    # -- the two sides ------------------------------------------------------------------------------------------
    def write_legs(self, cmd: MotorCommand) -> MotorCommand:
        """Set the 12 leg motors' command (kept until the next one); return what the motors apply after clamping.

        Raises:
            CommandError: not 12 joints.
        """
        if cmd.num_joints != LEG_JOINTS:
            raise CommandError(f"SharedPlant.write_legs: {cmd.num_joints} joints, the legs have {LEG_JOINTS}")
        with self._lock:
            self._legs = cmd
            applied = self._apply()
        return MotorCommand._trusted(applied.stacked()[:, :LEG_JOINTS].copy())

    def write_arm(self, cmd: MotorCommand, tau_max: np.ndarray | None = None) -> None:
        """Set the arm's command (`ArmPlant.write_arm`).

        Raises:
            CommandError: not 3 joints, or `tau_max` not (3,) of non-negative numbers (inf allowed).
        """
        if cmd.num_joints != ARM_JOINTS:
            raise CommandError(f"SharedPlant.write_arm: {cmd.num_joints} joints, the arm has {ARM_JOINTS}")
        bound = None
        if tau_max is not None:
            bound = np.array(tau_max, dtype=np.float64)
            if bound.shape != (ARM_JOINTS,) or np.isnan(bound).any() or (bound < 0).any():
                raise CommandError(f"SharedPlant.write_arm: tau_max must be (3,) non-negative [N m], got {tau_max}")
        with self._lock:
            self._arm, self._arm_tau_max = cmd, bound
            self._apply()

    def read(self) -> RobotState:
        """The whole robot's sensors now (15 joints, IMU, feet)."""
        with self._lock:
            return self.sim.read()

    def read_legs(self) -> RobotState:
        """The sensors as the leg link reports them: 12 joints, the IMU and the feet."""
        s = self.read()
        return RobotState(tick=s.tick, time=s.time, q=s.q[:LEG_JOINTS], dq=s.dq[:LEG_JOINTS],
                          tau_est=s.tau_est[:LEG_JOINTS], imu_quat=s.imu_quat, gyro_in_body=s.gyro_in_body,
                          accel_in_body=s.accel_in_body, foot_force=s.foot_force)

    def read_arm(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q [rad], dq [rad/s], tau_est [N m]) of the arm's three joints, each (3,) (`ArmPlant.read_arm`)."""
        s = self.read()
        return s.q[LEG_JOINTS:], s.dq[LEG_JOINTS:], s.tau_est[LEG_JOINTS:]

    def arm_command(self) -> tuple[MotorCommand, np.ndarray | None]:
        """The arm command in force and its torque bound, as the arm's emulator last wrote them."""
        with self._lock:
            return self._arm, None if self._arm_tau_max is None else self._arm_tau_max.copy()

    # -- time -----------------------------------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulation time [s]."""
        with self._lock:
            return self.sim.time

    def step(self, dt: float) -> None:
        """Advance the physics by `dt` (rounded to whole physics steps, at least one) [s]."""
        ts = self.sim.config.timestep
        n = max(1, round(dt / ts))
        with self._lock:
            if not self._clamp_arm:
                self.sim.advance(n * ts)
                return
            for _ in range(n):
                self._write_clamped_arm()
                self.sim.advance(ts)

    def base_truth(self) -> BaseTruth:
        """The simulated trunk's true pose and velocity now."""
        with self._lock:
            return self.sim.base_truth()

    def sim_truth(self) -> SimTruth:
        """The simulator's ground truth now (metrics only)."""
        with self._lock:
            return self.sim.sim_truth()

    # -- real time ------------------------------------------------------------------------------------------------
    @property
    def realtime(self) -> bool:
        """True while the real-time thread steps the physics."""
        return self._thread is not None

    def start_realtime(self) -> None:
        """Step the physics at wall-clock pace on a thread (`config.realtime_period` per tick). Idempotent."""
        if self._thread is not None:
            return
        self.start()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="shared-plant", daemon=True)
        self._thread.start()

    def stop_realtime(self) -> None:
        """Stop the real-time thread. Idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _run(self) -> None:
        period = self.config.realtime_period
        next_tick = time.monotonic() + period
        try:
            while not self._stop.is_set():
                delay = next_tick - time.monotonic()
                if delay > 0:
                    self._stop.wait(delay)
                self.step(period)
                next_tick += period
                now = time.monotonic()
                if now - next_tick > period:
                    self.overruns += 1
                    next_tick = now + period
        except BaseException as exc:  # noqa: BLE001 - kept for the caller to read; the thread must not die silently
            self.failure = exc

    # -- internals ------------------------------------------------------------------------------------------------
    def _apply(self) -> MotorCommand:
        """Send legs + arm to the simulator (under the lock); return what it applies."""
        rows = np.concatenate([self._legs.stacked(), self._arm.stacked()], axis=1)
        full = MotorCommand._trusted(rows)  # both halves were validated when built
        if not self.sim.is_connected:
            return full
        self._applied = self.sim.write(full)
        bound = self._arm_tau_max
        self._clamp_arm = bound is not None and bool((bound < self._arm_limit).any())
        return self._applied

    def _write_clamped_arm(self) -> None:
        """Evaluate the arm's PD law now and send it as a torque within the arm's bound (under the lock)."""
        d, cmd = self.sim.data, self._applied
        q = d.qpos[7 + LEG_JOINTS: 7 + LEG_JOINTS + ARM_JOINTS]
        dq = d.qvel[6 + LEG_JOINTS: 6 + LEG_JOINTS + ARM_JOINTS]
        arm = slice(LEG_JOINTS, LEG_JOINTS + ARM_JOINTS)
        tau = cmd.kp[arm] * (cmd.q[arm] - q) + cmd.kd[arm] * (cmd.dq[arm] - dq) + cmd.tau[arm]
        limit = np.minimum(self._arm_tau_max, self._arm_limit)
        rows = cmd.stacked()
        rows[2:4, arm] = 0.0
        rows[4, arm] = np.clip(tau, -limit, limit)
        self.sim.write(MotorCommand._trusted(rows))


class PlantLegs:
    """The legs' side of a `SharedPlant`, shaped as the part of `MujocoRobot` a leg emulator drives.

    ``UnitreeEmulator(config, sim=plant.legs)`` runs the Unitree wire over the shared body: its commands reach the
    12 leg motors, its states report the 12 legs, and its physics steps advance the whole robot, arm included.

    Args:
        plant: the shared robot.
    """

    num_joints = LEG_JOINTS

    def __init__(self, plant: SharedPlant) -> None:
        self._plant = plant

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The 12 leg joints, house order."""
        return self._plant.sim.joint_names[:LEG_JOINTS]

    @property
    def model(self) -> mujoco.MjModel:
        """The whole robot's MuJoCo model (``nq`` counts the arm's joints too)."""
        return self._plant.sim.model

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return self._plant.time

    def connect(self) -> None:
        """Build the shared simulation if nobody has yet."""
        self._plant.start()

    def reset(self, seed: int = 0, *, qpos: np.ndarray | None = None) -> None:
        """Reset the whole robot (`SharedPlant.reset`)."""
        self._plant.reset(seed, qpos=qpos)

    def read(self) -> RobotState:
        """12 joints, IMU, feet."""
        return self._plant.read_legs()

    def write(self, cmd: MotorCommand) -> MotorCommand:
        """Command the 12 leg motors; return what they apply."""
        return self._plant.write_legs(cmd)

    def advance(self, dt: float) -> None:
        """Step the whole robot's physics [s]."""
        self._plant.step(dt)

    def base_truth(self) -> BaseTruth:
        """The trunk's true pose and velocity."""
        return self._plant.base_truth()
