"""What the simulated robot and the training env both do to a MuJoCo model and its data, written once.

`MujocoRobot` (one robot, one model) and the batched training env (`wbc.learned.env`: N environments stepping a pool
of model variants) must simulate the same robot. So the domain parameters they write into a model, the motor law's
split into actuator parameters and controls, the ground under the spawn point and the spawn pose, the rounding of a
push to physics steps and its force and torque about the trunk's centre of mass, the rounding of a delay to physics
steps, and the lookups of the trunk body and the sensors all live here. The robot calls these functions for itself,
the env for its batch. Functions over arrays take leading batch axes. Functions that write a model take one model,
because MuJoCo keeps each variant in its own object, and the env calls them once per variant.

Motor law (Unitree low-level semantics, as an affine MuJoCo actuator, `wbc.robots.mujoco_model`):
``force = k (kp q* + kd dq* + tau_ff) - k kp q - k kd dq``, clamped to ``k`` times the torque limit, with ``k``
the motor strength: ``gainprm[0] = k``, ``biasprm[1:3] = (-k kp, -k kd)`` (`set_motor_gains`) and
``ctrl = kp q* + kd dq* + tau_ff`` (`motor_ctrl`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numba
import numpy as np

from wbc.hardware.mujoco.scene import set_ground_friction, set_terrain_heights
from wbc.robots.description import FOOT_NAMES
from wbc.scenario.push import Push
from wbc.scenario.terrain import TerrainConfig, fractal_heights

__all__ = [
    "BASE_BODY", "SPAWN_CLEARANCE", "SPAWN_GROUND_HALF_WIDTH", "NominalModel", "PushTable", "apply_domain",
    "apply_motor_rows", "apply_terrain", "base_body_id", "delay_steps", "foot_touch_adr", "ground_under_spawn",
    "initial_qpos", "motor_ctrl", "motor_strengths", "payload_trunk_inertial", "push_steps", "push_wrench",
    "sensor_slices",
    "set_motor_gains", "spawn_height",
]

BASE_BODY = "base"
"""Name of the trunk body: it carries the free joint, the payload and the pushes."""

SPAWN_CLEARANCE = 0.02  # [m] the feet start this far above the highest ground under the spawn point
SPAWN_GROUND_HALF_WIDTH = 0.4  # [m] half-width of the square under the spawn point whose highest point counts


# -- lookups --------------------------------------------------------------------------------------------------------
def base_body_id(model: mujoco.MjModel) -> int:
    """The trunk's body id."""
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, BASE_BODY)


def sensor_slices(model: mujoco.MjModel) -> dict[str, slice]:
    """Every sensor's entries in ``data.sensordata``, by sensor name."""
    return {
        model.sensor(i).name: slice(int(model.sensor_adr[i]), int(model.sensor_adr[i] + model.sensor_dim[i]))
        for i in range(model.nsensor)
    }


def foot_touch_adr(model: mujoco.MjModel) -> np.ndarray:
    """Index in ``data.sensordata`` of each foot's touch sensor, in `FOOT_NAMES` order (FR, FL, RR, RL)."""
    slices = sensor_slices(model)
    return np.array([slices[f.replace("_foot", "_touch")].start for f in FOOT_NAMES])


# -- domain parameters ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NominalModel:
    """The model fields that domain parameters overwrite, as compiled, so each application starts from nominal.

    Attributes:
        body_mass: (nbody,) [kg].
        body_ipos: (nbody, 3) centre of mass in each body's frame [m].
        body_inertia: (nbody, 3) principal inertia [kg m^2].
        geom_friction: (ngeom, 3) sliding, torsional, rolling friction.
        actuator_forcerange: (nu, 2) torque limits [N m].
    """

    body_mass: np.ndarray
    body_ipos: np.ndarray
    body_inertia: np.ndarray
    geom_friction: np.ndarray
    actuator_forcerange: np.ndarray

    @classmethod
    def of(cls, model: mujoco.MjModel) -> NominalModel:
        """Copies of the fields of `model` (call it before any domain parameters are applied)."""
        return cls(body_mass=model.body_mass.copy(), body_ipos=model.body_ipos.copy(),
                   body_inertia=model.body_inertia.copy(), geom_friction=model.geom_friction.copy(),
                   actuator_forcerange=model.actuator_forcerange.copy())


def payload_trunk_inertial(mass: float | np.ndarray, com: np.ndarray, payload_kg: float | np.ndarray,
                           payload_com: np.ndarray) -> tuple[float | np.ndarray, np.ndarray]:
    """The trunk's mass and centre of mass with a point payload added.

    Args:
        mass: trunk mass, scalar or (...) [kg].
        com: trunk centre of mass in the trunk frame, (..., 3) [m].
        payload_kg: payload mass, scalar or (...) [kg] (negative: a lighter trunk, its mass taken at `payload_com`).
        payload_com: payload position in the trunk frame, (..., 3) [m].

    Returns:
        ``m + payload`` and ``(m c + payload p) / (m + payload)``.
    """
    total = mass + payload_kg
    return total, (mass * com + np.asarray(payload_kg)[..., None] * payload_com) / np.asarray(total)[..., None]


def motor_strengths(motor_strength: float | np.ndarray, num_joints: int) -> np.ndarray:
    """Per-joint motor strength (num_joints,) from a scalar or per-joint value (a fresh array)."""
    return np.broadcast_to(np.asarray(motor_strength, dtype=np.float64), (num_joints,)).copy()


def apply_domain(model: mujoco.MjModel, data: mujoco.MjData, nominal: NominalModel, *, payload_kg: float,
                 payload_com: np.ndarray, friction: float, motor_strength: float | np.ndarray) -> np.ndarray:
    """Write domain parameters into `model`, on top of its nominal values, and recompute its constants.

    The payload is added to the trunk (`payload_trunk_inertial`; inertia is kept); `friction` is the sliding friction
    of every robot-ground contact (`set_ground_friction`); the motor strength scales each actuator's gain and torque
    limit (its bias, which holds kp and kd, is scaled by `set_motor_gains` when the gains are written). Both callers
    write the terrain first (`apply_terrain`), so that ``mj_setConst`` here is the last change to the model's
    constants.

    Args:
        model: the model to change.
        data: scratch data of `model` for ``mj_setConst`` (its state is overwritten).
        nominal: the fields as compiled.
        payload_kg: extra trunk mass [kg].
        payload_com: its position in the trunk frame, (3,) [m].
        friction: sliding friction coefficient.
        motor_strength: torque multiplier, a scalar or one per actuated joint.

    Returns:
        The per-joint motor strength (nu,).
    """
    b = base_body_id(model)
    model.body_mass[:] = nominal.body_mass
    model.body_ipos[:] = nominal.body_ipos
    model.body_inertia[:] = nominal.body_inertia
    if payload_kg != 0.0:  # no payload: the nominal values exactly, not a round trip through the formula
        model.body_mass[b], model.body_ipos[b] = payload_trunk_inertial(
            nominal.body_mass[b], nominal.body_ipos[b], payload_kg, payload_com)
    model.geom_friction[:] = nominal.geom_friction
    set_ground_friction(model, friction)
    k = motor_strengths(motor_strength, model.nu)
    model.actuator_forcerange[:] = nominal.actuator_forcerange * k[:, None]
    model.actuator_gainprm[:, 0] = k
    mujoco.mj_setConst(model, data)
    return k


# -- motor law ------------------------------------------------------------------------------------------------------
def set_motor_gains(model: mujoco.MjModel, strength: np.ndarray, kp: np.ndarray, kd: np.ndarray) -> None:
    """Write the motor law's gains into the actuators' bias: ``biasprm[:, 1:3] = (-k kp, -k kd)``.

    Args:
        model: the model.
        strength: (nu,) motor strength k.
        kp: (nu,) position gains [N m / rad].
        kd: (nu,) velocity gains [N m s / rad].
    """
    model.actuator_biasprm[:, 1] = -strength * kp
    model.actuator_biasprm[:, 2] = -strength * kd


def motor_ctrl(q: np.ndarray, dq: np.ndarray | float, tau: np.ndarray | float, kp: np.ndarray,
               kd: np.ndarray) -> np.ndarray:
    """The actuators' control of a motor command, ``kp q* + kd dq* + tau_ff``, broadcast over leading axes.

    Args:
        q: target positions, (..., nu) [rad].
        dq: target velocities, (..., nu) or a scalar [rad/s].
        tau: feed-forward torques, (..., nu) or a scalar [N m].
        kp: position gains, (..., nu) [N m / rad].
        kd: velocity gains, (..., nu) [N m s / rad].
    """
    return kp * q + kd * dq + tau


@numba.njit(cache=True, nogil=True)
def apply_motor_rows(rows: np.ndarray, strength: np.ndarray, biasprm: np.ndarray,
                     ctrl: np.ndarray) -> None:  # pragma: no cover - compiled
    """`set_motor_gains` and `motor_ctrl` of one command in one compiled call (the simulated robot's every write).

    Args:
        rows: the command's rows q, dq, kp, kd, tau, shape (5, nu) (`MotorCommand.rows`).
        strength: (nu,) motor strength k.
        biasprm: the model's ``actuator_biasprm`` (nu, 10), columns 1 and 2 written.
        ctrl: the data's ``ctrl`` (nu,), written.
    """
    for j in range(rows.shape[1]):
        kp, kd = rows[2, j], rows[3, j]
        biasprm[j, 1] = -strength[j] * kp
        biasprm[j, 2] = -strength[j] * kd
        ctrl[j] = kp * rows[0, j] + kd * rows[1, j] + rows[4, j]


# -- ground and spawn -----------------------------------------------------------------------------------------------
def ground_under_spawn(terrain: TerrainConfig, heights: np.ndarray) -> float:
    """Highest ground within `SPAWN_GROUND_HALF_WIDTH` of the origin (where robots spawn) [m].

    Args:
        terrain: the fractal's shape.
        heights: its normalised heights (`fractal_heights`).
    """
    c, r = heights.shape[0] // 2, int(round(SPAWN_GROUND_HALF_WIDTH / terrain.cell))
    return float(heights[c - r:c + r + 1, c - r:c + r + 1].max()) * terrain.amplitude


def apply_terrain(model: mujoco.MjModel, terrain: TerrainConfig, seed: int) -> float:
    """Fill a fractal scene's heightfield with the terrain of `seed`; returns `ground_under_spawn` (0 when flat) [m]."""
    if terrain.kind != "fractal":
        return 0.0
    heights = fractal_heights(terrain, seed)
    set_terrain_heights(model, heights)
    return ground_under_spawn(terrain, heights)


def spawn_height(stand_height: float, ground: float | np.ndarray) -> float | np.ndarray:
    """Trunk height at spawn: standing height above the ground plus `SPAWN_CLEARANCE` [m], scalar or batched."""
    return stand_height + ground + SPAWN_CLEARANCE


def initial_qpos(nq: int, base_height: float | np.ndarray, joint_q: np.ndarray) -> np.ndarray:
    """Spawn configurations: trunk level at the origin at `base_height`, joints at `joint_q`.

    Args:
        nq: configuration size of the model.
        base_height: trunk height, scalar or (...,) [m].
        joint_q: joint positions, (..., nu) [rad].

    Returns:
        (..., nq) configurations ``[0, 0, base_height, 1, 0, 0, 0, joint_q]``.
    """
    base_height, joint_q = np.asarray(base_height, dtype=np.float64), np.asarray(joint_q, dtype=np.float64)
    qpos = np.zeros((*np.broadcast_shapes(base_height.shape, joint_q.shape[:-1]), nq))
    qpos[..., 2] = base_height
    qpos[..., 3] = 1.0
    qpos[..., 7:] = joint_q
    return qpos


# -- delays --------------------------------------------------------------------------------------------------------
def delay_steps(delay_s: float, timestep: float) -> int:
    """A delay in whole physics steps: the nearest number, a half rounded up (0.003 s at 2 ms: 2 steps).

    A simulated robot can only hand a command to its motors, or take a sensor reading, at a physics step, so a
    delay is a whole number of steps. A tolerance of 1e-9 step keeps a delay written in decimal (0.003 s is
    1.4999999999999998 steps of 0.002 s in binary) on the side its decimal value lies.

    Args:
        delay_s: the delay [s], >= 0.
        timestep: physics step [s].
    """
    return int(math.floor(delay_s / timestep + 0.5 + 1e-9))


# -- pushes ---------------------------------------------------------------------------------------------------------
def push_steps(start_s: float, duration_s: float, timestep: float) -> tuple[int, int]:
    """The physics steps ``start <= k < stop`` a push acts on: its start rounded, and at least one step long.

    Args:
        start_s: the push's start [s].
        duration_s: how long it acts [s].
        timestep: physics step [s].
    """
    start = int(round(start_s / timestep))
    return start, start + max(1, int(round(duration_s / timestep)))


def push_wrench(force_in_world: np.ndarray, lever_arm_in_world: np.ndarray,
                active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Total force and torque about the trunk's centre of mass of the active pushes, for ``xfrc_applied``.

    Args:
        force_in_world: (..., P, 3) each push's force [N].
        lever_arm_in_world: (..., P, 3) from the trunk's centre of mass to each push's point [m].
        active: (..., P) whether each push acts (bool or 0/1).

    Returns:
        Force and torque, each (..., 3) [N], [N m]: the sums over active pushes of F and ``lever arm x F``.
    """
    act = np.asarray(active, dtype=np.float64)
    force = np.einsum("...p,...pk->...k", act, force_in_world)
    torque = np.einsum("...p,...pk->...k", act, np.cross(lever_arm_in_world, force_in_world))
    return force, torque


class PushTable:
    """The pushes of N robots at physics-step resolution, in arrays.

    Row i holds robot i's pushes in the order they were added: the physics steps they act on (`push_steps`), the
    force in the world frame and the application point in the trunk frame. The table grows to hold the longest row,
    so no push is ever dropped.

    Args:
        num_rows: robots.
        timestep: physics step [s].
        capacity: pushes per row allocated at first (more are added by growing the arrays).

    Attributes:
        start: (N, P) first physics step of each push (-1: empty slot).
        stop: (N, P) first physics step after it (-1: empty slot).
        force: (N, P, 3) force in the world frame [N].
        offset: (N, P, 3) application point in the trunk frame [m].
        count: (N,) pushes in each row.
    """

    def __init__(self, num_rows: int, timestep: float, capacity: int = 8) -> None:
        self.timestep = timestep
        self.start = np.full((num_rows, capacity), -1, dtype=np.int64)
        self.stop = np.full((num_rows, capacity), -1, dtype=np.int64)
        self.force = np.zeros((num_rows, capacity, 3))
        self.offset = np.zeros((num_rows, capacity, 3))
        self.count = np.zeros(num_rows, dtype=np.int64)

    @property
    def capacity(self) -> int:
        """Push slots per row."""
        return self.start.shape[1]

    def clear(self, row: int) -> None:
        """Remove every push of `row`."""
        self.start[row] = -1
        self.stop[row] = -1
        self.force[row] = 0.0
        self.offset[row] = 0.0
        self.count[row] = 0

    def add(self, row: int, push: Push) -> None:
        """Append `push` to `row` (growing the table when the row is full)."""
        k = int(self.count[row])
        if k == self.capacity:
            self._grow(max(1, 2 * self.capacity))
        self.start[row, k], self.stop[row, k] = push_steps(push.start, push.duration, self.timestep)
        self.force[row, k] = push.force_in_world
        self.offset[row, k] = push.offset_in_base
        self.count[row] = k + 1

    def set(self, row: int, pushes: Sequence[Push]) -> None:
        """Replace the pushes of `row` with `pushes`."""
        self.clear(row)
        for push in pushes:
            self.add(row, push)

    def active(self, step: np.ndarray) -> np.ndarray:
        """Whether each push acts at physics step `step`, (N,) or (N, T): returns (N, P) or (N, T, P) bool."""
        s = np.asarray(step)[..., None]
        shape = (self.start.shape[0],) + (1,) * (s.ndim - 2) + (self.capacity,)
        return (s >= self.start.reshape(shape)) & (s < self.stop.reshape(shape))

    def next_start(self, row: int, step: int) -> int | None:
        """The first physics step after `step` at which a push of `row` starts, or None."""
        later = self.start[row][self.start[row] > step]
        return int(later.min()) if later.size else None

    def force_at(self, step: np.ndarray) -> np.ndarray:
        """(N, 3) total push force acting at physics step `step` (N,) [N], world frame."""
        return np.einsum("np,npk->nk", self.active(step).astype(np.float64), self.force)

    def _grow(self, capacity: int) -> None:
        n, extra = self.start.shape[0], capacity - self.capacity
        self.start = np.concatenate([self.start, np.full((n, extra), -1, dtype=np.int64)], axis=1)
        self.stop = np.concatenate([self.stop, np.full((n, extra), -1, dtype=np.int64)], axis=1)
        self.force = np.concatenate([self.force, np.zeros((n, extra, 3))], axis=1)
        self.offset = np.concatenate([self.offset, np.zeros((n, extra, 3))], axis=1)
