"""`MujocoRobot`: the simulated robot behind the `Robot` interface.

The motor law runs inside MuJoCo's step (see `wbc.robots.mujoco_model`), so `advance` calls ``mj_step`` with
``nstep`` and no Python in between, except while a push acts (its torque about the CoM is refreshed every physics
step as the trunk moves). What `read` returns is what the real robot's sensors give (joint encoders, motor torque
estimate, IMU, foot force sensors, optionally noisy); simulator truth (base pose and velocity, contacts, applied
force) is only reachable through `sim_truth()`, for metrics.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from wbc.errors import ConfigError
from wbc.hardware.domain import DomainParams, SensorNoise
from wbc.hardware.mujoco_scene import TERRAIN_GEOM, build_scene, set_terrain_heights
from wbc.hardware.perturbation import Push
from wbc.hardware.robot import Robot
from wbc.hardware.terrain import TerrainConfig, fractal_heights
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import FOOT_NAMES, RobotDescription
from wbc.robots.joint_table import JointTable, joint_table
from wbc.robots.registry import get_robot
from wbc.types import MotorCommand, RobotState

__all__ = ["MujocoRobotConfig", "MujocoRobot", "SimTruth", "initial_qpos"]


@dataclass(frozen=True, kw_only=True)
class MujocoRobotConfig:
    """Configuration of the simulated robot.

    Attributes:
        robot: registry name (``a1-wx200``, ``go1-arm``).
        arm_mode: ``none``, ``locked`` or ``actuated``.
        arm_mass_scale: scales the arm's mass and inertia.
        terrain: ground shape.
        timestep: physics step [s].
        noise: sensor noise added by `read`.
    """

    robot: str = "a1-wx200"
    arm_mode: str = "actuated"
    arm_mass_scale: float = 1.0
    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    timestep: float = 0.002
    noise: SensorNoise = field(default_factory=SensorNoise)

    def __post_init__(self) -> None:
        if not 0 < self.timestep <= 0.01:
            raise ConfigError(f"MujocoRobotConfig.timestep must be in (0, 0.01] s, got {self.timestep}")

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


def initial_qpos(model: mujoco.MjModel, desc: RobotDescription, base_height: float) -> np.ndarray:
    """Standing configuration: trunk level at `base_height`, joints at the nominal pose."""
    qpos = np.zeros(model.nq)
    qpos[2] = base_height
    qpos[3] = 1.0
    qpos[7:] = desc.nominal_q
    return qpos


class MujocoRobot(Robot):
    """A robot simulated by MuJoCo.

    Args:
        config: what to simulate.
    """

    def __init__(self, config: MujocoRobotConfig | None = None) -> None:
        super().__init__()
        self.config = config if config is not None else MujocoRobotConfig()
        self.desc = self.config.description()
        self._limits = joint_table(self.desc)
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._pushes: list[Push] = []
        self._steps = 0
        self._rng = np.random.default_rng(0)
        self._domain = DomainParams()
        self._kp = np.zeros(self.num_joints)
        self._kd = np.zeros(self.num_joints)
        self._force_now = np.zeros(3)
        self._point_now = np.zeros(3)

    # -- Robot ----------------------------------------------------------------------------------------------------
    @property
    def joint_names(self) -> tuple[str, ...]:
        """Actuated joints, house order."""
        return self.desc.joint_names

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
        self._base_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base")
        self._terrain_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, TERRAIN_GEOM)
        self._sensor = {
            name: (m.sensor_adr[i], m.sensor_dim[i])
            for i in range(m.nsensor)
            for name in [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SENSOR, i)]
        }
        foot_body = {mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f): None for f in FOOT_NAMES}
        self._foot_bodies = np.array([m.site_bodyid[s] for s in foot_body])
        self._nominal = {
            "body_mass": m.body_mass.copy(), "body_ipos": m.body_ipos.copy(), "body_inertia": m.body_inertia.copy(),
            "geom_friction": m.geom_friction.copy(), "forcerange": m.actuator_forcerange.copy(),
        }
        self._reset(0, None, None)

    def _close(self) -> None:
        self.model = None
        self.data = None

    def _read(self) -> RobotState:
        d, noise = self.data, self.config.noise
        n = self.num_joints
        q = d.qpos[7:].copy()
        dq = d.qvel[6:].copy()
        quat = self._sensor_value("imu_quat")
        gyro = self._sensor_value("imu_gyro")
        accel = self._sensor_value("imu_accel")
        feet = np.array([self._sensor_value(f.replace("_foot", "_touch"))[0] for f in FOOT_NAMES])
        if noise.enabled:
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
            tick=self._steps, time=self.time, q=q, dq=dq, tau_est=d.actuator_force.copy(), imu_quat=quat,
            gyro_in_body=gyro, accel_in_body=accel, foot_force=feet,
        )

    def _send(self, cmd: MotorCommand) -> None:
        m, d = self.model, self.data
        k = np.broadcast_to(np.asarray(self._domain.motor_strength, dtype=np.float64), (self.num_joints,))
        m.actuator_gainprm[:, 0] = k
        m.actuator_biasprm[:, 1] = -k * cmd.kp
        m.actuator_biasprm[:, 2] = -k * cmd.kd
        d.ctrl[:] = cmd.kp * cmd.q + cmd.kd * cmd.dq + cmd.tau
        self._kp, self._kd = cmd.kp, cmd.kd

    def _advance(self, dt: float) -> None:
        n = max(1, int(round(dt / self.config.timestep)))
        m, d = self.model, self.data
        while n > 0:
            active = self._active_pushes(self._steps)
            if not active:
                # run without Python until the next push starts
                nxt = self._next_push_step(self._steps)
                k = n if nxt is None else max(1, min(n, nxt - self._steps))
                d.xfrc_applied[self._base_body] = 0.0
                self._force_now[:] = 0.0
                mujoco.mj_step(m, d, nstep=k)
                self._steps += k
                n -= k
                continue
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            rot = d.xmat[self._base_body].reshape(3, 3)
            force, torque = np.zeros(3), np.zeros(3)
            for p in active:
                point = d.xpos[self._base_body] + rot @ p.offset_in_base
                force += p.force_in_world
                torque += np.cross(point - d.xipos[self._base_body], p.force_in_world)
                self._point_now = point
            d.xfrc_applied[self._base_body, :3] = force
            d.xfrc_applied[self._base_body, 3:] = torque
            self._force_now = force
            mujoco.mj_step(m, d)
            self._steps += 1
            n -= 1
        if not self._active_pushes(self._steps):
            d.xfrc_applied[self._base_body] = 0.0
            self._force_now = np.zeros(3)

    # -- simulation-only API --------------------------------------------------------------------------------------
    def reset(self, seed: int = 0, *, domain: DomainParams | None = None, qpos: np.ndarray | None = None) -> None:
        """Put the robot back at its standing pose, with the terrain and randomisation of `seed`.

        Args:
            seed: seeds the terrain (fractal), the sensor noise and nothing else.
            domain: physical parameters (defaults: nominal).
            qpos: initial configuration (defaults: standing at the nominal pose above the terrain).
        """
        self._require_connected("reset")
        self._reset(seed, domain, qpos)

    def _reset(self, seed: int, domain: DomainParams | None, qpos: np.ndarray | None) -> None:
        m, d = self.model, self.data
        self._rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x5E45]))
        ground = 0.0
        if self.config.terrain.kind == "fractal":
            heights = fractal_heights(self.config.terrain, seed)
            set_terrain_heights(m, heights)
            c, r = heights.shape[0] // 2, int(round(0.4 / self.config.terrain.cell))
            ground = float(heights[c - r:c + r + 1, c - r:c + r + 1].max()) * self.config.terrain.amplitude
        self.set_domain(domain if domain is not None else DomainParams())
        mujoco.mj_resetData(m, d)
        d.qpos[:] = initial_qpos(m, self.desc, self.desc.stand_height + ground + 0.02) if qpos is None else qpos
        self._pushes = []
        self._steps = 0
        self._force_now = np.zeros(3)
        self._point_now = d.qpos[:3].copy()
        self._send(MotorCommand.hold(self.desc.nominal_q, 0.0, 0.0))
        mujoco.mj_forward(m, d)

    def set_domain(self, domain: DomainParams) -> None:
        """Apply physical parameters (payload, friction, motor strength) on top of the nominal model."""
        m, nom = self.model, self._nominal
        b = self._base_body
        m.body_mass[:] = nom["body_mass"]
        m.body_ipos[:] = nom["body_ipos"]
        m.body_inertia[:] = nom["body_inertia"]
        if domain.payload_mass != 0.0:
            m0, c0 = nom["body_mass"][b], nom["body_ipos"][b]
            m1 = m0 + domain.payload_mass
            m.body_mass[b] = m1
            m.body_ipos[b] = (m0 * c0 + domain.payload_mass * domain.payload_com) / m1
        m.geom_friction[:] = nom["geom_friction"]
        m.geom_friction[:, 0] = domain.friction
        k = np.broadcast_to(np.asarray(domain.motor_strength, dtype=np.float64), (self.num_joints,))
        m.actuator_forcerange[:] = nom["forcerange"] * k[:, None]
        self._domain = domain
        mujoco.mj_setConst(m, self.data)

    def apply_push(self, push: Push) -> None:
        """Schedule a push; it acts from ``push.start`` (simulation time) for ``push.duration``."""
        self._require_connected("apply_push")
        self._pushes.append(push)

    def sim_truth(self) -> SimTruth:
        """Ground truth of the simulator (for metrics and debugging; never hand this to a controller)."""
        self._require_connected("sim_truth")
        m, d = self.model, self.data
        mujoco.mj_subtreeVel(m, d)
        foot = np.zeros(4, dtype=bool)
        others: set[str] = set()
        for i in range(d.ncon):
            c = d.contact[i]
            if self._terrain_geom not in (c.geom1, c.geom2):
                continue
            body = m.geom_bodyid[c.geom2 if c.geom1 == self._terrain_geom else c.geom1]
            hit = np.flatnonzero(self._foot_bodies == body)
            is_foot_geom = m.geom_type[c.geom1 if c.geom1 != self._terrain_geom else c.geom2] == \
                mujoco.mjtGeom.mjGEOM_SPHERE
            if hit.size and is_foot_geom:
                foot[hit[0]] = True
            else:
                others.add(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body))
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
            ground_contact_bodies=tuple(sorted(others)),
            external_force_in_world=self._force_now.copy(),
            external_point_in_world=self._point_now.copy() if active else d.qpos[:3].copy(),
        )

    def base_rotation(self) -> np.ndarray:
        """Truth: trunk rotation matrix (body to world)."""
        return quat_to_matrix(self.data.qpos[3:7])

    # -- internals ------------------------------------------------------------------------------------------------
    def _sensor_value(self, name: str) -> np.ndarray:
        adr, dim = self._sensor[name]
        return self.data.sensordata[adr:adr + dim].copy()

    def _push_steps(self, p: Push) -> tuple[int, int]:
        start = int(round(p.start / self.config.timestep))
        return start, start + max(1, int(round(p.duration / self.config.timestep)))

    def _active_pushes(self, step: int) -> list[Push]:
        return [p for p in self._pushes if self._push_steps(p)[0] <= step < self._push_steps(p)[1]]

    def _next_push_step(self, step: int) -> int | None:
        starts = [self._push_steps(p)[0] for p in self._pushes if self._push_steps(p)[0] > step]
        return min(starts) if starts else None
