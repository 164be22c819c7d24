"""Observations of the learned policies, computed the same way in the batched env and on the robot.

The policy observation (the paper's O_quadruped, plus O_arm when the arm is actuated) is, in this order:

    ang_vel      gyro in the body frame x 0.25                        (3)
    gravity      unit gravity direction in the body frame             (3)
    command      (vx, vy, yaw rate) x (2, 2, 0.25)                    (3)
    dof_pos      q - q_default of the actuated joints                 (n)
    dof_vel      dq x 0.05                                            (n)
    last_action  the previous policy output                           (n)

with n = 12 (arm absent or locked) or 15 (arm actuated). Everything in it comes from `RobotState` (joint encoders and
IMU) and the operator's command: no base linear velocity. The privileged observation (the paper's O_privileged, for
the RMA encoder and the critic) holds what only a simulator knows: payload mass, friction, motor strength, base
linear velocity and the external push force.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.errors import ConfigError

__all__ = [
    "OBS_TERM_NAMES",
    "ObsLayout", "ObsScales", "PRIVILEGED_PARTS", "compatible_indices", "compatible_observation", "policy_observation",
    "privileged_observation", "projected_gravity",
]


@dataclass(frozen=True, kw_only=True)
class ObsScales:
    """Multipliers applied to observation parts (legged_gym's)."""

    ang_vel: float = 0.25
    dof_pos: float = 1.0
    dof_vel: float = 0.05
    command: tuple[float, float, float] = (2.0, 2.0, 0.25)


PRIVILEGED_PARTS: tuple[tuple[str, int], ...] = (
    ("payload_kg", 1), ("friction", 1), ("motor_strength", 1), ("base_linvel_in_body", 3), ("push_force_in_body", 3),
)
"""Parts of the privileged observation, in order; the push force is in units of 100 N."""


OBS_TERM_NAMES: dict[str, str] = {
    "ang_vel": "base_ang_vel", "gravity": "projected_gravity", "command": "velocity_commands",
    "dof_pos": "joint_pos_rel", "dof_vel": "joint_vel", "last_action": "last_action",
}
"""Each part of `ObsLayout` by the name trainers give that observation term (Isaac Lab's, as ONNX I/O files and replay
files name them, `wbc.control.onnx_io.TERMS`)."""


@dataclass(frozen=True)
class ObsLayout:
    """Named parts of a policy observation vector.

    Attributes:
        num_joints: actuated joints (12 or 15).
    """

    num_joints: int

    @property
    def parts(self) -> tuple[tuple[str, int], ...]:
        """(name, size) of each part, in order."""
        n = self.num_joints
        return (("ang_vel", 3), ("gravity", 3), ("command", 3), ("dof_pos", n), ("dof_vel", n), ("last_action", n))

    @property
    def size(self) -> int:
        """Length of the observation vector."""
        return sum(s for _, s in self.parts)

    def term_slices(self) -> tuple[tuple[str, int, int], ...]:
        """(term name, start, stop) of each part, named as `OBS_TERM_NAMES` says, in order."""
        out, at = [], 0
        for name, size in self.parts:
            out.append((OBS_TERM_NAMES[name], at, at + size))
            at += size
        return tuple(out)

    def as_list(self) -> list[list[str | int]]:
        """JSON-friendly form: ``[[name, size], ...]``."""
        return [[name, size] for name, size in self.parts]


def projected_gravity(quat_wxyz: np.ndarray) -> np.ndarray:
    """Unit gravity (0, 0, -1) in the body frame, R^T g, for quaternions of shape (..., 4) (body to world).

    One quaternion (a robot's tick) is computed on Python floats: the same operations in the same order as the
    arrays' path, the same bits, without a dozen numpy calls on arrays of one element.
    """
    q = np.asarray(quat_wxyz)
    if q.size == 4 and q.dtype == np.float64:
        w, x, y, z = q.reshape(4).tolist()
        row = [-(2 * (x * z - w * y)), -(2 * (y * z + w * x)), -(1 - 2 * (x * x + y * y))]
        return np.array(row, dtype=np.float64).reshape(q.shape[:-1] + (3,))
    w, x, y, z = (quat_wxyz[..., i] for i in range(4))
    # third row of R, negated: R^T (0, 0, -1) = -(R[2, 0], R[2, 1], R[2, 2])
    return -np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)


def policy_observation(
    *,
    gyro_in_body: np.ndarray,
    imu_quat: np.ndarray,
    command: np.ndarray,
    q: np.ndarray,
    dq: np.ndarray,
    last_action: np.ndarray,
    default_q: np.ndarray,
    scales: ObsScales,
) -> np.ndarray:
    """The policy observation of `ObsLayout`, batched over the leading axis.

    Args:
        gyro_in_body: (N, 3) [rad/s].
        imu_quat: (N, 4) (w, x, y, z), body to world.
        command: (N, 3) (vx [m/s], vy [m/s], yaw rate [rad/s]).
        q: (N, n) joint positions [rad].
        dq: (N, n) joint velocities [rad/s].
        last_action: (N, n) previous actions.
        default_q: (n,) joint positions the actions are offsets from [rad].
        scales: observation scales.

    Returns:
        (N, 9 + 3 n) float32.
    """
    return np.concatenate([
        gyro_in_body * scales.ang_vel,
        projected_gravity(imu_quat),
        command * np.asarray(scales.command),
        (q - default_q) * scales.dof_pos,
        dq * scales.dof_vel,
        last_action,
    ], axis=-1).astype(np.float32)


def privileged_observation(
    *,
    payload_kg: np.ndarray,
    friction: np.ndarray,
    motor_strength: np.ndarray,
    base_linvel_in_body: np.ndarray,
    push_force_in_body: np.ndarray,
) -> np.ndarray:
    """The privileged observation of `PRIVILEGED_PARTS`, batched: (N,), (N,), (N,), (N, 3), (N, 3) -> (N, 9)."""
    return np.concatenate([
        payload_kg[:, None], friction[:, None], motor_strength[:, None], base_linvel_in_body,
        push_force_in_body / 100.0,
    ], axis=-1).astype(np.float32)


def compatible_indices(source: ObsLayout, target: ObsLayout) -> np.ndarray:
    """Indices into a `source` observation of each entry of the `target` (fewer joints) observation.

    Joint parts keep their first ``target.num_joints`` entries (the legs); the other parts are taken whole.

    Raises:
        ConfigError: `target` has more joints than `source`.
    """
    if target.num_joints > source.num_joints:
        raise ConfigError(f"a {target.num_joints}-joint observation cannot be taken from a "
                          f"{source.num_joints}-joint one")
    pieces, at = [], 0
    for (_, size), (_, keep) in zip(source.parts, target.parts, strict=True):
        pieces.append(np.arange(at, at + keep))
        at += size
    return np.concatenate(pieces)


def compatible_observation(obs: np.ndarray, source: ObsLayout, target: ObsLayout) -> np.ndarray:
    """The part of `obs` (N, source.size) that a policy with layout `target` (fewer joints) observes."""
    return obs[:, compatible_indices(source, target)]
