"""The control tick's arithmetic, compiled (numba): kinematics, gait clock, trust, footholds, legs, command rows.

At 500 Hz the tick is a few hundred small operations on 3-vectors and 3 x 3 matrices; as numpy calls each costs a
microsecond or more of Python and numpy dispatch, which is most of the tick. Compiled, the same arithmetic is a few
microseconds in all. Each function here is one call from Python per tick, writing into arrays its caller allocated
once. Where a law is also written in Python (`wbc.robots.conventions.quat_to_matrix`, the gait's per-time queries),
the kernel performs the same floating-point operations in the same order, so the two agree to the bit.

`TreeModel` is the kinematic tree of a Pinocchio model with revolute joints on a free-flying base, as flat arrays the
compiled code reads (built once per controller); `tree_pass` computes, with the base at the origin and at rest
(only its orientation and angular velocity set), what `wbc.mpc.kinematics.RobotKinematics.tick` needs: the base's
rotation matrix, feet and hips relative to the base, the feet's velocities relative to the base, the leg Jacobians
and the joints' gravity torques. Its results equal Pinocchio's (`computeJointJacobians`, frame Jacobians in
LOCAL_WORLD_ALIGNED, `computeGeneralizedGravity`) to rounding; the tests check that on every robot.

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
from wbc.robots.conventions import G

__all__ = ["FOOTHOLD_CLIP_MARGIN", "TreeModel", "command_rows", "contact_trust", "gait_state", "leg_torques",
           "liftoffs", "place", "plan_footholds", "rotation_of", "swing_targets", "tree_pass"]

FOOTHOLD_CLIP_MARGIN = 1e-9
"""Relative margin below the largest foothold offset inside which `plan_footholds` needs no norm [1].

Far above the rounding of a squared norm (~1e-16), so an offset inside it is inside the limit whatever the norm's
last bit: only offsets near or past the limit are left for Python's `math.hypot` (the clip's norm; the compiled
libm ``hypot`` differs from it in the last bit on ~0.6 % of inputs)."""

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

    @classmethod
    def of(cls, model: pin.Model, foot_frames: list[str], thigh_joints: list[str], leg_joints: np.ndarray) -> TreeModel:
        """Flatten `model` (a free-flyer, then revolute joints about x, y or z).

        Args:
            model: the Pinocchio model.
            foot_frames: the four foot frames' names.
            thigh_joints: the four thigh joints' names.
            leg_joints: each leg's hip, thigh and calf as Pinocchio joint indices minus 2 (4, 3).

        Raises:
            ConfigError: the model's root is not a free-flyer, or a joint is not revolute about a frame axis.
        """
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
                   leg_joints=np.ascontiguousarray(leg_joints, dtype=np.int64))

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The model's arrays in the order `tree_pass` takes them (parent to leg_joints, as the attributes)."""
        return (self.parent, self.rot, self.pos, self.axis, self.mass, self.com, self.foot_joint, self.foot_pos,
                self.hip_joint, self.leg_joints)


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
              foot_joint, foot_pos, hip_joint, leg_joints, rot_base, q_pin, v_pin, feet_rel, hips_rel, feet_vel_rel,
              leg_jac, gravity_house, omega_world):  # pragma: no cover
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
        rot_base: out, the rotation matrix of `base_quat` (3, 3).
        q_pin: out, Pinocchio's configuration: its rows from 3 on are written (the base position is left alone).
        v_pin: out, Pinocchio's velocity: its rows from 3 on are written.
        feet_rel: out, feet relative to the base, world axes (4, 3) [m].
        hips_rel: out, thigh joints relative to the base, world axes (4, 3) [m].
        feet_vel_rel: out, feet velocities relative to the base, omega x r + J dq (4, 3) [m/s].
        leg_jac: out, d foot / d (hip, thigh, calf) per leg, world axes (4, 3, 3) [m/rad].
        gravity_house: out, each joint's generalized gravity, house order (n,) [N m].
        omega_world: out, the base's angular velocity in the world (3,) [rad/s].
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
        feet_vel_rel[i, 0] = vx
        feet_vel_rel[i, 1] = vy
        feet_vel_rel[i, 2] = vz


@numba.njit(cache=True, nogil=True)
def leg_torques(leg_jac, gravity, feet, feet_vel, stance, forces, swing_pos, swing_vel, swing_kp, swing_kd,
                stance_kd, limit, scale, tau):  # pragma: no cover
    """The leg-level layer's arithmetic (see `wbc.mpc.leg_layer`), into `tau` (n,) and `scale` (4,).

    Stance legs push -f - stance_kd v_foot, swing legs pull kp (p_des - p) + kd (v_des - v), both through J^T, on top
    of gravity; a stance leg whose torques would pass a limit has its push scaled down along its own direction until
    every joint is within (0 where even the gravity torques alone pass it).
    """
    for j in range(tau.shape[0]):
        tau[j] = gravity[j]
    cart = np.empty(3)
    legs = np.empty(3)
    for i in range(4):
        for a in range(3):
            if stance[i]:
                cart[a] = -forces[i, a] - stance_kd * feet_vel[i, a]
            else:
                cart[a] = swing_kp * (swing_pos[i, a] - feet[i, a]) + swing_kd * (swing_vel[i, a] - feet_vel[i, a])
        over = False
        for m in range(3):
            legs[m] = leg_jac[i, 0, m] * cart[0] + leg_jac[i, 1, m] * cart[1] + leg_jac[i, 2, m] * cart[2]
            if abs(legs[m] + gravity[3 * i + m]) > limit[3 * i + m]:
                over = True
        s = 1.0
        if over and stance[i]:
            for m in range(3):
                push, hold, lim = legs[m], gravity[3 * i + m], limit[3 * i + m]
                if abs(push) > 1e-9:
                    room = lim - hold if push > 0.0 else -lim - hold
                    s = min(s, room / push)
            s = min(max(s, 0.0), 1.0)
        scale[i] = s
        for m in range(3):
            tau[3 * i + m] += s * legs[m]


@numba.njit(cache=True, nogil=True)
def contact_trust(contact, foot_force, feet_vel_rel, vx, vy, inv_force, slip2, trust, slipping):  # pragma: no cover
    """How much the estimator trusts each foot as a stance foot, into `trust` (4,) and `slipping` (4,).

    A scheduled stance foot is trusted in proportion to its force sensor (fully from 1 / `inv_force` newtons); one
    whose world velocity at the base velocity (vx, vy) is faster than sqrt(`slip2`) slides and is not trusted.
    """
    for i in range(4):
        w = min(max(foot_force[i] * inv_force, 0.0), 1.0) if contact[i] else 0.0
        fx, fy = feet_vel_rel[i, 0] + vx, feet_vel_rel[i, 1] + vy
        slides = w > 0.0 and fx * fx + fy * fy > slip2
        slipping[i] = slides
        trust[i] = 0.0 if slides else w


@numba.njit(cache=True, nogil=True)
def swing_targets(contact, progress, liftoff, footholds, below_z, duration, apex, pos, vel):  # pragma: no cover
    """Swing feet's position and velocity targets into `pos`, `vel` (4, 3); stance rows are zero.

    Each swing foot goes from its lift-off point to its foothold lowered by `below_z` over `duration` [s], at
    progress s in [0, 1]. Horizontal: a cubic smooth step (zero velocity at both ends). Vertical: the same blend plus
    a bump 16 apex s^2 (1 - s)^2, which peaks at `apex` mid-swing and touches down with zero vertical velocity.
    """
    for i in range(4):
        if contact[i]:
            for a in range(3):
                pos[i, a] = 0.0
                vel[i, a] = 0.0
            continue
        s = min(1.0, max(0.0, progress[i]))
        blend, dblend = 3.0 * s * s - 2.0 * s * s * s, 6.0 * s - 6.0 * s * s
        bump, dbump = 16.0 * s * s * (1.0 - s) ** 2, 32.0 * s * (1.0 - s) * (1.0 - 2.0 * s)
        rate = dblend / duration
        for a in range(3):
            end = footholds[i, a] - below_z if a == 2 else footholds[i, a]
            d = end - liftoff[i, a]
            pos[i, a] = liftoff[i, a] + d * blend
            vel[i, a] = d * rate
        pos[i, 2] += apex * bump
        vel[i, 2] += apex * dbump / duration


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
def gait_state(t, period, duty, margin, offsets, contact, progress, touchdown):  # pragma: no cover
    """A periodic gait's state at time `t` [s] into `contact`, `progress` and `touchdown` (one entry per foot).

    Foot i's phase is (t / period + offsets[i]) mod 1, stance first: it is in contact while the phase is below
    duty - margin; in swing (phase >= duty) its progress is (phase - duty) / (1 - duty) and its time to touchdown
    (1 - phase) period [s], both 0 in stance. A duty of 1 never lifts a foot.
    """
    if duty >= 1.0:
        for i in range(offsets.shape[0]):
            contact[i] = True
            progress[i] = 0.0
            touchdown[i] = 0.0
        return
    cycles = t / period
    swing_s = 1.0 - duty
    for i in range(offsets.shape[0]):
        ph = (cycles + offsets[i]) % 1.0
        contact[i] = ph < duty - margin
        if ph >= duty:
            progress[i] = (ph - duty) / swing_s
            touchdown[i] = (1.0 - ph) * period
        else:
            progress[i] = 0.0
            touchdown[i] = 0.0


@numba.njit(cache=True, nogil=True)
def liftoffs(contact, was_stance, feet, liftoff, footholds, lifted):  # pragma: no cover
    """The footholds' bookkeeping of one tick; returns how many feet lifted off at it.

    A swing foot that stood at the last tick lifted off now: its lift-off point is where it is (`lifted` marks it);
    a stance foot's foothold is where it stands. `was_stance` becomes this tick's contact.
    """
    count = 0
    for i in range(4):
        up = not contact[i] and was_stance[i]
        lifted[i] = up
        if up:
            count += 1
            for a in range(3):
                liftoff[i, a] = feet[i, a]
        if contact[i]:
            for a in range(3):
                footholds[i, a] = feet[i, a]
        was_stance[i] = contact[i]
    return count


@numba.njit(cache=True, nogil=True)
def plan_footholds(contact, lifted, refresh, hips_rel, base_position, com, com_vel, v_cmd_x, v_cmd_y, yaw_rate,
                   touchdown, stance_s, ground, capture_gain, centripetal_gain, max_offset, min_height, footholds,
                   parts, clip):  # pragma: no cover
    """The footholds of the swing feet to place at this tick, into `footholds` (4, 3); returns how many are left.

    The feet placed: every swing foot when `refresh`, else those that lifted off at this tick (`lifted`). The law is
    `wbc.mpc.footholds`': p = hip at touchdown + v_cmd T_st / 2 + k sqrt(h / g) (v - v_cmd) + (w x r_hip) T_st / 2
    + k_c sqrt(h / g) (v x w), the offset from the hip clipped to `max_offset`, on the ground at `ground`. A foot
    whose offset may reach the limit (within `FOOTHOLD_CLIP_MARGIN`) is left: its hip at touchdown and unclipped
    offset go to `parts[i]` (hip x, hip y, offset x, offset y) and ``clip[i]`` is set, for the caller to clip with
    Python's ``math.hypot`` (`wbc.mpc.footholds.FootholdPlanner`).

    Args:
        contact: scheduled stance flags (4,).
        lifted: the feet that lifted off at this tick (4,).
        refresh: place every swing foot.
        hips_rel: thigh joints relative to the base, world axes (4, 3) [m].
        base_position: the base, world (3,) [m].
        com: CoM position, world (3,) [m].
        com_vel: CoM velocity, world (3,) [m/s].
        v_cmd_x: commanded velocity, world x [m/s].
        v_cmd_y: commanded velocity, world y [m/s].
        yaw_rate: commanded yaw rate [rad/s].
        touchdown: time to each foot's touchdown (4,) [s].
        stance_s: stance duration [s].
        ground: ground height [m].
        capture_gain: k.
        centripetal_gain: k_c.
        max_offset: largest offset from the hip [m].
        min_height: floor on the CoM height h above the ground [m].
        footholds: out, the placed feet's rows (4, 3) [m].
        parts: out, the left feet's rows (4, 4) [m].
        clip: out, the left feet (4,).
    """
    height = com[2] - ground
    root = math.sqrt((min_height if min_height > height else height) / G)
    half = stance_s / 2.0
    cx, cy = com[0], com[1]
    vx, vy = com_vel[0], com_vel[1]
    w = yaw_rate
    limit2 = max_offset * max_offset * (1.0 - FOOTHOLD_CLIP_MARGIN)
    left = 0
    for i in range(4):
        clip[i] = False
        if contact[i] or not (refresh or lifted[i]):
            continue
        t = touchdown[i]
        # the hip at touchdown: carried by the CoM and turned about it by the yaw rate over the remaining swing
        c, s = math.cos(w * t), math.sin(w * t)
        rx = hips_rel[i, 0] + base_position[0] - cx
        ry = hips_rel[i, 1] + base_position[1] - cy
        lever_x, lever_y = c * rx - s * ry, s * rx + c * ry
        hip_x, hip_y = cx + vx * t + lever_x, cy + vy * t + lever_y
        off_x = v_cmd_x * half + capture_gain * root * (vx - v_cmd_x)
        off_y = v_cmd_y * half + capture_gain * root * (vy - v_cmd_y)
        # v x (0, 0, w) = (w v_y, -w v_x, 0)
        off_x += centripetal_gain * root * w * vy
        off_y -= centripetal_gain * root * w * vx
        # turning: over half a stance the hip sweeps by yaw_rate x (hip - CoM); (0, 0, w) x (l_x, l_y, 0)
        off_x -= w * lever_y * half
        off_y += w * lever_x * half
        if off_x * off_x + off_y * off_y < limit2:
            footholds[i, 0] = hip_x + off_x
            footholds[i, 1] = hip_y + off_y
            footholds[i, 2] = ground
        else:
            parts[i, 0], parts[i, 1], parts[i, 2], parts[i, 3] = hip_x, hip_y, off_x, off_y
            clip[i] = True
            left += 1
    return left


@numba.njit(cache=True, nogil=True)
def command_rows(q, tau, kp, kd, arm_first, arm_target, arm_velocity, dt, rows):  # pragma: no cover
    """A motor command's rows q, dq, kp, kd, tau into `rows` (5, n); returns whether the command is valid.

    Every joint holds its measured position `q` under gains `kp`, `kd` at zero target velocity, with feed-forward
    `tau`. With `arm_first` >= 0 the three joints from it are the arm: its target advances by `arm_velocity` dt (in
    place; pass zeros to hold it) and the arm tracks it at that velocity. Valid: every entry finite and both gain rows
    non-negative, what `wbc.types.MotorCommand` checks.
    """
    n = rows.shape[1]
    for j in range(n):
        rows[0, j] = q[j]
        rows[1, j] = 0.0
        rows[2, j] = kp[j]
        rows[3, j] = kd[j]
        rows[4, j] = tau[j]
    if arm_first >= 0:
        for m in range(3):
            arm_target[m] = arm_target[m] + arm_velocity[m] * dt
            rows[0, arm_first + m] = arm_target[m]
            rows[1, arm_first + m] = arm_velocity[m]
    valid = n > 0
    for r in range(5):
        for j in range(n):
            v = rows[r, j]
            if not math.isfinite(v) or (r == 2 or r == 3) and v < 0.0:
                valid = False
    return valid
