"""The control tick's compiled pieces against plain NumPy statements of the same laws (the kinematics pass is checked
against Pinocchio in test_mpc.py)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from wbc.errors import CommandError
from wbc.estimation import BaseEstimator, EstimatorConfig
from wbc.estimation.kinematics import RobotKinematics
from wbc.mpc.compiled import (
    FEET_HEIGHT_BOUND,
    STAGE_CLIP,
    STAGE_DONE,
    STAGE_FOOTHOLDS,
    STAGE_FRONT,
    STAGE_REFERENCE,
    command_rows,
    contact_trust,
    control_tick,
    feet_heights_in_bound,
    liftoffs,
    reference_update,
    swing_targets,
)
from wbc.mpc.compiled import ground_height as compiled_ground_height
from wbc.mpc.controller import MpcController
from wbc.mpc.footholds import MIN_CAPTURE_HEIGHT_M, FootholdConfig, FootholdPlanner, ground_height
from wbc.mpc.gait import TROT
from wbc.mpc.leg_layer import LegLayer
from wbc.mpc.reference import XY_LEASH_M, YAW_LEASH_RAD, MotionReference
from wbc.robots import get_robot, joint_table
from wbc.robots.conventions import G, quat_to_matrix
from wbc.robots.euler import yaw_of
from wbc.types import MotorCommand, RobotState, VelocityCommand


def _leg_torques_numpy(kin, contact, forces, pos, vel, kp, kd, stance_kd, limit):
    """The leg layer's law: stance -J^T (f + c v), swing J^T (kp e + kd de), plus gravity; a stance leg past a limit
    is scaled along its own push by the largest s in [0, 1] that keeps every joint within."""
    stance = contact[:, None]
    swing = kp * (pos - kin.feet) + kd * (vel - kin.feet_vel)
    cart = np.where(stance, -forces - stance_kd * kin.feet_vel, swing)
    legs = np.einsum("iam,ia->im", kin.leg_jacobians, cart)
    hold = kin.gravity[:12].reshape(4, 3)
    lim = limit.reshape(4, 3)
    scale = np.ones(4)
    for i in range(4):
        if contact[i] and np.any(np.abs(legs[i] + hold[i]) > lim[i]):
            # bisection on s: the oracle does not share the closed form
            lo, hi = 0.0, 1.0
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                ok = np.all(np.abs(mid * legs[i] + hold[i]) <= lim[i] + 1e-12)
                lo, hi = (mid, hi) if ok else (lo, mid)
            scale[i] = lo
    tau = kin.gravity.copy()
    tau[:12] += (legs * scale[:, None]).ravel()
    return tau, scale


@pytest.mark.parametrize("robot", ["a1-wx200", "go1-arm"])
def test_the_leg_layer_applies_its_law_and_scales_only_stance_legs_past_their_limits(robot):
    desc = get_robot(robot)
    limit = joint_table(desc).torque_limit
    layer = LegLayer(swing_kp=700.0, swing_kd=20.0, torque_limit=limit, stance_kd=10.0)
    kin = RobotKinematics(desc)
    rng = np.random.default_rng(1)
    scaled = 0
    for k in range(200):
        quat = np.array([1.0, 0.0, 0.0, 0.0]) + 0.1 * rng.standard_normal(4)
        quat /= np.linalg.norm(quat)
        kin.update(rng.standard_normal(3), quat, desc.nominal_q + 0.2 * rng.standard_normal(15),
                   rng.standard_normal(15), rng.standard_normal(3), rng.standard_normal(3), centroidal=False)
        contact = rng.random(4) < 0.6
        forces = rng.normal([0, 0, 60], [30, 30, 60], (4, 3)) * (4.0 if k % 3 == 0 else 1.0)
        pos, vel = kin.feet + 0.05 * rng.standard_normal((4, 3)), rng.standard_normal((4, 3))
        tau = layer.torques(kin, contact, forces, pos, vel)
        want, scale = _leg_torques_numpy(kin, contact, forces, pos, vel, 700.0, 20.0, 10.0, limit[:12])
        np.testing.assert_allclose(layer.scale, scale, atol=1e-9)
        np.testing.assert_allclose(tau, want, atol=1e-6)
        assert np.all(layer.scale[~contact] == 1.0)
        scaled += int(np.any(layer.scale < 1.0))
        stance_legs = np.repeat(contact, 3)
        leg_tau = tau[:12][stance_legs].reshape(-1, 3)
        hold = kin.gravity[:12][stance_legs].reshape(-1, 3)
        lim = limit[:12][stance_legs].reshape(-1, 3)
        # a scaled stance leg is within its limits, or pushes nothing when even gravity alone is past them
        for t, h, m, s in zip(leg_tau, hold, lim, layer.scale[contact], strict=True):
            assert np.all(np.abs(t) <= m + 1e-9) or (s == 0.0 and np.allclose(t, h))
    assert scaled > 20  # the strong forces really reached the limits


def test_before_a_plan_each_stance_foot_pushes_a_quarter_of_the_weight():
    desc = get_robot("a1-wx200")
    layer = LegLayer(swing_kp=700.0, swing_kd=20.0, torque_limit=np.full(15, 1e3))
    kin = RobotKinematics(desc)
    kin.update(np.zeros(3), np.array([1.0, 0, 0, 0]), desc.nominal_q, np.zeros(15), np.zeros(3), np.zeros(3),
               centroidal=False)
    contact = np.ones(4, dtype=bool)
    tau = layer.torques(kin, contact, None, np.zeros((4, 3)), np.zeros((4, 3)))
    want, _ = _leg_torques_numpy(kin, contact, np.tile([0.0, 0.0, 35.0], (4, 1)), 0, 0, 700.0, 20.0, 0.0,
                                 np.full(12, 1e3))
    np.testing.assert_allclose(tau, want, atol=1e-9)


def test_swing_targets_leave_and_land_at_rest_and_peak_at_the_apex_mid_swing():
    liftoff = np.array([[0.2, -0.1, 0.01], [0.2, 0.1, 0.0], [-0.2, -0.1, 0.02], [-0.2, 0.1, 0.0]])
    footholds = liftoff + [0.1, 0.03, -0.01]
    contact = np.array([False, True, False, False])
    pos, vel = np.empty((4, 3)), np.empty((4, 3))
    for s, check in [(0.0, "start"), (0.5, "apex"), (1.0, "end"), (-0.2, "start"), (1.3, "end")]:
        swing_targets(contact, np.full(4, s), liftoff, footholds, 0.02, 0.2, 0.07, pos, vel)
        assert np.all(pos[1] == 0.0) and np.all(vel[1] == 0.0)  # a stance foot has none
        swing = ~contact
        if check == "start":
            np.testing.assert_allclose(pos[swing], liftoff[swing], atol=1e-15)
        elif check == "end":
            np.testing.assert_allclose(pos[swing], footholds[swing] - [0.0, 0.0, 0.02], atol=1e-15)
        else:
            mid = 0.5 * (liftoff + footholds - [0.0, 0.0, 0.02])
            np.testing.assert_allclose(pos[swing], mid[swing] + [0.0, 0.0, 0.07], atol=1e-15)
        if check != "apex":
            np.testing.assert_allclose(vel[swing], 0.0, atol=1e-12)
    # the velocity is the derivative of the position over the swing's duration
    a, b = np.empty((4, 3)), np.empty((4, 3))
    eps = 1e-7
    swing_targets(contact, np.full(4, 0.3), liftoff, footholds, 0.02, 0.2, 0.07, pos, vel)
    swing_targets(contact, np.full(4, 0.3 + eps), liftoff, footholds, 0.02, 0.2, 0.07, a, b)
    np.testing.assert_allclose((a - pos) / (eps * 0.2), vel, atol=1e-5)


def test_the_estimator_trusts_loaded_stance_feet_and_drops_sliding_ones():
    contact = np.array([True, True, True, False])
    force = np.array([30.0, 7.5, 30.0, 50.0])
    vel_rel = np.array([[-0.5, 0.0, 0.0], [-0.5, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    trust, slipping = np.empty(4), np.empty(4, dtype=bool)
    # the base moves at 0.5 m/s: feet 0 and 1 stand still in the world, foot 2 moves with the base (slides)
    contact_trust(contact, force, vel_rel, 0.5, 0.0, 1.0 / 15.0, 0.3**2, trust, slipping)
    np.testing.assert_allclose(trust, [1.0, 0.5, 0.0, 0.0])
    assert slipping.tolist() == [False, False, True, False]


def test_the_compiled_steady_step_is_the_stored_matrices_applied():
    dt = 0.002
    est = BaseEstimator(dt, EstimatorConfig())
    rng = np.random.default_rng(3)
    est.reset(rng.standard_normal(3), rng.standard_normal((4, 3)))
    for _ in range(50):
        x = est.x.copy()
        trust = rng.random(4)
        pattern = sum(1 << i for i in range(4) if trust[i] >= 0.5)
        rot = quat_to_matrix(np.array([0.9, 0.1, -0.2, 0.3]) / np.linalg.norm([0.9, 0.1, -0.2, 0.3]))
        accel, rel, vel = rng.standard_normal(3), rng.standard_normal((4, 3)), rng.standard_normal((4, 3))
        keep_a, keep_b, keep_g, gain = (m[pattern] for m in est._steady)
        want = keep_a @ x + keep_b @ (rot @ accel) + gain @ np.concatenate([rel.ravel(), vel.ravel()]) + keep_g
        est.update(rot, accel, rel, vel, trust.tolist() if pattern % 2 else trust)
        np.testing.assert_allclose(est.x, want, atol=1e-12)


def test_lift_offs_are_recorded_once_and_stance_feet_stand_where_they_are():
    feet = np.arange(12.0).reshape(4, 3)
    liftoff, footholds = np.zeros((4, 3)), np.full((4, 3), -1.0)
    was_stance, lifted = np.array([True, True, False, True]), np.empty(4, dtype=bool)
    contact = np.array([False, True, False, True])  # foot 0 lifts now, foot 2 was already up
    assert liftoffs(contact, was_stance, feet, liftoff, footholds, lifted) == 1
    assert lifted.tolist() == [True, False, False, False] and was_stance.tolist() == contact.tolist()
    np.testing.assert_array_equal(liftoff, [feet[0], [0, 0, 0], [0, 0, 0], [0, 0, 0]])
    np.testing.assert_array_equal(footholds, [[-1, -1, -1], feet[1], [-1, -1, -1], feet[3]])  # swing feet untouched
    assert liftoffs(contact, was_stance, feet + 1.0, liftoff, footholds, lifted) == 0  # nothing lifts twice
    np.testing.assert_array_equal(liftoff[0], feet[0])


@pytest.mark.parametrize("arm_first", [-1, 12])
def test_the_command_rows_hold_the_legs_and_move_the_arm_along_its_velocity(arm_first):
    n = 15
    rng = np.random.default_rng(5)
    q, tau = rng.standard_normal(n), rng.standard_normal(n)
    kp, kd = np.where(np.arange(n) >= 12, 20.0, 0.0), np.full(n, 0.5)
    target, velocity, dt = np.array([0.1, -1.2, 1.4]), np.array([0.5, -0.25, 1.0]), 0.002
    rows = np.empty((5, n))
    assert command_rows(q, tau, kp, kd, arm_first, target, velocity, dt, rows)
    want = np.array([q, np.zeros(n), kp, kd, tau])
    if arm_first >= 0:
        moved = np.array([0.1, -1.2, 1.4]) + velocity * dt
        np.testing.assert_array_equal(target, moved)  # advanced in place
        want[0, 12:], want[1, 12:] = moved, velocity
    np.testing.assert_array_equal(rows, want)


@pytest.mark.parametrize(("row", "value"), [(4, np.nan), (0, np.inf), (3, -0.1), (2, -1e-300)])
def test_the_command_rows_are_refused_as_the_command_refuses_them(row, value):
    n = 12
    rows = np.empty((5, n))
    fields = [np.zeros(n), np.zeros(n), np.zeros(n), np.full(n, 0.5), np.zeros(n)]
    fields[row][7] = value
    q, _, kp, kd, tau = fields
    assert not command_rows(q, tau, kp, kd, -1, np.zeros(3), np.zeros(3), 0.002, rows)
    with pytest.raises(CommandError):
        MotorCommand.from_rows(rows)


def test_the_mpc_refuses_a_command_it_cannot_vouch_for():
    """A non-finite measurement reaches the torques; the controller's command is refused as a constructed one is
    (CommandError naming the field), never handed to a robot unchecked."""
    desc = get_robot("a1-wx200")
    ctrl = MpcController(desc)
    n = desc.num_joints
    dq = np.zeros(n)
    dq[4] = np.nan
    state = RobotState(tick=0, time=0.0, q=np.asarray(desc.nominal_q, dtype=np.float64)[:n].copy(), dq=dq,
                       tau_est=np.zeros(n), imu_quat=np.array([1.0, 0.0, 0.0, 0.0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.full(4, 40.0))
    with pytest.raises(CommandError, match="non-finite"):
        ctrl.act(state, VelocityCommand())


def _foothold_python(hip, com, v_com, v_cmd, w, t, stance_s, ground, cfg):
    """The foothold law in Python floats, statement by statement (`wbc.mpc.footholds`)."""
    hx, hy, _ = hip.tolist()
    cx, cy, cz = com.tolist()
    vx, vy = float(v_com[0]), float(v_com[1])
    vcx, vcy = v_cmd
    c, s = math.cos(w * t), math.sin(w * t)
    rx, ry = hx - cx, hy - cy
    lever_x, lever_y = c * rx - s * ry, s * rx + c * ry
    hip_x, hip_y = cx + vx * t + lever_x, cy + vy * t + lever_y
    root = math.sqrt(max(cz - ground, MIN_CAPTURE_HEIGHT_M) / G)
    half = stance_s / 2
    off_x = vcx * half + cfg.capture_gain * root * (vx - vcx)
    off_y = vcy * half + cfg.capture_gain * root * (vy - vcy)
    off_x += cfg.centripetal_gain * root * w * vy
    off_y -= cfg.centripetal_gain * root * w * vx
    off_x -= w * lever_y * half
    off_y += w * lever_x * half
    norm = math.hypot(off_x, off_y)
    if norm > cfg.max_offset:
        off_x *= cfg.max_offset / norm
        off_y *= cfg.max_offset / norm
    return [hip_x + off_x, hip_y + off_y, ground]


def test_footholds_are_the_law_in_python_floats_to_the_bit_clipped_or_not():
    cfg = FootholdConfig()
    planner = FootholdPlanner(TROT, cfg, 0.07)
    rng = np.random.default_rng(11)
    clipped = 0
    for _ in range(400):
        feet = rng.normal(0.0, 0.2, (4, 3))
        kin = SimpleNamespace(feet=feet, hips_rel=rng.normal(0.0, 0.2, (4, 3)), base_position=rng.normal(0.0, 1.0, 3),
                              com=rng.normal(0.0, 1.0, 3), com_vel=rng.normal(0.0, 1.0, 3))
        contact = rng.random(4) < 0.5
        touchdown, v_cmd, w = rng.random(4) * 0.16, tuple(rng.normal(0.0, 1.0, 2).tolist()), float(rng.normal())
        planner.update(kin, contact, touchdown, v_cmd, w, refresh=True)
        ground = ground_height(feet, contact)
        for i in np.flatnonzero(~contact):
            want = _foothold_python(kin.hips_rel[i] + kin.base_position, kin.com, kin.com_vel, v_cmd, w,
                                    float(touchdown[i]), TROT.stance_s, ground, cfg)
            assert planner.footholds[i].tolist() == want
            clipped += bool(planner._clip[i])  # left to Python's hypot: near or past the reach
        np.testing.assert_array_equal(planner.footholds[contact], feet[contact])
    assert 100 < clipped < 700  # both branches ran, each many times (of ~800 swing feet)


# -- the whole tick in one call (`control_tick`) ---------------------------------------------------------------------

def _reference_python(targets, yaw, com_x, com_y, vx, vy, yaw_rate, dt):
    """The reference's law in Python floats, statement by statement (`wbc.mpc.reference.MotionReference.update`)."""
    before = targets[0]
    unwrapped = before + math.remainder(yaw - before, 2 * math.pi)
    cy, sy = math.cos(unwrapped), math.sin(unwrapped)
    vxw, vyw = cy * vx - sy * vy, sy * vx + cy * vy

    def leash(offset, length):
        return min(max(offset, -length), length)

    return ([unwrapped, unwrapped + leash(targets[1] + yaw_rate * dt - unwrapped, YAW_LEASH_RAD),
             com_x + leash(targets[2] + vxw * dt - com_x, XY_LEASH_M),
             com_y + leash(targets[3] + vyw * dt - com_y, XY_LEASH_M)], [vxw, vyw])


def test_the_compiled_reference_is_the_python_law_to_the_bit():
    rng = np.random.default_rng(5)
    reference = MotionReference(control_dt=0.002, horizon=10, step_s=0.032, body_height=0.28, arm_q=np.zeros(3))
    v_cmd = np.empty(2)
    for k in range(3000):
        targets = (rng.normal(0.0, 10.0 if k % 3 else 0.2, 4)).tolist()
        yaw = float(rng.uniform(-math.pi, math.pi))
        rot = quat_to_matrix(np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]))
        com_x, com_y, vx, vy, yaw_rate = rng.normal(0.0, 1.0, 5).tolist()
        state = np.array(targets)
        assert reference_update(rot, com_x, com_y, vx, vy, yaw_rate, 0.002, XY_LEASH_M, YAW_LEASH_RAD, state, v_cmd)
        want_state, want_v = _reference_python(targets, yaw_of(rot), com_x, com_y, vx, vy, yaw_rate, 0.002)
        assert state.tolist() == want_state and v_cmd.tolist() == want_v
        # and the reference's own Python update, which the staged tick calls
        reference.targets[:] = targets
        got_v = reference.update(yaw_of(rot), com_x, com_y, VelocityCommand(vx=vx, vy=vy, yaw_rate=yaw_rate))
        assert reference.targets.tolist() == want_state and list(got_v) == want_v
    # a NaN yaw goes through as Python's remainder hands it back; an infinite one is left to Python (which raises)
    state = np.zeros(4)
    assert reference_update(np.full((3, 3), np.nan), 0.0, 0.0, 0.0, 0.0, 0.0, 0.002, 0.15, 0.3, state, v_cmd)
    assert math.isnan(state[0])
    state = np.array([np.inf, 0.0, 0.0, 0.0])
    assert not reference_update(np.eye(3), 0.0, 0.0, 0.0, 0.0, 0.0, 0.002, 0.15, 0.3, state, v_cmd)
    assert state.tolist() == [np.inf, 0.0, 0.0, 0.0]


def test_the_compiled_ground_height_is_math_fsums_to_the_bit():
    rng = np.random.default_rng(8)
    awkward = [0.0, -0.0, 1e-16, 1.0, 1e16, -1e16, 0.1, 0.2, 0.3, -0.1, 5e-324, 1.0 + 2.0**-52, 1e300, -1e300]
    for k in range(20000):
        feet = rng.normal(0.0, 1.0, (4, 3)) * 10.0 ** rng.integers(-20, 20)
        if k % 2:
            feet[:, 2] = rng.choice(awkward, 4)
        stance = rng.random(4) < 0.6
        assert feet_heights_in_bound(feet) == bool(np.all(np.abs(feet[:, 2]) <= FEET_HEIGHT_BOUND))
        got, want = compiled_ground_height(feet, stance), ground_height(feet, stance)
        assert got == want and math.copysign(1.0, got) == math.copysign(1.0, want)
    assert not feet_heights_in_bound(np.array([[0.0, 0.0, np.nan]] * 4))
    assert not feet_heights_in_bound(np.array([[0.0, 0.0, 2e300]] * 4))


def _play(controller, robot_name, seconds, schedule, push):
    from wbc.arena.divergence import DivergenceCheck
    from wbc.arena.runner import run_episode
    from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig

    rows = []

    class Recording:
        rate_hz = controller.rate_hz

        def reset(self):
            controller.reset()

        def act(self, state, command):
            out = controller.act(state, command)
            rows.append(np.array(out.rows))
            return out

    robot = MujocoRobot(MujocoRobotConfig(robot=robot_name, arm_mode=controller.desc.arm_mode))
    with robot:
        robot.reset(seed=0)
        if push is not None:
            robot.apply_push(push)
        episode = run_episode(robot, Recording(), schedule, seconds, divergence=DivergenceCheck())
    assert not episode.fell
    return np.stack(rows)


@pytest.mark.parametrize(("name", "robot_name", "pushed"), [("mpc", "a1-wx200", True), ("mpc-noarm", "go1-arm", False)])
def test_the_compiled_tick_gives_the_staged_ticks_commands_to_the_bit(monkeypatch, name, robot_name, pushed):
    """Walking, turning and (a1) pushed sideways, its footholds clipped to the legs' reach: each tick's command from
    the whole tick in one compiled call equals, to the bit, the command of the same tick played stage by stage."""
    import wbc.mpc.controller as controller_module
    from wbc.control.registry import get_controller
    from wbc.scenario.push import Push
    from wbc.scenario.trial import CommandSchedule

    schedule = CommandSchedule(vx=0.5, vy=0.1, yaw_rate=0.5, ramp_s=0.3)
    push = Push(force_in_world=np.array([0.0, 360.0, 0.0]), offset_in_base=np.array([0.05, 0.0, 0.0]), start=0.5,
                duration=0.09) if pushed else None
    spec = get_controller(name)
    desc = get_robot(robot_name, spec.arm_mode)
    staged = spec.make(desc)
    staged._compiled_act = staged._staged_act  # every tick stage by stage
    want = _play(staged, robot_name, 1.0, schedule, push)
    stops = []

    def counted(*args):
        stage = compiled_tick(*args)
        stops.append((args[0], args[1], stage))
        return stage

    compiled_tick = controller_module.control_tick
    monkeypatch.setattr(controller_module, "control_tick", counted)
    got = _play(spec.make(desc), robot_name, 1.0, schedule, push)
    assert got.shape == want.shape
    assert np.array_equal(got.view(np.uint64), want.view(np.uint64))
    whole = sum(first == STAGE_FRONT and last == STAGE_DONE for first, last, _ in stops)
    assert whole > 0.8 * len(got)  # most ticks are one call
    assert any(first == STAGE_REFERENCE for first, _, _ in stops)  # MPC updates split the tick around them
    if pushed:
        assert any(stage == STAGE_CLIP for _, _, stage in stops)  # the push's step-out clipped a foothold in Python


def _standing_a1() -> tuple[MpcController, RobotState]:
    """An MPC for the A1 with its arm and the state of that robot standing still in its nominal pose."""
    desc = get_robot("a1-wx200")
    n = desc.num_joints
    state = RobotState(tick=0, time=0.0, q=np.asarray(desc.nominal_q, dtype=np.float64)[:n].copy(), dq=np.zeros(n),
                       tau_est=np.zeros(n), imu_quat=np.array([1.0, 0.0, 0.0, 0.0]), gyro_in_body=np.zeros(3),
                       accel_in_body=np.array([0.0, 0.0, 9.81]), foot_force=np.full(4, 40.0))
    return MpcController(desc), state


def test_a_stage_leaves_to_python_what_python_must_do():
    """The footholds' stage stops before touching anything when a foot's height is outside what its exact sum takes;
    the whole tick then gives what the staged tick gives (here: a command refused, never sent)."""
    ctrl, state = _standing_a1()
    ctrl.act(state, VelocityCommand())  # the first tick, staged
    feet_before = ctrl.feet.footholds.copy()
    model_f, model_i, kin_buffer, floats, flags, constants = ctrl._tick_arrays()
    kin_buffer[93 + 2] = np.inf  # foot FR's height (`wbc.estimation.tree.tick_arrays`: the feet from entry 93)
    stage = control_tick(STAGE_FOOTHOLDS, STAGE_DONE, state.imu_quat, state.gyro_in_body, state.q, state.dq,
                         state.accel_in_body, state.foot_force, ctrl.t, 0.0, 0.0, 0.0, True, ctrl.plan.forces[0],
                         np.zeros(3), model_f, model_i, kin_buffer, floats, flags, constants,
                         np.empty((5, state.q.size)))
    assert stage == STAGE_FOOTHOLDS
    np.testing.assert_array_equal(ctrl.feet.footholds, feet_before)
    # a non-finite measurement on a compiled tick: the command is refused as a constructed one is
    dq = np.zeros(state.q.size)
    dq[4] = np.nan
    ctrl.act(state, VelocityCommand())
    with pytest.raises(CommandError, match="non-finite"):
        ctrl.act(RobotState(**{**state.__dict__, "dq": dq}), VelocityCommand())


def test_the_compiled_tick_is_compiled_again_when_a_module_it_calls_into_changes():
    """numba keys its disk cache by the function's own file; the tick's key also holds the digest of the modules it
    calls into (the kinematics pass, the estimator's step), so an edit there cannot leave stale machine code."""
    from wbc.estimation import filter as filter_module
    from wbc.estimation import tree
    from wbc.mpc.compiled import _sources_digest

    cells = [cell.cell_contents for cell in control_tick.py_func.__closure__]
    assert _sources_digest(tree, filter_module) in cells


@pytest.mark.parametrize(("name", "robot_name"), [("mpc", "a1-wx200"), ("mpc-locked", "a1-wx200"),
                                                  ("mpc-noarm", "go1-arm")])
def test_an_updates_inputs_are_the_python_statements_to_the_bit(monkeypatch, name, robot_name):
    """x0, the reference, the contact table and the feet of an MPC update from the one compiled call equal, to the
    bit, those of the Python statements it replaces (the fallback), at every tick of a walk that turns."""
    import wbc.mpc.controller as controller_module
    from wbc.control.registry import get_controller
    from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig

    spec = get_controller(name)
    robot = MujocoRobot(MujocoRobotConfig(robot=robot_name, arm_mode=spec.arm_mode))
    ctrl = spec.make(robot.desc)
    compiled = controller_module.update_inputs
    with robot:
        robot.reset(seed=1)
        ctrl.reset()
        for k in range(300):
            command = VelocityCommand(vx=0.6, vy=-0.1 * (k > 150), yaw_rate=1.0 if k > 100 else 0)
            state = robot.read()
            robot.write(ctrl.act(state, command))
            robot.advance(ctrl.dt)
            if k % 7:
                continue
            got = ctrl._update_inputs(state, command)
            monkeypatch.setattr(controller_module, "update_inputs", lambda *args: False)
            want = ctrl._update_inputs(state, command)
            monkeypatch.setattr(controller_module, "update_inputs", compiled)
            for a, b in zip(got, want, strict=True):
                assert a.shape == b.shape and a.dtype == b.dtype
                assert a.tobytes() == b.tobytes()


def test_an_array_a_reset_replaced_is_moved_back_into_the_compiled_ticks_buffers():
    """The compiled tick writes its buffers; a part whose reset replaced one of its arrays (as a subclass may) gets
    the buffer's view back, with its values, before the first compiled tick of the episode reads it."""
    ctrl, state = _standing_a1()
    ctrl.reset()
    ctrl._arm_target = np.array([0.1, -0.2, 0.3])
    ctrl.feet.footholds = np.full((4, 3), 7.0)
    ctrl.act(state, VelocityCommand())  # the first tick of the episode, staged
    ctrl.act(state, VelocityCommand())  # compiled
    assert np.shares_memory(ctrl._arm_target, ctrl._tick_floats)
    assert np.shares_memory(ctrl.feet.footholds, ctrl._tick_floats)
    # the arm's target moved on from the value the reset left, not from the buffer's old one
    assert np.abs(ctrl._arm_target - [0.1, -0.2, 0.3]).max() < 0.01
