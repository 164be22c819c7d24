"""Actuation and sensing delay of the simulated robot: exact to the physics step, free when zero, from a scenario.

A delayed robot is checked against an undelayed twin that does by hand what the delay should do: writes each command
N physics steps later (actuation), or is read N physics steps earlier (sensing). The twins must agree bit for bit,
whatever the lengths of the `advance` calls (a delay longer or shorter than one, a command arriving mid-call, a push).
"""

import copy
import dataclasses
from pathlib import Path

import mujoco
import numpy as np
import pytest

from wbc.arena.sim_trial import simulated_robot
from wbc.control.stand import stand_command
from wbc.errors import ConfigError
from wbc.hardware import check_robot
from wbc.hardware.clock import ManualClock
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.hardware.mujoco.latency import CommandQueue
from wbc.hardware.mujoco.physics import delay_steps
from wbc.scenario import DomainParams, Push, load_scenario
from wbc.tools.bench.latency import delay_margin, probe_ticks, wire_probe
from wbc.types import MotorCommand

DT = 0.002  # [s] the default physics step
SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
PUSH = Push(force_in_world=np.array([80.0, -40.0, 0.0]), offset_in_base=np.array([0.05, 0.0, 0.0]), start=0.05,
            duration=0.03)


def _commands(robot, count):
    """`count` distinct commands around the standing pose (each differs in q, gains and feed-forward torque)."""
    base = stand_command(robot.desc)
    n = robot.num_joints
    return [dataclasses.replace(base, q=base.q + 0.02 * np.sin(i + np.arange(n)), kp=base.kp + 2.0 * i,
                                tau=np.full(n, 0.3 * (-1) ** i)) for i in range(count)]


def _robot(actuation=0, sensing=0, push=False):
    robot = MujocoRobot(MujocoRobotConfig(arm_mode="actuated"))
    robot.connect()
    robot.reset(seed=2, domain=DomainParams(actuation_delay=actuation * DT, sensing_delay=sensing * DT))
    if push:
        robot.apply_push(PUSH)
    return robot


def _state(robot):
    d = robot.data
    return np.concatenate([d.qpos, d.qvel, d.act, d.ctrl, d.actuator_force, d.sensordata])


@pytest.mark.parametrize(("lag", "chunk", "push"), [(5, 7, False), (5, 3, False), (1, 1, False), (12, 4, True)])
def test_a_command_reaches_the_motors_exactly_n_steps_after_it_was_written(lag, chunk, push):
    """The delayed robot, written every `chunk` steps, equals a twin written `lag` steps later, at every step."""
    delayed = _robot(actuation=lag, push=push)
    twin = _robot(push=push)
    assert delayed.actuation_delay_steps == lag
    cmds = _commands(delayed, 12)
    total = chunk * len(cmds) + lag + 3
    twin_states = []
    for step in range(total):
        twin_states.append(_state(twin))  # before a write: the motors take a command at the next physics step
        if step >= lag and (step - lag) % chunk == 0 and (step - lag) // chunk < len(cmds):
            twin.write(cmds[(step - lag) // chunk])
        twin.advance(DT)
    twin_states.append(_state(twin))
    for k in range(0, total, chunk):  # whole `advance` calls: a command arrives inside most of them
        assert np.array_equal(_state(delayed), twin_states[k]), f"step {k}"
        if k // chunk < len(cmds):
            delayed.write(cmds[k // chunk])
        delayed.advance(min(chunk, total - k) * DT)
    assert np.array_equal(_state(delayed), twin_states[total])


def test_a_torque_step_shows_in_the_torque_estimate_after_the_delay_and_not_before():
    lag = 4
    robot = _robot(actuation=lag)
    hold = stand_command(robot.desc)
    robot.write(hold)
    robot.advance(0.2)
    before = robot.read().tau_est
    step = dataclasses.replace(hold, tau=hold.tau + np.where(np.arange(robot.num_joints) == 2, 5.0, 0.0))
    robot.write(step)
    seen = []
    for _ in range(lag + 2):
        robot.advance(DT)
        seen.append(robot.read().tau_est[2] - before[2])
    # the motors run the step's first physics step under it at step `lag`; its torque is read one step later
    assert np.all(np.abs(seen[:lag]) < 0.5) and seen[lag] > 4.5, seen


@pytest.mark.parametrize(("lag", "chunk"), [(5, 3), (2, 7), (3, 1), (6, 6)])
def test_a_read_returns_the_undelayed_reading_of_n_steps_earlier(lag, chunk):
    delayed = _robot(sensing=lag, push=True)
    twin = _robot(push=True)
    assert delayed.sensing_delay_steps == lag
    cmds = _commands(delayed, 10)
    total = chunk * len(cmds)
    twin_reads, twin_truth = [], []
    for step in range(total + 1):
        if step % chunk == 0 and step // chunk < len(cmds):
            twin.write(cmds[step // chunk])
        twin_reads.append(twin.read())
        twin_truth.append(np.r_[twin.data.qpos, twin.data.qvel])
        twin.advance(DT)
    for k in range(0, total + 1, chunk):
        # the physics is not delayed, only what the sensors report
        assert np.array_equal(np.r_[delayed.data.qpos, delayed.data.qvel], twin_truth[k])
        got, want = delayed.read(), twin_reads[max(0, k - lag)]
        assert got.tick == k and got.time == want.time
        for name in ("q", "dq", "tau_est", "imu_quat", "gyro_in_body", "accel_in_body", "foot_force"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), (k, name)
        if k // chunk < len(cmds):
            delayed.write(cmds[k // chunk])
            delayed.advance(chunk * DT)


def test_zero_delay_is_one_plain_mujoco_run_per_advance():
    """With no delay `advance` is exactly ``mj_step`` with ``nstep``: the trajectory of a raw copy of the data."""
    for domain in (DomainParams(), DomainParams(actuation_delay=0.0009, sensing_delay=0.0009)):  # both round to 0
        robot = MujocoRobot(MujocoRobotConfig(arm_mode="actuated"))
        robot.connect()
        robot.reset(seed=2, domain=domain)
        assert robot.actuation_delay_steps == robot.sensing_delay_steps == 0
        for cmd in _commands(robot, 4):
            robot.write(cmd)
            raw = copy.copy(robot.data)
            robot.advance(25 * DT)
            mujoco.mj_step(robot.model, raw, nstep=25)
            assert np.array_equal(np.r_[raw.qpos, raw.qvel, raw.sensordata, raw.actuator_force],
                                  np.r_[robot.data.qpos, robot.data.qvel, robot.data.sensordata,
                                        robot.data.actuator_force])
            state = robot.read()
            assert state.time == robot.time and np.array_equal(state.q, raw.qpos[7:])


def test_delays_are_rounded_to_whole_physics_steps():
    assert [delay_steps(s, 0.002) for s in (0.0, 0.0009, 0.001, 0.002, 0.003, 0.005, 0.0199, 0.2)] == \
        [0, 0, 1, 1, 2, 3, 10, 100]
    robot = _robot()
    robot.set_domain(DomainParams(actuation_delay=0.0149, sensing_delay=0.0151))
    assert (robot.actuation_delay_steps, robot.sensing_delay_steps) == (7, 8)
    robot.reset()
    assert (robot.actuation_delay_steps, robot.sensing_delay_steps) == (0, 0)


def test_bad_delays_name_the_field():
    for name in ("actuation_delay", "sensing_delay"):
        for bad in (-0.001, 0.25, float("nan")):
            with pytest.raises(ConfigError, match=f"DomainParams.{name} must be in \\[0, 0.2\\] s"):
                DomainParams(**{name: bad})


def test_commands_on_the_way_keep_their_order_when_the_delay_shrinks():
    queue = CommandQueue()
    z = np.zeros(3)
    queue.push(10, z, z, np.full(3, 1.0))
    queue.push(6, z, z, np.full(3, 2.0))  # would overtake the first: it arrives with it, and wins
    queue.push(12, z, z, np.full(3, 3.0))
    assert len(queue) == 2 and queue.next_arrival() == 10
    assert queue.due(9) is None
    assert queue.due(10).ctrl[0] == 2.0 and queue.next_arrival() == 12
    assert queue.due(20).ctrl[0] == 3.0 and queue.due(30) is None and len(queue) == 0


def test_a_trials_delays_reach_the_simulated_robot(tmp_path):
    text = (SCENARIOS / "push.toml").read_text().replace(
        "friction = [0.8, 1.0]",
        "friction = [0.8, 1.0]\nactuation_delay_s = [0.004, 0.02]\nsensing_delay_s = [0.002, 0.002]")
    (tmp_path / "late.toml").write_text(text)
    trial = load_scenario(tmp_path / "late.toml").trial("in", 0, 3)
    robot = simulated_robot(trial, "actuated")
    robot.reset(seed=trial.terrain_seed, domain=trial.domain)
    assert robot.actuation_delay_steps == delay_steps(trial.domain.actuation_delay, DT) >= 2
    assert robot.sensing_delay_steps == 1


# -- the latency bench's pieces ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("actuation", "sensing", "steps_per_tick"), [(0, 0, 1), (3, 0, 1), (2, 4, 1), (0, 0, 5),
                                                                      (7, 2, 5)])
def test_the_probe_counts_one_tick_plus_the_delay(actuation, sensing, steps_per_tick):
    with MujocoRobot(MujocoRobotConfig(robot="go1-arm", arm_mode="none")) as robot:
        robot.reset(domain=DomainParams(actuation_delay=actuation * DT, sensing_delay=sensing * DT))
        hold = MotorCommand.hold(robot.desc.nominal_q, 20.0, 0.5)
        ticks = probe_ticks(robot, hold, period=steps_per_tick * DT, samples=4)
    assert ticks == [-(-(1 + actuation + sensing) // steps_per_tick)] * 4


def test_the_probe_sees_the_step_over_the_wire():
    """On the test's clock, the real-time emulator and the link in lockstep with it: a step written in one control
    tick goes out in the next link period, steps the physics in the emulator's next period and shows in the state
    read after it, the same count every time (``wbc bench latency`` prints the count in real time)."""
    ticks = wire_probe("go1", samples=6, clock=ManualClock())
    assert len(ticks) == 6 and len(set(ticks)) == 1 and 1 <= ticks[0] <= 3, ticks


@pytest.mark.realtime
def test_the_probe_sees_the_step_over_the_wire_in_real_time():
    ticks = wire_probe("go1", samples=6)
    assert len(ticks) == 6 and all(1 <= t <= 100 for t in ticks)


def test_stand_keeps_its_margin_to_the_largest_delay():
    """`stand`'s PD runs in the motors, which no loop delay reaches: it passes every delay of a short sweep.

    On push version 1, whose push duration was calibrated so that `stand` survives band in without stepping (version
    2's longer pushes fell it with no delay at all: they need steps)."""
    m = delay_margin("stand", str(SCENARIOS / "push-v1.toml"), trials=1, coarse_ms=(0.0, 200.0))
    assert (m.still_margin_ms, m.still_fell_at_ms, m.push_margin_ms, m.push_fell_at_ms) == (200.0, None, 200.0, None)
    assert m.runs == 4 and len(m.push_force_n) == 1 and 200.0 <= m.push_force_n[0] <= 300.0


def test_a_go1_margin_plays_the_turn_scenarios_walking_trials_on_the_go1():
    """The Go1's turn scenario has no standing trials with pushes: it was refused, so a Go1 team had no Go1 margin.
    Its first trials play as they are, walking their command; with no push, no push margin is claimed."""
    m = delay_margin("stand", str(SCENARIOS / "turn.toml"), trials=1, coarse_ms=(0.0,))
    assert (m.robot, m.scenario, m.standing, m.still_s) == ("go1-arm", "turn", False, 6.0)
    assert (m.still_margin_ms, m.still_fell_at_ms, m.push_margin_ms, m.push_fell_at_ms) == (0.0, None, None, None)
    assert m.push_force_n == () and m.runs == 1
    pushed = delay_margin("stand", str(SCENARIOS / "push-v1.toml"), trials=1, coarse_ms=(0.0,))
    assert (pushed.robot, pushed.standing, pushed.still_s) == ("a1-wx200", True, 3.0)


@pytest.mark.slow
def test_mpc_margin_is_bracketed_to_the_fine_step():
    m = delay_margin("mpc", str(SCENARIOS / "push-v1.toml"), trials=1, coarse_ms=(0.0, 40.0), fine_ms=20.0)
    assert m.still_fell_at_ms is not None and m.still_fell_at_ms <= 40.0
    assert m.still_margin_ms == m.still_fell_at_ms - 20.0
    assert m.push_margin_ms is not None and m.push_margin_ms <= m.still_margin_ms


def test_a_late_robot_keeps_the_robot_contract():
    late = DomainParams(actuation_delay=0.01, sensing_delay=0.006)
    check_robot(lambda: MujocoRobot(MujocoRobotConfig(arm_mode="none", domain=late)))
    with MujocoRobot(MujocoRobotConfig(arm_mode="none", domain=late)) as robot:
        assert (robot.actuation_delay_steps, robot.sensing_delay_steps) == (5, 3)
        robot.reset(domain=DomainParams())
        assert (robot.actuation_delay_steps, robot.sensing_delay_steps) == (0, 0)
        robot.reset()
        assert (robot.actuation_delay_steps, robot.sensing_delay_steps) == (5, 3)


def test_an_emulated_robot_made_late_is_that_much_later_over_the_wire():
    """The wire adds its own ticks to the simulated delay, never takes any away: on the test's clock, exactly as many
    as without the delay."""
    lag = 5
    counts = {}
    for delay in (0, lag):
        sim = MujocoRobot(MujocoRobotConfig(robot="go1-arm", arm_mode="none",
                                            domain=DomainParams(actuation_delay=delay * DT)))
        counts[delay] = wire_probe("go1", samples=6, period=DT, mode="lockstep", clock=ManualClock(), sim=sim)
    assert len(set(counts[0])) == 1 and counts[0][0] >= 1
    assert counts[lag] == [counts[0][0] + lag] * 6, counts
