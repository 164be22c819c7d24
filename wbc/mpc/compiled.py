"""The control tick's arithmetic, compiled (numba): gait clock, trust, footholds, legs, command rows.

At 500 Hz the tick is a few hundred small operations on 3-vectors and 3 x 3 matrices; as numpy calls each costs a
microsecond or more of Python and numpy dispatch, which is most of the tick. Compiled, the same arithmetic is a few
microseconds in all. Each function here is one call from Python per tick, writing into arrays its caller allocated
once. Where a law is also written in Python (`wbc.robots.conventions.quat_to_matrix`, the gait's per-time queries),
the kernel performs the same floating-point operations in the same order, so the two agree to the bit.

The kinematics' own pass over the model's tree is `wbc.estimation.tree` (the MPC and the arena's estimate share it).

Compiled functions are cached on disk beside this module (numba's ``cache=True``): a process compiles them once per
machine, later processes load them.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from wbc.robots.conventions import G

__all__ = ["FOOTHOLD_CLIP_MARGIN", "command_rows", "contact_trust", "gait_state", "leg_torques", "liftoffs",
           "plan_footholds", "swing_targets"]

FOOTHOLD_CLIP_MARGIN = 1e-9
"""Relative margin below the largest foothold offset inside which `plan_footholds` needs no norm [1].

Far above the rounding of a squared norm (~1e-16), so an offset inside it is inside the limit whatever the norm's
last bit: only offsets near or past the limit are left for Python's `math.hypot` (the clip's norm; the compiled
libm ``hypot`` differs from it in the last bit on ~0.6 % of inputs)."""

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
