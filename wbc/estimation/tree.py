"""The robot's kinematic tree, compiled (numba): one pass per control tick, and the placement at the base's state.

`TreeModel` is the kinematic tree of a Pinocchio model with revolute joints on a free-flying base, as flat arrays the
compiled code reads (built once per robot model); `tree_pass` computes, with the base at the origin and at rest (only
its orientation and angular velocity set), what `wbc.estimation.kinematics.RobotKinematics.tick` needs: the base's
rotation matrix, feet and hips relative to the base, the feet's velocities relative to the base (of the foot frames,
and of the points in contact below each rolling foot sphere), the leg Jacobians and the joints' gravity torques. Its
results equal Pinocchio's (`computeJointJacobians`, frame Jacobians in LOCAL_WORLD_ALIGNED,
`computeGeneralizedGravity`) to rounding; the tests check that on every robot. `place` puts that configuration at
the base's estimated (or true) position and velocity.

`packed_pass` and `packed_place` are the same two on packed arrays: the model and `tree_pass`'s constants in two
(`TreeModel.packed`, `model_arrays`), every per-tick input and output in one buffer (`tick_arrays`). A compiled call
costs ~0.15 us for each array it is handed; the tick is handed three instead of twenty-five, and a caller that
compiles the pass into a larger call (the MPC controller's tick) hands it the same three.

Compiled functions are cached on disk beside this module (numba's ``cache=True``): a process compiles them once per
machine, later processes load them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
import pinocchio as pin

from wbc.errors import ConfigError

__all__ = ["TICK_FIXED", "TreeModel", "model_arrays", "packed_pass", "packed_place", "place", "rotation_of",
           "tick_arrays", "tick_buffer_size", "tree_pass"]

_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class TreeModel:
    """A Pinocchio model's joints below its free-flyer, as arrays in Pinocchio's (topological) joint order.

    Joint k here is Pinocchio joint k + 2 (0 is the universe, 1 the free-flyer).

    Attributes:
        parent: each joint's parent, -1 for the base (nj,).
        rot: each joint's placement in its parent's frame, rotation (nj, 3, 3).
        pos: the same, translation (nj, 3) [m].
        axis: each joint's rotation axis in its own frame, unit (nj, 3).
        mass: the mass moved by each joint alone (its body and the fixed bodies merged into it) (nj,) [kg].
        com: that mass's centre in the joint's frame (nj, 3) [m].
        foot_joint: the joint each foot frame hangs from (4,).
        foot_pos: each foot frame's origin in its joint's frame (4, 3) [m].
        hip_joint: each leg's thigh joint (4,).
        leg_joints: each leg's hip, thigh and calf joints (4, 3).
        foot_radius: each foot's sphere radius (4,) [m]: its point in contact is that far below the foot frame.
    """

    parent: np.ndarray
    rot: np.ndarray
    pos: np.ndarray
    axis: np.ndarray
    mass: np.ndarray
    com: np.ndarray
    foot_joint: np.ndarray
    foot_pos: np.ndarray
    hip_joint: np.ndarray
    leg_joints: np.ndarray
    foot_radius: np.ndarray

    @classmethod
    def of(cls, model: pin.Model, foot_frames: list[str], thigh_joints: list[str], leg_joints: np.ndarray,
           foot_radius: np.ndarray | None = None) -> TreeModel:
        """Flatten `model` (a free-flyer, then revolute joints about x, y or z).

        Args:
            model: the Pinocchio model.
            foot_frames: the four foot frames' names.
            thigh_joints: the four thigh joints' names.
            leg_joints: each leg's hip, thigh and calf as Pinocchio joint indices minus 2 (4, 3).
            foot_radius: each foot's sphere radius (4,) [m] (None: 0, a point foot).

        Raises:
            ConfigError: the model's root is not a free-flyer, a joint is not revolute about a frame axis, or a foot
                radius is negative.
        """
        radius = np.zeros(4) if foot_radius is None else np.array(foot_radius, dtype=np.float64).reshape(4)
        if not np.all(radius >= 0.0):
            raise ConfigError(f"TreeModel: foot radii must be >= 0, got {radius.tolist()}")
        if model.joints[1].shortname() != "JointModelFreeFlyer":
            raise ConfigError(f"TreeModel: joint 1 of model {model.name!r} is {model.joints[1].shortname()}, not the "
                              "free-flyer the compiled kinematics expect")
        nj = model.njoints - 2
        parent = np.empty(nj, dtype=np.int64)
        rot, pos = np.empty((nj, 3, 3)), np.empty((nj, 3))
        axis, mass, com = np.empty((nj, 3)), np.empty(nj), np.empty((nj, 3))
        for k in range(nj):
            j = k + 2
            kind = model.joints[j].shortname()
            if kind not in _AXES:
                raise ConfigError(f"TreeModel: joint {model.names[j]!r} of model {model.name!r} is {kind}; the "
                                  f"compiled kinematics handle revolute joints about a frame axis ({', '.join(_AXES)})")
            parent[k] = model.parents[j] - 2
            rot[k] = model.jointPlacements[j].rotation
            pos[k] = model.jointPlacements[j].translation
            axis[k] = _AXES[kind]
            mass[k] = model.inertias[j].mass
            com[k] = model.inertias[j].lever
        frames = [model.frames[model.getFrameId(name)] for name in foot_frames]
        return cls(parent=parent, rot=rot, pos=pos, axis=axis, mass=mass, com=com,
                   foot_joint=np.array([f.parentJoint - 2 for f in frames], dtype=np.int64),
                   foot_pos=np.array([f.placement.translation for f in frames]),
                   hip_joint=np.array([model.getJointId(n) - 2 for n in thigh_joints], dtype=np.int64),
                   leg_joints=np.ascontiguousarray(leg_joints, dtype=np.int64), foot_radius=radius)

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The model's arrays in the order `tree_pass` takes them (parent to foot_radius, as the attributes)."""
        return (self.parent, self.rot, self.pos, self.axis, self.mass, self.com, self.foot_joint, self.foot_pos,
                self.hip_joint, self.leg_joints, self.foot_radius)

    def packed(self, perm: np.ndarray, gravity_z: float) -> tuple[np.ndarray, np.ndarray]:
        """The model with `tree_pass`'s other constants as two flat arrays, which `model_arrays` reads back.

        A compiled call costs ~0.15 us per array it is handed (numba wraps each one on the way in): two arrays
        instead of twelve.

        Args:
            perm: the house index of each tree joint (nj,).
            gravity_z: the gravity's z component [m/s^2].

        Returns:
            floats (gravity_z, rot, pos, axis, mass, com, foot_pos, foot_radius, each flattened) and ints (nj, perm,
            parent, foot_joint, hip_joint, leg_joints).
        """
        floats = np.concatenate([[gravity_z], self.rot.ravel(), self.pos.ravel(), self.axis.ravel(), self.mass,
                                 self.com.ravel(), self.foot_pos.ravel(), self.foot_radius]).astype(np.float64)
        ints = np.concatenate([[self.parent.size], np.asarray(perm).ravel(), self.parent, self.foot_joint,
                               self.hip_joint, self.leg_joints.ravel()]).astype(np.int64)
        return floats, ints


@numba.njit(cache=True, nogil=True)
def model_arrays(floats, ints):  # pragma: no cover
    """`TreeModel.packed`'s two arrays as the views `tree_pass` takes, in its order (perm to foot_radius)."""
    nj = ints[0]
    perm = ints[1:1 + nj]
    parent = ints[1 + nj:1 + 2 * nj]
    foot_joint = ints[1 + 2 * nj:5 + 2 * nj]
    hip_joint = ints[5 + 2 * nj:9 + 2 * nj]
    leg_joints = ints[9 + 2 * nj:21 + 2 * nj].reshape((4, 3))
    o = 1
    rot = floats[o:o + 9 * nj].reshape((nj, 3, 3))
    o += 9 * nj
    pos = floats[o:o + 3 * nj].reshape((nj, 3))
    o += 3 * nj
    axis = floats[o:o + 3 * nj].reshape((nj, 3))
    o += 3 * nj
    mass = floats[o:o + nj]
    o += nj
    com = floats[o:o + 3 * nj].reshape((nj, 3))
    o += 3 * nj
    foot_pos = floats[o:o + 12].reshape((4, 3))
    o += 12
    foot_radius = floats[o:o + 4]
    return perm, floats[0], parent, rot, pos, axis, mass, com, foot_joint, foot_pos, hip_joint, leg_joints, foot_radius


TICK_FIXED = 135
"""Entries of a tick buffer (`tick_arrays`) before its three joint-sized arrays."""


def tick_buffer_size(n: int) -> int:
    """Length of the tick buffer of a robot with `n` joints (`tick_arrays`)."""
    return TICK_FIXED + n + (7 + n) + (6 + n)


@numba.njit(cache=True, nogil=True)
def tick_arrays(buf):  # pragma: no cover
    """The per-tick arrays of the kinematics as views of one buffer of `tick_buffer_size` (n joints) entries.

    In order: rot_base (3, 3), q_pin (7 + n), v_pin (6 + n), feet_rel, hips_rel, feet_vel_rel (4, 3), leg_jac
    (4, 3, 3), gravity (n), omega_world (3), contact_vel_rel (4, 3) (`tree_pass`'s outputs, in its order), then
    com_in_base (3), base_position, base_velocity (3), feet, feet_vel (4, 3), com, com_vel (3) (`place`'s inputs and
    outputs).
    `wbc.estimation.kinematics.RobotKinematics` keeps these views as its attributes, so one compiled call reads
    and writes all of them through one array.
    """
    rot_base = buf[0:9].reshape((3, 3))
    feet_rel = buf[9:21].reshape((4, 3))
    hips_rel = buf[21:33].reshape((4, 3))
    feet_vel_rel = buf[33:45].reshape((4, 3))
    leg_jac = buf[45:81].reshape((4, 3, 3))
    omega_world = buf[81:84]
    com_in_base = buf[84:87]
    base_position = buf[87:90]
    base_velocity = buf[90:93]
    feet = buf[93:105].reshape((4, 3))
    feet_vel = buf[105:117].reshape((4, 3))
    com = buf[117:120]
    com_vel = buf[120:123]
    contact_vel_rel = buf[123:135].reshape((4, 3))
    n = (buf.shape[0] - TICK_FIXED - 13) // 3
    gravity = buf[135:135 + n]
    q_pin = buf[135 + n:142 + 2 * n]
    v_pin = buf[142 + 2 * n:148 + 3 * n]
    return (rot_base, q_pin, v_pin, feet_rel, hips_rel, feet_vel_rel, leg_jac, gravity, omega_world, com_in_base,
            base_position, base_velocity, feet, feet_vel, com, com_vel, contact_vel_rel)


@numba.njit(cache=True, nogil=True)
def rotation_of(quat, rot):  # pragma: no cover
    """The rotation matrix (body to world) of a unit quaternion (w, x, y, z) into `rot` (3, 3).

    The formula and operation order of `wbc.robots.conventions.quat_to_matrix`, so the same bits.
    """
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    rot[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    rot[0, 1] = 2.0 * (x * y - w * z)
    rot[0, 2] = 2.0 * (x * z + w * y)
    rot[1, 0] = 2.0 * (x * y + w * z)
    rot[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    rot[1, 2] = 2.0 * (y * z - w * x)
    rot[2, 0] = 2.0 * (x * z - w * y)
    rot[2, 1] = 2.0 * (y * z + w * x)
    rot[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@numba.njit(cache=True, fastmath=False, nogil=True)
def tree_pass(base_quat, omega_body, q_house, dq_house, perm, gravity_z, parent, rot, pos, axis, mass, com,
              foot_joint, foot_pos, hip_joint, leg_joints, foot_radius, rot_base, q_pin, v_pin, feet_rel, hips_rel,
              feet_vel_rel, leg_jac, gravity_house, omega_world, contact_vel_rel):  # pragma: no cover
    """One kinematics pass with the base at the origin and at rest, into the output arrays.

    Args:
        base_quat: base orientation (w, x, y, z).
        omega_body: base angular velocity, body frame (3,) [rad/s].
        q_house: joint positions, house order (n,) [rad].
        dq_house: joint velocities, house order (n,) [rad/s].
        perm: the house index of each tree joint (n,).
        gravity_z: the gravity's z component [m/s^2] (negative).
        parent: the model (`TreeModel`, in the order of `TreeModel.arrays`): each joint's parent.
        rot: each joint's placement rotation.
        pos: each joint's placement translation.
        axis: each joint's axis.
        mass: the mass each joint moves alone.
        com: that mass's centre.
        foot_joint: each foot's joint.
        foot_pos: each foot in its joint's frame.
        hip_joint: each leg's thigh joint.
        leg_joints: each leg's three joints.
        foot_radius: each foot's sphere radius.
        rot_base: out, the rotation matrix of `base_quat` (3, 3).
        q_pin: out, Pinocchio's configuration: its rows from 3 on are written (the base position is left alone).
        v_pin: out, Pinocchio's velocity: its rows from 3 on are written.
        feet_rel: out, feet relative to the base, world axes (4, 3) [m].
        hips_rel: out, thigh joints relative to the base, world axes (4, 3) [m].
        feet_vel_rel: out, feet velocities relative to the base, omega x r + J dq (4, 3) [m/s].
        leg_jac: out, d foot / d (hip, thigh, calf) per leg, world axes (4, 3, 3) [m/rad].
        gravity_house: out, each joint's generalized gravity, house order (n,) [N m].
        omega_world: out, the base's angular velocity in the world (3,) [rad/s].
        contact_vel_rel: out, relative to the base, the velocity of the point of each foot's sphere right below its
            centre, fixed to the foot (feet_vel_rel + omega_foot x (0, 0, -radius)), world axes (4, 3) [m/s]: zero
            relative to the ground for a foot that rolls without slipping, where the foot frame moves.
    """
    rotation_of(base_quat, rot_base)
    nj = q_house.shape[0]
    # Pinocchio's configuration and velocity (base at the origin, at rest but for its rotation), tree order
    q = np.empty(nj)
    dq = np.empty(nj)
    for k in range(nj):
        q[k] = q_house[perm[k]]
        dq[k] = dq_house[perm[k]]
        q_pin[7 + k] = q[k]
        v_pin[6 + k] = dq[k]
    q_pin[3], q_pin[4], q_pin[5], q_pin[6] = base_quat[1], base_quat[2], base_quat[3], base_quat[0]
    v_pin[3], v_pin[4], v_pin[5] = omega_body[0], omega_body[1], omega_body[2]
    gravity = np.empty(nj)
    wr = np.empty((nj, 3, 3))  # joint frames in the world (base at the origin)
    wp = np.empty((nj, 3))
    wa = np.empty((nj, 3))  # joint axes in the world
    wc = np.empty((nj, 3))  # the joints' own mass centres in the world
    pre = np.empty((3, 3))
    jr = np.empty((3, 3))
    for k in range(nj):
        par = parent[k]
        # frame of the joint before its rotation: the parent's frame times the placement
        pr = rot_base if par < 0 else wr[par]
        for a in range(3):
            origin = 0.0 if par < 0 else wp[par, a]
            wp[k, a] = origin + pr[a, 0] * pos[k, 0] + pr[a, 1] * pos[k, 1] + pr[a, 2] * pos[k, 2]
            for b in range(3):
                pre[a, b] = pr[a, 0] * rot[k, 0, b] + pr[a, 1] * rot[k, 1, b] + pr[a, 2] * rot[k, 2, b]
        # the joint's rotation about its axis (Rodrigues), then the frame after it
        ux, uy, uz = axis[k, 0], axis[k, 1], axis[k, 2]
        c, s = math.cos(q[k]), math.sin(q[k])
        t = 1.0 - c
        jr[0, 0] = c + ux * ux * t
        jr[0, 1] = ux * uy * t - uz * s
        jr[0, 2] = ux * uz * t + uy * s
        jr[1, 0] = uy * ux * t + uz * s
        jr[1, 1] = c + uy * uy * t
        jr[1, 2] = uy * uz * t - ux * s
        jr[2, 0] = uz * ux * t - uy * s
        jr[2, 1] = uz * uy * t + ux * s
        jr[2, 2] = c + uz * uz * t
        for a in range(3):
            wa[k, a] = pre[a, 0] * ux + pre[a, 1] * uy + pre[a, 2] * uz
            for b in range(3):
                wr[k, a, b] = pre[a, 0] * jr[0, b] + pre[a, 1] * jr[1, b] + pre[a, 2] * jr[2, b]
        for a in range(3):
            wc[k, a] = wp[k, a] + wr[k, a, 0] * com[k, 0] + wr[k, a, 1] * com[k, 1] + wr[k, a, 2] * com[k, 2]
    # gravity: each joint holds the first moment of the mass below it about its axis; a backward pass sums them
    sub_m = mass.copy()
    sub_s = np.empty((nj, 3))
    for k in range(nj):
        for a in range(3):
            sub_s[k, a] = mass[k] * wc[k, a]
    for k in range(nj - 1, -1, -1):
        par = parent[k]
        if par >= 0:
            sub_m[par] += sub_m[k]
            for a in range(3):
                sub_s[par, a] += sub_s[k, a]
    for k in range(nj):
        # (S - M p) x (0, 0, gz) = (gz ry, -gz rx, 0); the generalized gravity is minus its component on the axis
        rx = sub_s[k, 0] - sub_m[k] * wp[k, 0]
        ry = sub_s[k, 1] - sub_m[k] * wp[k, 1]
        gravity[k] = -(wa[k, 0] * gravity_z * ry - wa[k, 1] * gravity_z * rx)
    # the base's angular velocity in the world
    wx = rot_base[0, 0] * omega_body[0] + rot_base[0, 1] * omega_body[1] + rot_base[0, 2] * omega_body[2]
    wy = rot_base[1, 0] * omega_body[0] + rot_base[1, 1] * omega_body[1] + rot_base[1, 2] * omega_body[2]
    wz = rot_base[2, 0] * omega_body[0] + rot_base[2, 1] * omega_body[1] + rot_base[2, 2] * omega_body[2]
    omega_world[0], omega_world[1], omega_world[2] = wx, wy, wz
    for k in range(nj):
        gravity_house[perm[k]] = gravity[k]
    for i in range(4):
        j = foot_joint[i]
        for a in range(3):
            feet_rel[i, a] = (wp[j, a] + wr[j, a, 0] * foot_pos[i, 0] + wr[j, a, 1] * foot_pos[i, 1]
                              + wr[j, a, 2] * foot_pos[i, 2])
            hips_rel[i, a] = wp[hip_joint[i], a]
        fx, fy, fz = feet_rel[i, 0], feet_rel[i, 1], feet_rel[i, 2]
        vx = wy * fz - wz * fy
        vy = wz * fx - wx * fz
        vz = wx * fy - wy * fx
        ox, oy, oz = wx, wy, wz  # the foot's angular velocity: the base's plus its leg joints'
        for m in range(3):
            k = leg_joints[i, m]
            # d foot / d q_k = a_k x (foot - p_k)
            dx, dy, dz = fx - wp[k, 0], fy - wp[k, 1], fz - wp[k, 2]
            jx = wa[k, 1] * dz - wa[k, 2] * dy
            jy = wa[k, 2] * dx - wa[k, 0] * dz
            jz = wa[k, 0] * dy - wa[k, 1] * dx
            leg_jac[i, 0, m] = jx
            leg_jac[i, 1, m] = jy
            leg_jac[i, 2, m] = jz
            vx += jx * dq[k]
            vy += jy * dq[k]
            vz += jz * dq[k]
            ox += wa[k, 0] * dq[k]
            oy += wa[k, 1] * dq[k]
            oz += wa[k, 2] * dq[k]
        feet_vel_rel[i, 0] = vx
        feet_vel_rel[i, 1] = vy
        feet_vel_rel[i, 2] = vz
        # omega x (0, 0, -r) = (-r oy, r ox, 0)
        r = foot_radius[i]
        contact_vel_rel[i, 0] = vx - r * oy
        contact_vel_rel[i, 1] = vy + r * ox
        contact_vel_rel[i, 2] = vz


@numba.njit(cache=True, nogil=True)
def place(feet_rel, feet_vel_rel, rot_base, com_in_base, omega_world, position, velocity, base_position, base_velocity,
          feet, feet_vel, com, com_vel):  # pragma: no cover
    """Put a tick's base-relative kinematics at a base position and velocity (world), into the six outputs.

    base_position = p, base_velocity = v, feet = r + p, feet_vel = v_rel + v, com = p + R c, com_vel = v + omega x
    (R c), with c the CoM in the trunk frame.
    """
    for a in range(3):
        base_position[a] = position[a]
        base_velocity[a] = velocity[a]
    for i in range(4):
        for a in range(3):
            feet[i, a] = feet_rel[i, a] + position[a]
            feet_vel[i, a] = feet_vel_rel[i, a] + velocity[a]
    r = np.empty(3)
    for a in range(3):
        r[a] = rot_base[a, 0] * com_in_base[0] + rot_base[a, 1] * com_in_base[1] + rot_base[a, 2] * com_in_base[2]
        com[a] = position[a] + r[a]
    wx, wy, wz = omega_world[0], omega_world[1], omega_world[2]
    com_vel[0] = velocity[0] + wy * r[2] - wz * r[1]
    com_vel[1] = velocity[1] + wz * r[0] - wx * r[2]
    com_vel[2] = velocity[2] + wx * r[1] - wy * r[0]


@numba.njit(cache=True, nogil=True)
def packed_pass(base_quat, omega_body, q_house, dq_house, model_f, model_i, buf):  # pragma: no cover
    """`tree_pass` on a packed model (`TreeModel.packed`) into a tick buffer (`tick_arrays`)."""
    (rot_base, q_pin, v_pin, feet_rel, hips_rel, feet_vel_rel, leg_jac, gravity, omega_world, _, _, _, _, _, _,
     _, contact_vel_rel) = tick_arrays(buf)
    (perm, gravity_z, parent, rot, pos, axis, mass, com, foot_joint, foot_pos, hip_joint,
     leg_joints, foot_radius) = model_arrays(model_f, model_i)
    tree_pass(base_quat, omega_body, q_house, dq_house, perm, gravity_z, parent, rot, pos, axis, mass, com,
              foot_joint, foot_pos, hip_joint, leg_joints, foot_radius, rot_base, q_pin, v_pin, feet_rel, hips_rel,
              feet_vel_rel, leg_jac, gravity, omega_world, contact_vel_rel)


@numba.njit(cache=True, nogil=True)
def packed_place(buf, position, velocity):  # pragma: no cover
    """`place` on a tick buffer (`tick_arrays`)."""
    (rot_base, _, _, feet_rel, _, feet_vel_rel, _, _, omega_world, com_in_base, base_position, base_velocity, feet,
     feet_vel, com, com_vel, _) = tick_arrays(buf)
    place(feet_rel, feet_vel_rel, rot_base, com_in_base, omega_world, position, velocity, base_position,
          base_velocity, feet, feet_vel, com, com_vel)
