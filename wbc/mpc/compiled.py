"""The control tick's arithmetic, compiled (numba): gait clock, trust, footholds, reference, legs, command rows.

At 500 Hz the tick is a few hundred small operations on 3-vectors and 3 x 3 matrices; as numpy calls each costs a
microsecond or more of Python and numpy dispatch, which is most of the tick. Compiled, the same arithmetic is a few
microseconds in all. Each stage here is a function writing into arrays its caller allocated once. Where a law is also
written in Python (`wbc.robots.conventions.quat_to_matrix`, the gait's per-time queries, the reference's targets, the
ground height's ``math.fsum``), the kernel performs the same floating-point operations in the same order, so the two
agree to the bit.

`control_tick` runs the stages of a whole tick (the kinematics' pass over the model's tree, `wbc.estimation.tree`,
and the estimator's steady step, `wbc.estimation.filter.steady_step`, included) in one call: a compiled call costs
~0.15 us for each array it is handed and a few tenths more of Python around it, so a dozen calls a tick cost more
than their arithmetic. The controller calls the stages one by one where the tick needs Python between them (the
first tick of an episode, PlaCo's whole-body QP, the debug truth).

Compiled functions are cached on disk beside this module (numba's ``cache=True``): a process compiles them once per
machine, later processes load them.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numba
import numpy as np

from wbc.estimation import filter as filter_module
from wbc.estimation import tree
from wbc.estimation.filter import steady_step
from wbc.estimation.tree import packed_pass, packed_place, tick_arrays
from wbc.robots.conventions import G

__all__ = ["FEET_HEIGHT_BOUND", "FOOTHOLD_CLIP_MARGIN", "STAGE_CLIP", "STAGE_COMMAND", "STAGE_DONE",
           "STAGE_FOOTHOLDS", "STAGE_FRONT", "STAGE_LEGS", "STAGE_REFERENCE", "TICK_CONSTANTS", "TICK_FLAGS",
           "TICK_FLOATS", "command_rows", "contact_trust", "control_tick", "feet_heights_in_bound", "gait_state",
           "ground_height", "leg_torques", "liftoffs", "plan_footholds", "reference_update", "swing_targets",
           "tick_constant_arrays", "tick_constants_size", "tick_flags", "tick_floats", "update_inputs"]

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


@numba.njit(cache=True, nogil=True)
def _remainder(x, y):  # pragma: no cover
    """IEEE remainder of finite `x` by finite, non-zero `y`: CPython's ``math.remainder``, step for step (exact)."""
    absx, absy = abs(x), abs(y)
    m = absx % absy  # positive operands: C's fmod, exact
    c = absy - m
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:  # half-way: the even multiple
        r = m - 2.0 * ((0.5 * (absx - m)) % absy)
    return math.copysign(1.0, x) * r


@numba.njit(cache=True, nogil=True)
def _leash(offset, length):  # pragma: no cover
    """`offset` clipped to [-length, length], as `wbc.mpc.reference`'s leash."""
    return -length if offset < -length else length if offset > length else offset


_TWO_PI = 2 * math.pi


@numba.njit(cache=True, nogil=True)
def reference_update(rot, com_x, com_y, vx, vy, yaw_rate, dt, xy_leash, yaw_leash, state, v_cmd):  # pragma: no cover
    """One tick of `wbc.mpc.reference.MotionReference.update`: the targets in `state`, the command into `v_cmd`.

    `state` holds (yaw, yaw target, target x, target y), advanced in place; `v_cmd` (2,) gets the commanded horizontal
    velocity in the world. The measured yaw is that of `rot` (`wbc.robots.euler.yaw_of`). The same operations in the
    same order as the Python law (the tests keep it), so the same bits. Returns False, having changed nothing, where
    Python's ``math.remainder`` would raise (an infinite yaw difference): the caller then runs the Python law.
    """
    yaw = state[0]
    turn = math.atan2(rot[1, 0], rot[0, 0]) - yaw
    if math.isinf(turn):
        return False
    if math.isnan(turn):
        unwrapped = yaw + turn  # Python's remainder hands a NaN back
    else:
        unwrapped = yaw + _remainder(turn, _TWO_PI)
    state[0] = unwrapped
    cy, sy = math.cos(unwrapped), math.sin(unwrapped)
    vx_world = cy * vx - sy * vy
    vy_world = sy * vx + cy * vy
    state[2] = com_x + _leash(state[2] + vx_world * dt - com_x, xy_leash)
    state[3] = com_y + _leash(state[3] + vy_world * dt - com_y, xy_leash)
    state[1] = unwrapped + _leash(state[1] + yaw_rate * dt - unwrapped, yaw_leash)
    v_cmd[0] = vx_world
    v_cmd[1] = vy_world
    return True


@numba.njit(cache=True, nogil=True)
def _exact_sum(values, count):  # pragma: no cover
    """The correctly rounded sum of the first `count` (<= 4) of `values`: CPython's ``math.fsum``, step for step.

    Its partials, then their sum rounded once, half-way cases included; for finite values whose sum does not
    overflow (where ``math.fsum`` would raise, or hand back a NaN, the callers run the Python law).
    """
    partials = np.empty(4)
    n = 0
    for k in range(count):
        x = values[k]
        i = 0
        for j in range(n):
            y = partials[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo != 0.0:
                partials[i] = lo
                i += 1
            x = hi
        n = i
        if x != 0.0:
            partials[n] = x
            n += 1
    hi = 0.0
    if n > 0:
        n -= 1
        hi = partials[n]
        lo = 0.0
        while n > 0:
            x = hi
            n -= 1
            y = partials[n]
            hi = x + y
            yr = hi - x
            lo = y - yr
            if lo != 0.0:
                break
        if n > 0 and ((lo < 0.0 and partials[n - 1] < 0.0) or (lo > 0.0 and partials[n - 1] > 0.0)):
            y = lo * 2.0
            x = hi + y
            yr = x - hi
            if y == yr:
                hi = x
    return hi


FEET_HEIGHT_BOUND = 1e300
"""Largest foot height [m] the compiled ground height takes: four of them sum without overflow, where Python's
``math.fsum`` would raise (a tick whose feet lie outside is handed to the Python law)."""


@numba.njit(cache=True, nogil=True)
def feet_heights_in_bound(feet):  # pragma: no cover
    """Whether every foot's height is finite and within `FEET_HEIGHT_BOUND` (`ground_height` takes them)."""
    for i in range(4):
        if not abs(feet[i, 2]) <= FEET_HEIGHT_BOUND:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def ground_height(feet, stance):  # pragma: no cover
    """`wbc.mpc.footholds.ground_height` to the bit, for heights `feet_heights_in_bound` takes.

    The mean height of the stance feet (their correctly rounded sum over their count), or the lowest foot when none
    stands.
    """
    heights = np.empty(4)
    count = 0
    for i in range(4):
        if stance[i]:
            heights[count] = feet[i, 2]
            count += 1
    if count == 0:
        low = feet[0, 2]
        for i in range(1, 4):
            if feet[i, 2] < low:
                low = feet[i, 2]
        return low
    return _exact_sum(heights, count) / count



@numba.njit(cache=True, nogil=True)
def _in_stance(t, step, period, duty, margin, offset):  # pragma: no cover
    """Whether a foot of phase `offset` stands at `t` + `step` [s] (`wbc.mpc.gait.GaitScheduler`'s law)."""
    if duty >= 1.0:
        return True
    return ((t + step) / period + offset) % 1.0 < duty - margin


@numba.njit(cache=True, nogil=True)
def update_inputs(t, step_s, vx, vy, yaw_rate, body_height, step_times, period, duty, margin, offsets, kin, footholds,
                  targets, arm_reference, momentum, arm_q, x0, x_ref, contact, feet):  # pragma: no cover
    """An MPC update's inputs from the tick's state, as `wbc.mpc.controller.MpcController` states them in Python.

    Into `x0` (15,) the current state; into `contact` (N, 4) the gait's stance flags at the middle of each step;
    into `feet` (N, 4, 3) each foot where it stands until it first lifts within the horizon, at its foothold from
    then on; into `x_ref` (N, 15) the reference trajectory (`wbc.mpc.reference.MotionReference.trajectory`) but
    for its momentum rows, a product the caller leaves to numpy as the Python law does. The same operations in
    the same order as the Python statements (the tests keep them), so the same bits. Returns False, having
    written nothing, where a foot's height is outside `FEET_HEIGHT_BOUND` (the ground's exact sum): the caller
    then runs the Python statements.

    Args:
        t: the tick's time [s].
        step_s: the MPC step [s].
        vx: the commanded forward velocity [m/s] (a float).
        vy: the commanded lateral velocity [m/s] (a float).
        yaw_rate: the commanded yaw rate [rad/s] (a float).
        body_height: the CoM height to hold above the stance feet [m].
        step_times: the ends of the horizon's steps from now (N,) [s].
        period: the gait's period [s].
        duty: its duty factor.
        margin: its stance-end margin (`wbc.mpc.gait.STANCE_END_MARGIN`).
        offsets: its phase offsets (4,).
        kin: the kinematics' tick buffer, placed (`wbc.estimation.tree.tick_arrays`).
        footholds: the footholds (4, 3) [m].
        targets: the reference's targets (yaw, yaw target, target x, target y).
        arm_reference: the arm's reference pose (3,) [rad].
        momentum: the centroidal angular momentum (3,).
        arm_q: the arm's current joint positions (3,) [rad].
        x0: out.
        x_ref: out, rows 9-11 left alone.
        contact: out.
        feet: out.
    """
    (rot, _, _, _, _, _, _, _, _, _, _, _, feet_now, _, com, com_vel, _) = tick_arrays(kin)
    if not feet_heights_in_bound(feet_now):
        return False
    n = x_ref.shape[0]
    for k in range(n):
        for i in range(4):
            contact[k, i] = _in_stance(t, (k + 0.5) * step_s, period, duty, margin, offsets[i])
    for i in range(4):
        lifted = False
        for k in range(n):
            lifted = lifted or not contact[k, i]
            for a in range(3):
                feet[k, i, a] = footholds[i, a] if lifted else feet_now[i, a]
    stance = np.empty(4, dtype=np.bool_)
    for i in range(4):
        stance[i] = _in_stance(t, 0.0, period, duty, margin, offsets[i])
    ground = ground_height(feet_now, stance)
    # roll and pitch as `wbc.robots.euler.rpy_of` (Python's min and max: the second argument only if it is
    # strictly smaller / larger)
    sin_pitch = rot[2, 0]
    clamped = sin_pitch if sin_pitch < 1.0 else 1.0
    clamped = clamped if clamped > -1.0 else -1.0
    for a in range(3):
        x0[a] = com[a]
        x0[3 + a] = com_vel[a]
        x0[9 + a] = momentum[a]
        x0[12 + a] = arm_q[a]
    x0[6] = math.atan2(rot[2, 1], rot[2, 2])
    x0[7] = -math.asin(clamped)
    x0[8] = targets[0]
    total_x, total_y = 0.0, 0.0
    for k in range(n):
        yaw_k = targets[1] + yaw_rate * step_times[k]
        cos_k, sin_k = math.cos(yaw_k), math.sin(yaw_k)
        vx_k = cos_k * vx - sin_k * vy
        vy_k = sin_k * vx + cos_k * vy
        total_x += vx_k
        total_y += vy_k
        x_ref[k, 0] = targets[2] + total_x * step_s
        x_ref[k, 1] = targets[3] + total_y * step_s
        x_ref[k, 2] = ground + body_height
        x_ref[k, 3] = vx_k
        x_ref[k, 4] = vy_k
        x_ref[k, 5] = 0.0
        x_ref[k, 6] = 0.0
        x_ref[k, 7] = 0.0
        x_ref[k, 8] = yaw_k
        for a in range(3):
            x_ref[k, 12 + a] = arm_reference[a]
    return True


STAGE_FRONT = 0
"""`control_tick`'s first stage: the kinematics pass, the gait's state, the estimator (trust, steady-gain step) and the
kinematics placed at its estimate."""
STAGE_REFERENCE = 1
"""The leashed targets advanced by the command (`reference_update`)."""
STAGE_FOOTHOLDS = 2
"""The lift-offs recorded and the swing feet's footholds placed (`liftoffs`, `plan_footholds`)."""
STAGE_CLIP = 3
"""The footholds `plan_footholds` left for Python's ``math.hypot`` clipped: never run by `control_tick`."""
STAGE_LEGS = 4
"""The swing paths and the leg layer (`swing_targets`, `leg_torques`)."""
STAGE_COMMAND = 5
"""The motor command's rows, checked (`command_rows`)."""
STAGE_DONE = 6
"""Past the last stage."""

C_PERIOD, C_DUTY, C_MARGIN, C_INV_FORCE, C_SLIP2, C_DT, C_XY_LEASH, C_YAW_LEASH = range(8)
C_STANCE_S, C_CAPTURE, C_CENTRIPETAL, C_MAX_OFFSET, C_MIN_HEIGHT, C_BELOW_Z, C_SWING_S, C_APEX = range(8, 16)
C_SWING_KP, C_SWING_KD, C_STANCE_KD, C_ARM_FIRST = range(16, 20)
TICK_CONSTANTS = 20
"""Length of `control_tick`'s scalar constants (the first entries of its constants buffer); the ``C_*`` names index
them."""

OUT_V_CMD_X, OUT_V_CMD_Y, OUT_GROUND, OUT_VALID = range(4)
"""Indices of `control_tick`'s results array: the commanded velocity in the world (its reference stage), the ground
height of a placement left to clip, and whether the command's rows passed the check (1.0) or not (0.0)."""

TICK_FLOATS = 109
"""Entries of the tick's float buffer before the joint torques (`tick_floats`)."""
TICK_FLAGS = 20
"""Entries of the tick's flag buffer (`tick_flags`)."""
_PATTERNS, _NX_EST = 16, 18  # the estimator's contact patterns and state size (`wbc.estimation.filter`)


def tick_constants_size(n: int) -> int:
    """Length of the tick's constants buffer (`tick_constant_arrays`) for a robot of `n` joints."""
    return TICK_CONSTANTS + 4 + 12 + 2 * n + _PATTERNS * _NX_EST * (_NX_EST + 3 + 1 + 24)


@numba.njit(cache=True, nogil=True)
def tick_floats(buf):  # pragma: no cover
    """The tick's per-tick float arrays as views of one buffer of `TICK_FLOATS` + n entries.

    In order: the gait's progress and time to touchdown (4,), the estimator's trust (4,), the reference's targets
    (4,), the lift-off points and footholds (4, 3), the feet left to clip (4, 4), the swing targets' positions and
    velocities (4, 3), the legs' push scales (4,), the arm's target (3,), the results (``OUT_*``, 4), the estimator's
    state (18,), the joint torques (n,). The controller's parts hold these views as their arrays, so one compiled
    call is handed one array for all of them (numba wraps every array handed to it, ~0.15 us each).
    """
    return (buf[0:4], buf[4:8], buf[8:12], buf[12:16], buf[16:28].reshape((4, 3)), buf[28:40].reshape((4, 3)),
            buf[40:56].reshape((4, 4)), buf[56:68].reshape((4, 3)), buf[68:80].reshape((4, 3)), buf[80:84],
            buf[84:87], buf[87:91], buf[91:109], buf[109:])


@numba.njit(cache=True, nogil=True)
def tick_flags(buf):  # pragma: no cover
    """The tick's flags as views of one boolean buffer of `TICK_FLAGS` entries (4 each).

    In order: the gait's stance flags, the feet the estimator dropped, the last tick's stance flags, this tick's
    lift-offs, the feet left to clip.
    """
    return buf[0:4], buf[4:8], buf[8:12], buf[12:16], buf[16:20]


@numba.njit(cache=True, nogil=True)
def tick_constant_arrays(buf, n):  # pragma: no cover
    """The tick's constants as views of one buffer of `tick_constants_size` (n joints) entries.

    In order: the scalars (``C_*``, `TICK_CONSTANTS`), the gait's phase offsets (4,), the legs' torque limits (12,),
    the joints' gains kp and kd (n,), the estimator's steady-step matrices keep_a (16, 18, 18), keep_b (16, 18, 3),
    keep_g (16, 18), gain (16, 18, 24) (`wbc.estimation.filter.steady_step`).
    """
    o = TICK_CONSTANTS
    consts, offsets, limit = buf[0:o], buf[o:o + 4], buf[o + 4:o + 16]
    o += 16
    kp, kd = buf[o:o + n], buf[o + n:o + 2 * n]
    o += 2 * n
    size = _PATTERNS * _NX_EST
    keep_a = buf[o:o + size * _NX_EST].reshape((_PATTERNS, _NX_EST, _NX_EST))
    o += size * _NX_EST
    keep_b = buf[o:o + size * 3].reshape((_PATTERNS, _NX_EST, 3))
    o += size * 3
    keep_g = buf[o:o + size].reshape((_PATTERNS, _NX_EST))
    o += size
    gain = buf[o:o + size * 24].reshape((_PATTERNS, _NX_EST, 24))
    return consts, offsets, limit, kp, kd, keep_a, keep_b, keep_g, gain


def _sources_digest(*modules: object) -> str:
    """SHA-256 of the modules' source files, for the compiled tick's key in numba's disk cache.

    numba keys a cached function by its own file only, so a function it compiled in from another module could change
    without the cache noticing, and the old machine code would run (numba's documented limitation). numba's key does
    hash a function's closure variables: `control_tick` closes over this digest of the modules it calls into, and a
    change to them compiles it afresh.
    """
    digest = hashlib.sha256()
    for module in modules:
        digest.update(Path(module.__file__).read_bytes())
    return digest.hexdigest()


def _make_control_tick(sources: str):  # noqa: ANN202 (returns a numba dispatcher)
    """`control_tick`, compiled with `sources` (`_sources_digest` of the modules it calls into) in its cache key."""

    @numba.njit(cache=True, nogil=True)
    def control_tick(first, last, base_quat, omega_body, q, dq, accel_body, foot_force, t, vx, vy, yaw_rate, refresh,
                     forces, arm_velocity, model_f, model_i, kin, floats, flags, constants, rows):  # pragma: no cover
        """The MPC controller's control tick, from stage `first` to before stage `last` (``STAGE_*``), in one call.

        Each stage is the compiled function the controller otherwise calls on its own, with the same arguments, so
        the tick gives the same bits either way; here it is one call from Python instead of a dozen
        (`wbc.mpc.controller.MpcController`'s staged path; the tests compare the two). A stage stops early, having
        changed nothing of its own, where the Python law must take over: the reference when Python's remainder would
        raise (returns `STAGE_REFERENCE`), the footholds when a foot's height is outside `FEET_HEIGHT_BOUND`
        (`STAGE_FOOTHOLDS`); after the footholds' placement, when some are left to clip (`STAGE_CLIP`, the ground in
        ``out[OUT_GROUND]``).

        Args:
            first: the first stage to run.
            last: the stage to stop before.
            base_quat: the IMU's orientation (w, x, y, z).
            omega_body: the trunk's angular velocity, body frame (3,) [rad/s].
            q: joint positions (n,) [rad].
            dq: joint velocities (n,) [rad/s].
            accel_body: the accelerometer's specific force, body frame (3,) [m/s^2].
            foot_force: the foot sensors (4,) [N].
            t: the gait's time [s].
            vx: the commanded forward velocity [m/s] (a float).
            vy: the commanded lateral velocity [m/s] (a float).
            yaw_rate: the commanded yaw rate [rad/s] (a float).
            refresh: place every swing foot's foothold (not only those lifting off).
            forces: the plan's contact forces at this tick, world (4, 3) [N].
            arm_velocity: the arm's velocity at this tick (3,) [rad/s].
            model_f: the kinematics' packed model, floats (`wbc.estimation.tree.TreeModel.packed`).
            model_i: the same, integers.
            kin: the kinematics' tick buffer (`wbc.estimation.tree.tick_arrays`).
            floats: the tick's float arrays (`tick_floats`): the gait's state, the estimator's trust and state, the
                reference's targets, the footholds' bookkeeping, the swing paths' targets, the legs' push scales, the
                arm's target, the results (``OUT_*``), the torques; updated in place.
            flags: the tick's flags (`tick_flags`), updated in place.
            constants: the tick's constants (`tick_constant_arrays`).
            rows: out, the command's rows (5, n).

        Returns:
            The stage to run next: `last` when every stage ran.
        """
        sources  # noqa: B018 - in numba's cache key (`_sources_digest`)
        (rot, _, _, feet_rel, hips_rel, _, leg_jac, gravity, _, _, base_position, _, feet, feet_vel, com,
         com_vel, contact_vel_rel) = tick_arrays(kin)
        (progress, touchdown, trust, reference, liftoff, footholds, parts, swing_pos, swing_vel, scale, arm_target,
         out, x, tau) = tick_floats(floats)
        contact, slipping, was_stance, lifted, clip = tick_flags(flags)
        consts, offsets, limit, kp, kd, keep_a, keep_b, keep_g, gain = tick_constant_arrays(constants, tau.shape[0])
        arm_first = int(consts[C_ARM_FIRST])
        stage = first
        if stage == STAGE_FRONT and stage < last:
            packed_pass(base_quat, omega_body, q, dq, model_f, model_i, kin)
            gait_state(t, consts[C_PERIOD], consts[C_DUTY], consts[C_MARGIN], offsets, contact, progress, touchdown)
            contact_trust(contact, foot_force, contact_vel_rel, x[3], x[4], consts[C_INV_FORCE], consts[C_SLIP2],
                          trust, slipping)
            steady_step(x, trust, rot, accel_body, feet_rel, contact_vel_rel, keep_a, keep_b, keep_g, gain)
            packed_place(kin, x[0:3], x[3:6])
            stage = STAGE_REFERENCE
        if stage == STAGE_REFERENCE and stage < last:
            if not reference_update(rot, com[0], com[1], vx, vy, yaw_rate, consts[C_DT], consts[C_XY_LEASH],
                                    consts[C_YAW_LEASH], reference, out[0:2]):
                return STAGE_REFERENCE
            stage = STAGE_FOOTHOLDS
        if stage == STAGE_FOOTHOLDS and stage < last:
            if not feet_heights_in_bound(feet):
                return STAGE_FOOTHOLDS
            count = liftoffs(contact, was_stance, feet, liftoff, footholds, lifted)
            stage = STAGE_LEGS
            if refresh or count:
                ground = ground_height(feet, contact)
                if plan_footholds(contact, lifted, refresh, hips_rel, base_position, com, com_vel, out[OUT_V_CMD_X],
                                  out[OUT_V_CMD_Y], yaw_rate, touchdown, consts[C_STANCE_S], ground,
                                  consts[C_CAPTURE], consts[C_CENTRIPETAL], consts[C_MAX_OFFSET], consts[C_MIN_HEIGHT],
                                  footholds, parts, clip):
                    out[OUT_GROUND] = ground
                    return STAGE_CLIP
        if stage == STAGE_CLIP and stage < last:
            return STAGE_CLIP
        if stage == STAGE_LEGS and stage < last:
            swing_targets(contact, progress, liftoff, footholds, consts[C_BELOW_Z], consts[C_SWING_S], consts[C_APEX],
                          swing_pos, swing_vel)
            leg_torques(leg_jac, gravity, feet, feet_vel, contact, forces, swing_pos, swing_vel, consts[C_SWING_KP],
                        consts[C_SWING_KD], consts[C_STANCE_KD], limit, scale, tau)
            stage = STAGE_COMMAND
        if stage == STAGE_COMMAND and stage < last:
            valid = command_rows(q, tau, kp, kd, arm_first, arm_target, arm_velocity, consts[C_DT], rows)
            out[OUT_VALID] = 1.0 if valid else 0.0
            stage = STAGE_DONE
        return stage

    return control_tick


control_tick = _make_control_tick(_sources_digest(tree, filter_module))
