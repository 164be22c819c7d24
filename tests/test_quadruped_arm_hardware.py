"""The whole robot over both wires: `SafeRobot(QuadrupedArmRobot(UnitreeRobot, DynamixelArm))` against one
`RobotEmulator` (legs on the Unitree wire, arm on the Dynamixel bus, one physics): the contract, fault case 10
through the safety layer (it trips; damping on both wires), and the issue's 10 s stand beside the same 10 s in pure
simulation.

The default suite runs the robot in lockstep on one `ManualClock`: the emulator hands out both wires in process
(`RobotEmulator.legs_transport`, `RobotEmulator.arm_handlers`), the legs' link period and the arm's bus cycle are
tasks of that clock, and each leg command steps the physics by one link period. The stand is ten seconds of
simulated time, run in a few seconds of CPU, and every figure a test checks (when the layer trips, what reached
which wire when) is the same on any machine at any load. The same robot over UDP on 127.0.0.1 and a pty, against
the wall clock, is what the tests marked ``realtime`` run (``make test-realtime``); ``wbc bench arm`` prints its
real-time figures (the bus loop's rate and busy time, the fault-to-latch times).
"""

from __future__ import annotations

import gc
import io
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from wbc.control.stand import StandController
from wbc.errors import ConfigError, TargetRefusedError, UnknownNameError
from wbc.hardware import Robot
from wbc.hardware.clock import ManualClock
from wbc.hardware.dynamixel import DynamixelArm, DynamixelArmConfig
from wbc.hardware.dynamixel.arm_robot import ARM_KD_MAX, ARM_KP_MAX
from wbc.hardware.emulators import BusFault, Fault, RobotEmulator, RobotEmulatorConfig
from wbc.hardware.hardware_robot import HardwareRobotConfig, build_hardware_robot
from wbc.hardware.interpreter import freeze_heap
from wbc.hardware.mujoco.robot import MujocoRobot, MujocoRobotConfig
from wbc.hardware.quadruped_arm_robot import QuadrupedArmConfig, QuadrupedArmRobot
from wbc.hardware.realtime import NO_REALTIME, RealtimeRequest, request_realtime
from wbc.hardware.robot_contract import check_robot
from wbc.hardware.safety import SafeRobot, SafetyConfig, SafetyEvent, SafetyState
from wbc.hardware.unitree import UnitreeRobot, UnitreeRobotConfig
from wbc.hardware.unitree.command_codec import encode_command
from wbc.hardware.unitree.layout import frame_layout
from wbc.hardware.unitree.state_codec import decode_state
from wbc.robots.registry import get_robot
from wbc.types import MotorCommand

sdk = pytest.importorskip("dynamixel_sdk")

ARM = dict(latency_ms=4.0)  # over the pty (realtime tests): the emulator answers from a thread of this process
ROOT = Path(__file__).resolve().parents[1]
LEGS = {"a1-wx200": "a1", "go1-arm": "go1"}


def _lockstep(robot: str, arm_mode: str, clock: ManualClock, emu: RobotEmulator,
              quadruped: QuadrupedArmConfig | None = None) -> QuadrupedArmRobot:
    """Legs and arm on `clock`, their wires in process to `emu` (the robot's default latency timer, 1 ms)."""
    legs = UnitreeRobot(UnitreeRobotConfig(robot=LEGS[robot], target_host="127.0.0.1", target_port=9),
                        emu.legs_transport, clock=clock)
    arm = DynamixelArm(DynamixelArmConfig(robot=robot, port=emu.port), handlers=emu.arm_handlers(), clock=clock)
    return QuadrupedArmRobot(legs, arm, quadruped or QuadrupedArmConfig(arm_mode=arm_mode))


@contextmanager
def _whole_robot(arm_mode: str = "actuated", **safety: object) -> Iterator[tuple[RobotEmulator, SafeRobot,
                                                                                  list[SafetyEvent]]]:
    """The a1-wx200 in lockstep on one `ManualClock`, through the safety layer."""
    events: list[SafetyEvent] = []
    clock = ManualClock()
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="lockstep"), clock=clock) as emu:
        safe = SafeRobot(_lockstep("a1-wx200", arm_mode, clock, emu),
                         SafetyConfig(position_table="a1", on_event=events.append, **safety))
        with safe:
            yield emu, safe, events
        assert emu.failure is None, emu.failure
    assert not [t.name for t in threading.enumerate() if t.name.startswith(("unitree-", "dynamixel-"))]


def _stand(safe: SafeRobot, seconds: float, until: object = None) -> None:
    """The stand controller for `seconds` of the robot's time (or until `until()`)."""
    ctrl = StandController(get_robot("a1-wx200", "actuated"))
    for _ in range(round(seconds * ctrl.rate_hz)):
        if until is not None and until():
            return
        safe.write(ctrl.act(safe.read(), None))
        safe.advance(1.0 / ctrl.rate_hz)


def test_contract_of_the_joined_robot_over_both_emulators() -> None:
    clock = ManualClock()
    with RobotEmulator(RobotEmulatorConfig(robot="go1-arm", mode="lockstep"), clock=clock) as emu:
        check_robot(lambda: _lockstep("go1-arm", "actuated", clock, emu))
        assert emu.failure is None


def test_close_damps_the_legs_from_their_next_frame_then_parks_the_arm() -> None:
    """Without a safety layer's damping before it, `close` damps the legs from the very next frame, then closes the
    arm (its close damping, then its park). The arm was closed first: the legs held their last command through it
    until their own write deadline (25 frames), as long as if nothing had closed them."""
    clock = ManualClock()
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="lockstep"), clock=clock) as emu:
        robot = _lockstep("a1-wx200", "actuated", clock, emu)
        robot.connect()
        hold = MotorCommand.hold(robot.read().q, 20.0, 0.5)
        for _ in range(25):
            robot.write(hold)
            robot.advance(0.004)
        sent = len(emu.legs.commands())
        assert not emu.legs.commands()[-1].damping
        emu.arm.clear_log()
        robot.close()
        frames = emu.legs.commands()[sent:]
        parked = [p.time for p in emu.arm.packets() if p.written("operating_mode")]
        assert emu.failure is None
    held = next((k for k, c in enumerate(frames) if c.damping), None)
    assert held == 0 and all(c.damping for c in frames)  # from the next frame on, and nothing else after it
    assert parked and frames[0].time < min(parked)  # the legs damped before the arm is parked


def _build(robot: str, arm_mode: str, target: tuple[str, int] = ("127.0.0.1", 9), **arm: object) -> Robot:
    return build_hardware_robot(HardwareRobotConfig(robot=robot, arm_mode=arm_mode, legs_host=target[0],
                                                    legs_port=target[1], **arm)).robot


def test_the_factory_names_what_a_mode_needs() -> None:
    with pytest.raises(ConfigError, match="serial port"):
        _build("a1-wx200", "actuated")
    with pytest.raises(ConfigError, match="drives no arm"):
        _build("go1-arm", "none", arm_port="/dev/ttyUSB0")
    with pytest.raises(UnknownNameError, match="a1-wx200"):
        _build("a1", "actuated", arm_port="/dev/ttyUSB0")
    with pytest.raises(TargetRefusedError, match="/dev/null is a character device that is not a pseudo-terminal"):
        _build("go1-arm", "locked", arm_port="/dev/null")  # a real adapter (a character device) needs the consent
    locked = _build("go1-arm", "locked", arm_port="/dev/ttyUSB0", allow_hardware=True)  # built, never opened
    assert locked.num_joints == 12 and isinstance(locked.arm, DynamixelArm)  # locked: the servos hold it stowed
    assert _build("go1-arm", "locked").num_joints == 12  # no port: fixed on the trunk, the legs' wire alone
    assert isinstance(_build("go1-arm", "locked"), UnitreeRobot)
    assert _build("go1-arm", "actuated", arm_port="/dev/ttyUSB0", allow_hardware=True).num_joints == 15


def test_a_warm_arm_servo_below_its_own_limit_trips_the_layers_temperature_check() -> None:
    """75 degC on the elbow: below the servo's own Temperature Limit (80, no alert, no latch on the bus) and above
    the layer's 70: the layer trips on the arm's status read, names the servo, and damps both wires."""
    with _whole_robot(ramp_time_s=0.2) as (emu, safe, events):
        arm = safe.robot.arm
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        t0 = emu.clock.now()
        emu.inject(BusFault.OVER_TEMPERATURE, (4, 75))
        _stand(safe, 1.0, until=lambda: safe.safety_state is SafetyState.DAMPED)
        assert safe.safety_state is SafetyState.DAMPED
        event = events[-1]
        assert event.reason == "motor_temperature" and event.detail.startswith("elbow (ID 4) "), event
        assert "75" in event.detail and arm.fault is None  # the servo itself did not alert: the layer caught it
        # the status read that saw it comes every 2 * status_every bus cycles
        assert event.time - t0 <= 2 * arm.config.status_every / arm.config.rate_hz + 1.0 / 50.0 + 1e-9
        _stand(safe, 0.3)
        frames = [c for c in emu.legs.commands() if c.time > event.time + 0.002 + 1e-9]
        assert frames and all(c.damping for c in frames)
        goals = [{w.id: w.value for w in p.writes if w.name == "goal_current"} for p in emu.arm.packets()
                 if p.time > event.time + 1.0 / arm.config.rate_hz and p.written("goal_current")]
        assert goals and all(set(g) == {1, 2, 4} for g in goals)  # every servo still driven, none left limp
        for _ in range(20):  # by the damping: the servos' torques only take energy out
            cmd, _ = emu.plant.arm_command()
            _, dq, _ = emu.plant.read_arm()
            assert (cmd.kp == 0).all() and (cmd.tau * dq <= 0.05).all()  # [W]: at most quantisation
            safe.write(MotorCommand.damping(15, 0.5))
            safe.advance(0.02)


@pytest.mark.parametrize("fault,value", [(BusFault.SILENT_ID, 4), (BusFault.BAD_CRC, 2), (BusFault.OVERLOAD, 1),
                                         (BusFault.OVER_TEMPERATURE, (4, 85)), (BusFault.PORT_CLOSED, None),
                                         (BusFault.LATE_ANSWER, (4, 0.2))])
def test_an_arm_bus_fault_trips_the_safety_layer_and_damps_both_wires(fault: BusFault, value: object) -> None:
    with _whole_robot(ramp_time_s=0.2) as (emu, safe, events):
        clock, arm = emu.clock, safe.robot.arm
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        t0 = clock.now()
        emu.inject(fault, value)
        _stand(safe, 1.0, until=lambda: safe.safety_state is SafetyState.DAMPED)
        assert safe.safety_state is SafetyState.DAMPED
        tripped = events[-1].time  # on the layer's clock: the robot's, i.e. the test's
        reason = events[-1].reason
        assert reason in ("motor_mode", "motor_temperature", "stale_state"), events[-1]
        if fault in (BusFault.SILENT_ID, BusFault.OVER_TEMPERATURE) and reason != "stale_state":
            assert events[-1].detail.startswith("elbow (ID 4) "), events[-1]  # the servo by name, not "motor 15"
        assert arm.fault is not None and arm.fault.kind in ("no_answer", "corrupt", "hardware_error", "port_lost")
        # late is not dead: an unreadable servo latches once silent for the watchdog's time, in that bus cycle (a
        # silent servo's retries and pings take ~42 ms of it); a fault the servo reports latches at once. The layer
        # trips at its next control tick after the latch, or earlier on the stale frame, within its own deadline
        assert arm.fault.time - t0 < arm.config.watchdog_s + 1.0 / arm.config.rate_hz + 0.05
        assert reason == "stale_state" or tripped - arm.fault.time <= 1.0 / 50.0 + 1e-9
        assert tripped - t0 <= safe.robot.config.arm_stale_s + safe.config.stale_timeout_s + 1.0 / 50.0 + 1e-9
        _stand(safe, 0.3)  # the controller goes on; the layer sends damping
        # legs: from the first damping frame on (the link period after the trip), nothing but damping
        frames = [c for c in emu.legs.commands() if c.time > t0]
        first = next(k for k, c in enumerate(frames) if c.damping)
        assert frames[first].time - tripped <= 1.0 / safe.robot.legs.config.rate_hz + 1e-9
        assert all(c.damping for c in frames[first:])
        assert len(frames) - first >= round(0.3 / 0.002)  # every link period of the 0.3 s
        # arm: no goal to an unreadable servo, and the servos' torques only take energy out (damping)
        packets = [p for p in emu.arm.packets() if p.time > arm.fault.time]
        goals = [{w.id: w.value for w in p.writes if w.name == "goal_current"} for p in packets if
                 p.written("goal_current")]
        if fault in (BusFault.SILENT_ID, BusFault.BAD_CRC):
            assert goals and all(value not in g or g[value] == 0 for g in goals)
        if fault is BusFault.PORT_CLOSED:
            assert not packets
        for _ in range(20):
            cmd, _ = emu.plant.arm_command()
            _, dq, _ = emu.plant.read_arm()
            assert (cmd.kp == 0).all() and (cmd.tau * dq <= 0.05).all()  # [W]: at most quantisation
            safe.write(MotorCommand.damping(15, 0.5))
            safe.advance(0.005)
        print(f"\n{fault.value}: injected -> tripped ({reason}) in {(tripped - t0) * 1e3:.0f} ms of the robot's "
              f"clock; {arm.fault}")


def _stand_in_simulation(seconds: float) -> tuple[float, np.ndarray]:
    with MujocoRobot(MujocoRobotConfig(robot="a1-wx200", arm_mode="actuated")) as sim:
        ctrl = StandController(sim.desc)
        for _ in range(int(round(seconds * ctrl.rate_hz))):
            sim.write(ctrl.act(sim.read(), None))
            sim.advance(1.0 / ctrl.rate_hz)
        return float(sim.base_truth().base_position_in_world[2]), sim.read().q[12:].copy()


def test_stand_ten_seconds_with_the_arm_actuated_over_both_wires_matches_simulation() -> None:
    # the acceptance run: 10 s of the robot's time, in lockstep on the test's clock
    seconds = 10.0
    with _whole_robot() as (emu, safe, events):
        t0 = emu.clock.now()
        _stand(safe, seconds)
        elapsed = emu.clock.now() - t0
        height = float(emu.base_truth().base_position_in_world[2])  # before close() damps it down
        arm_q, _, _ = emu.plant.read_arm()
        sim_time = emu.sim_time
        assert safe.safety_state is SafetyState.RUN, [str(e) for e in events]
        assert [e.reason for e in events] == ["fresh_state", "ramp_done"]
        arm = safe.robot.arm
        stats, link = arm.bus_stats(), safe.robot.legs.link_stats()
        assert arm.fault is None
    sim_height, sim_q = _stand_in_simulation(seconds)
    dq = arm_q - sim_q
    print(f"\na1-wx200, arm actuated, {seconds:.0f} s stand through SafeRobot over both wires in lockstep (emulated "
          f"{sim_time:.3f} s): trunk height {height:.4f} m vs {sim_height:.4f} m in simulation "
          f"({(height - sim_height) * 1e3:+.2f} mm); arm q {np.round(arm_q, 4)} vs {np.round(sim_q, 4)} "
          f"(differences {np.round(dq * 1e3, 1)} mrad); arm bus: {stats.cycles} cycles")
    assert elapsed == pytest.approx(seconds)
    assert sim_time == pytest.approx(seconds, abs=0.01)  # one physics period per leg command
    assert height > 0.2 and abs(height - sim_height) < 0.01
    assert np.abs(dq).max() < 0.05
    # on the test's clock nothing is late: every bus cycle and link period ran, no write deadline passed
    assert stats.cycles == pytest.approx(seconds * arm.config.rate_hz, abs=2)
    assert stats.states == stats.cycles and stats.failed_transfers == 0 and stats.deadline_trips == 0
    assert link.deadline_trips == 0 and link.overruns == 0 and stats.overruns == 0


def test_locked_mode_holds_the_arm_stowed_through_the_servos() -> None:
    with _whole_robot("locked", ramp_time_s=0.2) as (emu, safe, _):
        ctrl = StandController(get_robot("a1-wx200", "locked"))
        for _ in range(60):
            safe.write(ctrl.act(safe.read(), None))
            safe.advance(0.02)
        assert safe.num_joints == 12 and safe.safety_state is SafetyState.RUN
        arm_q, _, _ = emu.plant.read_arm()
    # the stowed pose, within the sag of the locked hold's kp 20 under gravity
    np.testing.assert_allclose(arm_q, QuadrupedArmConfig().stowed_q, atol=0.08)


def _arm_goals(emu: RobotEmulator, since: float) -> list[dict[int, int]]:
    """The arm's Goal Current writes on the bus after `since`, each as {servo ID: value}."""
    return [{w.id: w.value for w in p.writes if w.name == "goal_current"} for p in emu.arm.packets()
            if p.time > since and p.written("goal_current")]


def test_a_locked_arm_obeys_the_safety_layer_on_the_wire() -> None:
    """Damped while the layer waits and after an e-stop, ramped into its hold from where it is: never a jump."""
    with _whole_robot("locked", ramp_time_s=0.2) as (emu, safe, _):
        robot, clock = safe.robot, emu.clock
        asked: list[MotorCommand] = []  # what the joined robot asks of the arm device, beside what reaches the bus
        write = robot.arm.write
        robot.arm.write = lambda cmd: asked.append(cmd) or write(cmd)
        limit = robot.arm.law.limit_units
        ctrl = StandController(get_robot("a1-wx200", "locked"))
        held = QuadrupedArmConfig().stowed_q + np.array([0.8, 0.7, -0.7])  # far from its hold: kp 20 would slam it
        qpos = emu.plant.sim.data.qpos.copy()
        qpos[-3:] = held
        emu.reset(qpos)
        start = clock.now()
        for _ in range(3):
            safe.write(MotorCommand.damping(12, 3.0))  # waiting: the layer sends damping
            clock.advance(0.02)
        assert safe.safety_state is SafetyState.WAITING
        assert asked and all((c.kp == 0).all() for c in asked)
        waiting = _arm_goals(emu, start)
        assert waiting and all(abs(v) < 0.05 * limit for goal in waiting for v in goal.values())  # no hold current
        # the ramp: the hold's target leaves the measured pose at the ramp's slew, its gain rises from the start's
        asked.clear()
        ramp_start = clock.now()
        for _ in range(60):
            safe.write(ctrl.act(safe.read(), None))
            safe.advance(0.02)
        assert safe.safety_state is SafetyState.RUN
        ramp = [c for c in asked if c.kp.any()]
        np.testing.assert_allclose(ramp[0].kp, safe.config.ramp_kp)  # the ramp's start gain, not the hold's 20
        assert np.abs(ramp[0].q - held).max() < 0.05  # it starts where the arm is
        steps = np.abs(np.diff([c.q for c in ramp], axis=0))
        assert steps.max() <= safe.config.ramp_slew * 0.02 + 1e-6  # and moves its target at the ramp's slew
        np.testing.assert_allclose(asked[-1].q, robot.config.stowed_q)  # into the hold
        np.testing.assert_allclose(asked[-1].kp, robot.config.hold_kp)
        early = _arm_goals(emu, ramp_start)[:10]
        assert early and all(abs(v) < limit for goal in early for v in goal.values())  # no stall current at once
        arm_q, _, _ = emu.plant.read_arm()
        np.testing.assert_allclose(arm_q, robot.config.stowed_q, atol=0.1)
        # an e-stop damps the locked arm as it damps the legs, and the controller's writes do not undo it
        asked.clear()
        t0 = clock.now()
        safe.estop()
        for _ in range(10):
            safe.write(ctrl.act(safe.read(), None))
            safe.advance(0.02)
        assert asked and all((c.kp == 0).all() and np.allclose(c.kd, safe.config.arm_damping_kd) for c in asked)
        assert all(c.damping for c in emu.legs.commands() if c.time > t0 + 0.004)
        _, dq, _ = emu.plant.read_arm()
        assert np.abs(dq).max() < 0.5  # resting: damping only takes energy out


def test_a_stall_past_the_arms_own_write_deadline_ramps_the_whole_robot_again() -> None:
    """The arm's bus damps after its write deadline (50 ms) while the legs' (here 90 ms) does not trip: the layer,
    told of the arm's trip, ramps again from the measured pose, arm included, before the controller's gains return."""
    events: list[SafetyEvent] = []
    clock = ManualClock()
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode="lockstep"), clock=clock) as emu:
        legs = UnitreeRobot(UnitreeRobotConfig(robot="a1", target_host="127.0.0.1", target_port=9,
                                               write_deadline=0.09), emu.legs_transport, clock=clock)
        arm = DynamixelArm(DynamixelArmConfig(robot="a1-wx200", port=emu.port), handlers=emu.arm_handlers(),
                           clock=clock)
        safe = SafeRobot(QuadrupedArmRobot(legs, arm, QuadrupedArmConfig(arm_mode="actuated")),
                         SafetyConfig(position_table="a1", on_event=events.append, ramp_time_s=0.2))
        with safe:
            _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
            assert safe.safety_state is SafetyState.RUN
            _stand(safe, 0.1)
            asked: list[MotorCommand] = []  # what the joined robot hands the arm's bus thread
            write = arm.write
            arm.write = lambda cmd: asked.append(cmd) or write(cmd)
            stalled_at = clock.now()
            clock.advance(0.07)  # the loop stalls: past the arm's deadline, not the legs', not the stale timeout
            resumed_at = clock.now()
            assert arm.deadline_trips == 1 and legs.deadline_trips == 0
            assert not any(c.damping for c in emu.legs.commands() if stalled_at < c.time <= resumed_at)
            ctrl = StandController(get_robot("a1-wx200", "actuated"))
            full = ctrl.act(safe.read(), None)
            assert safe.safety_state is SafetyState.RAMP and events[-1].reason == "write_deadline", events[-1]
            _stand(safe, 0.1)
            first = next(c for c in asked if c.kp.any())
            np.testing.assert_allclose(first.kp, safe.config.ramp_kp)  # the ramp's start gain on the arm
            assert all((c.kp < full.kp[12:]).all() for c in asked)  # never the controller's gain within the blend
            legs_after = [c for c in emu.legs.commands() if c.time > resumed_at and not c.damping]
            assert legs_after and all((c.wire.kp < full.kp[:12]).all() for c in legs_after)
            np.testing.assert_allclose(legs_after[0].wire.kp, safe.config.ramp_kp)
        assert emu.failure is None, emu.failure


def test_each_joint_is_bounded_by_its_own_devices_gains_and_the_layer_says_what_went_out() -> None:
    with _whole_robot("actuated", ramp_time_s=0.2) as (emu, safe, _):
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        sent = safe.write(MotorCommand.hold(safe.read().q, 300.0, 20.0))
        np.testing.assert_array_equal(sent.kp[:12], 300.0)  # within the legs' driver's bounds
        np.testing.assert_array_equal(sent.kd[:12], 20.0)
        np.testing.assert_array_equal(sent.kp[12:], ARM_KP_MAX)  # the arm's own, as its bus got them
        np.testing.assert_array_equal(sent.kd[12:], ARM_KD_MAX)
        assert safe.robot.gain_limits[0][12:].tolist() == [ARM_KP_MAX] * 3


@pytest.mark.parametrize("arm_mode", ["actuated", "locked"])
@pytest.mark.parametrize("trigger", ["estop", "remote"])
def test_an_estop_damps_the_arm_on_its_bus_as_it_damps_the_legs(arm_mode: str, trigger: str) -> None:
    with _whole_robot(arm_mode, ramp_time_s=0.2) as (emu, safe, events):
        robot, clock = safe.robot, emu.clock
        asked: list[MotorCommand] = []
        write = robot.arm.write
        robot.arm.write = lambda cmd: asked.append(cmd) or write(cmd)
        ctrl = StandController(get_robot("a1-wx200", arm_mode))
        for _ in range(60):
            safe.write(ctrl.act(safe.read(), None))
            safe.advance(0.02)
        assert safe.safety_state is SafetyState.RUN and any(c.kp.any() for c in asked)
        t0 = clock.now()
        if trigger == "estop":
            safe.estop()
        else:
            emu.inject(Fault.REMOTE_L2_B)
        asked.clear()
        for _ in range(15):
            safe.write(ctrl.act(safe.read(), None))  # the controller goes on asking for its hold
            safe.advance(0.02)
            cmd, _ = emu.plant.arm_command()
            _, dq, _ = emu.plant.read_arm()
            assert (cmd.tau * dq <= 0.05).all()  # [W]: the servos' torques only take energy out
        assert safe.safety_state is SafetyState.DAMPED
        assert events[-1].reason == ("software_estop" if trigger == "estop" else "remote_estop")
        damped = asked[3:]  # from the next control tick on (the remote's frame takes a link period to arrive)
        assert damped and all((c.kp == 0).all() and np.allclose(c.kd, safe.config.arm_damping_kd) for c in damped)
        assert all(c.damping for c in emu.legs.commands() if c.time > t0 + 0.06)


def test_the_remote_damps_the_arm_on_its_bus_before_the_control_loop_reads_again() -> None:
    """L2 + B pressed between two reads of a 50 Hz loop: the legs' link latches damping on the frame that shows it,
    and the arm's bus damps from its next cycle on (its goal currents drop to the damping's), before the layer looks."""
    with _whole_robot("actuated", ramp_time_s=0.2) as (emu, safe, events):
        robot, clock = safe.robot, emu.clock
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        _stand(safe, 0.2)
        assert safe.safety_state is SafetyState.RUN
        ctrl = StandController(get_robot("a1-wx200", "actuated"))
        safe.write(ctrl.act(safe.read(), None))
        pressed_at = clock.now()
        damped_before = robot.arm.bus_stats().damping_cycles
        emu.inject(Fault.REMOTE_L2_B)
        clock.advance(0.015)  # the loop has not read again
        assert safe.safety_state is SafetyState.RUN
        assert robot.legs.remote_estop_latched
        assert robot.arm.bus_stats().damping_cycles - damped_before >= 2  # the arm's bus damps, cycle after cycle
        goals = _arm_goals(emu, pressed_at + 0.01)
        assert goals and all(abs(v) < 0.1 * robot.arm.law.limit_units for g in goals for v in g.values())
        emu.clear(Fault.REMOTE_L2_B)
        safe.read()
        assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "remote_estop"


def test_a_press_between_two_reads_trips_the_layer_and_its_reset_releases_the_links_latch() -> None:
    """L2 + B pressed and released between two reads: the layer trips on the legs' link's latch count (the remote
    shows nothing by then), and its reset releases that latch, so the legs and the arm are driven again, not damped."""
    with _whole_robot("actuated", ramp_time_s=0.2) as (emu, safe, events):
        robot, clock = safe.robot, emu.clock
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        emu.inject(Fault.REMOTE_L2_B)
        clock.advance(0.015)
        emu.clear(Fault.REMOTE_L2_B)
        clock.advance(0.015)
        assert robot.legs.remote_estop_latched and not robot.remote().l2_b
        safe.read()
        assert safe.safety_state is SafetyState.DAMPED and events[-1].reason == "remote_estop"
        safe.reset()
        assert not robot.legs.remote_estop_latched
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        since, damped = clock.now(), robot.arm.bus_stats().damping_cycles
        _stand(safe, 0.5)
        frames = [c for c in emu.legs.commands() if c.time > since]
        assert frames and not any(c.damping for c in frames)  # the controller's commands on the legs' wire
        assert robot.arm.bus_stats().damping_cycles == damped  # and on the arm's bus
        assert safe.safety_state is SafetyState.RUN and [e.reason for e in events].count("remote_estop") == 1


def test_hw_emulate_serves_one_robot_on_both_wires(monkeypatch: pytest.MonkeyPatch) -> None:
    # the wires' clients wait up to seconds for an answer: only a hung machine misses that
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", 500)
    proc = subprocess.Popen([sys.executable, "-m", "wbc.cli", "hw", "emulate", "--robot", "go1-arm", "--arm",
                             "actuated", "--seconds", "60"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)
    try:
        line = proc.stdout.readline()  # bounded: the process stops by itself after --seconds
        found = re.search(r"legs on 127\.0\.0\.1:(\d+) \(UDP\), arm on (\S+) \(Dynamixel", line)
        assert found, line
        layout = frame_layout("go1")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sock.bind(("127.0.0.1", 0))
            sock.settimeout(10.0)
            sock.sendto(encode_command(layout, MotorCommand.damping(12, 1.0)), ("127.0.0.1", int(found[1])))
            frame, _ = sock.recvfrom(4096)
        state, _ = decode_state(layout, frame, time=0.0)
        assert state.num_joints == 12
        port = sdk.PortHandler(found[2])
        assert port.openPort()
        try:
            ph = sdk.PacketHandler(2.0)
            for servo_id in range(1, 8):
                assert ph.ping(port, servo_id) == (1020, sdk.COMM_SUCCESS, 0)
        finally:
            port.closePort()
    finally:
        proc.send_signal(signal.SIGINT)  # Ctrl-C: the emulator stops and prints its counts
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    packets = re.search(r"arm bus: packets decoded (\d+)", out)
    assert packets and int(packets[1]) == 7 and "Traceback" not in err


def test_step_metrics_of_a_known_response() -> None:
    from wbc.tools.bench.arm import step_metrics

    t = np.arange(-0.05, 1.0, 0.001)
    tau = 0.05  # a first-order lag of 50 ms toward 0.9 (target 1.0: 0.1 of steady error)
    y = np.where(t < 0, 0.0, 0.9 * (1 - np.exp(-np.clip(t, 0, None) / tau)))
    rise, overshoot, settle, error = step_metrics(t, y, 1.0)
    assert rise == pytest.approx(1e3 * tau * np.log(9), abs=1.5)  # 10 % -> 90 % of a first-order lag
    assert overshoot < 0.01 and settle == pytest.approx(1e3 * tau * np.log(20), abs=1.5)
    assert error == pytest.approx(0.1, abs=1e-3)


def test_bench_arm_builds_everything_before_it_asks_for_real_time(monkeypatch: pytest.MonkeyPatch) -> None:
    """What runs at a real-time priority holds off every other thread of that priority on its CPU, for as long as a
    MuJoCo reference takes to build (~0.1-0.4 s of CPU). The references in simulation, the bus's SDK, the compiled
    check, the plant of the emulators' timing and the legs' robot come before the request; the legs' link connects
    after it, its thread inheriting the priority. Every builder and the request are replaced here by recorders, and
    this process keeps its scheduling; the legs' connect ends the bench."""
    from wbc.tools.bench import arm as bench

    calls: list[str] = []

    class Stop(Exception):
        pass

    class Plant:
        def start(self) -> Plant:
            calls.append("plant built")
            return self

        def __enter__(self) -> Plant:
            return self.start()

        def __exit__(self, *exc: object) -> None:
            calls.append("plant closed")

    class Legs:
        def __init__(self, config: UnitreeRobotConfig) -> None:
            calls.append("legs built")

        def __enter__(self) -> Legs:
            calls.append("legs connected")
            raise Stop

        def __exit__(self, *exc: object) -> None:
            pass

    class Process:
        stdin = io.StringIO()

        def communicate(self, timeout: float) -> tuple[str, str]:
            calls.append("emulator process stopped")
            return "", ""

    def reference(robot: str, q0: np.ndarray, kp: float, kd: float, step: float) -> tuple[np.ndarray, np.ndarray]:
        calls.append(f"reference kp {kp:g}")
        t = np.arange(-0.1, 1.0, 0.002)
        return t, np.where(t < 0.0, q0[2], q0[2] + step)

    monkeypatch.setattr(bench, "_sim_step", reference)
    monkeypatch.setattr(bench, "require", lambda module: calls.append(f"import {module}"))
    monkeypatch.setattr(bench, "load_write_check", lambda: calls.append("compiled code"))
    monkeypatch.setattr(bench, "SharedPlant", lambda config: Plant())
    monkeypatch.setattr(bench, "_start_emulator", lambda robot, seconds, realtime: (
        calls.append("emulator process started"), (Process(), {"host": "127.0.0.1", "port": 9, "pty": "/dev/null"}))[1])
    monkeypatch.setattr(bench, "UnitreeRobot", Legs)
    monkeypatch.setattr(bench, "request_realtime",
                        lambda request: calls.append("real time") or request_realtime(NO_REALTIME))
    with pytest.raises(Stop):
        bench.bench_arm(gains=((20.0, 0.5), (60.0, 1.0)), host_realtime=RealtimeRequest())
    assert calls == ["reference kp 20", "reference kp 60", "import dynamixel_sdk", "compiled code", "plant built",
                     "emulator process started", "legs built", "real time", "legs connected",
                     "emulator process stopped", "plant closed"]


@pytest.mark.slow
def test_bench_arm_measures_rates_and_a_step_against_the_emulator_in_its_own_process(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from wbc.tools.bench import arm as bench

    # the request is recorded, not made: every MuJoCo model of this process is built before it
    calls: list[str] = []
    connect = MujocoRobot._connect
    monkeypatch.setattr(MujocoRobot, "_connect", lambda self: (calls.append("MuJoCo model built"), connect(self))[1])
    monkeypatch.setattr(bench, "request_realtime",
                        lambda request: calls.append("real time") or request_realtime(NO_REALTIME))
    result = bench.bench_arm(rates=(200.0,), seconds=0.5, gains=((20.0, 0.5),), host_realtime=RealtimeRequest())
    assert calls == ["MuJoCo model built", "MuJoCo model built", "real time"]  # the reference, the plant
    (rate,) = result.rates
    assert 100.0 < rate.achieved_hz <= 205.0 and rate.cycles > 50
    bus, sim = result.steps
    assert (bus.source, sim.source) == ("bus", "simulation")
    assert 10.0 < bus.rise_ms < 300.0 and abs(bus.final_error_rad - sim.final_error_rad) < 0.01


# -- the same robot over UDP and a pty against the wall clock (``make test-realtime``) -----------------------------
@contextmanager
def _realtime_robot(mode: str = "realtime", **safety: object) -> Iterator[tuple[RobotEmulator, SafeRobot,
                                                                                  list[SafetyEvent]]]:
    events: list[SafetyEvent] = []
    with RobotEmulator(RobotEmulatorConfig(robot="a1-wx200", mode=mode)) as emu:
        safe = SafeRobot(_build("a1-wx200", "actuated", emu.address, arm=DynamixelArmConfig(port=emu.port, **ARM)),
                         SafetyConfig(position_table="a1", on_event=events.append, **safety))
        with safe:
            yield emu, safe, events
        assert emu.failure is None, emu.failure


def _stand_wall(safe: SafeRobot, seconds: float, until: object = None) -> None:
    ctrl = StandController(get_robot("a1-wx200", "actuated"))
    end = time.monotonic() + seconds
    for _ in range(int(seconds * ctrl.rate_hz) + 1):
        if time.monotonic() >= end or (until is not None and until()):
            return
        safe.write(ctrl.act(safe.read(), None))
        safe.advance(1.0 / ctrl.rate_hz)


@contextmanager
def _frozen_heap() -> Iterator[None]:
    freeze_heap()
    try:
        yield
    finally:
        gc.unfreeze()


@pytest.mark.realtime
def test_stand_ten_seconds_in_real_time_over_udp_and_the_pty_matches_simulation() -> None:
    seconds = 10.0
    # as `wbc hw run` and `wbc hw emulate` do: a full collection of the test session's heap (hundreds of ms) would
    # stall the link and the bus past the safety layer's 0.1 s stale-state limit
    with _frozen_heap(), _realtime_robot() as (emu, safe, events):
        t0 = time.monotonic()
        _stand_wall(safe, 2.5 * seconds, until=lambda: emu.sim_time >= seconds)
        wall = time.monotonic() - t0
        height = float(emu.base_truth().base_position_in_world[2])
        arm_q, _, _ = emu.plant.read_arm()
        sim_time = emu.sim_time
        assert safe.safety_state is SafetyState.RUN, [str(e) for e in events]
        assert [e.reason for e in events] == ["fresh_state", "ramp_done"]
        stats = safe.robot.arm.bus_stats()
        assert safe.robot.arm.fault is None
    sim_height, sim_q = _stand_in_simulation(seconds)
    print(f"\nreal-time stand: emulated {sim_time:.2f} s in {wall:.1f} s of wall time; arm bus period mean "
          f"{stats.period_mean * 1e3:.2f} ms max {stats.period_max * 1e3:.1f} ms, failed reads "
          f"{stats.failed_transfers}")
    assert height > 0.2 and abs(height - sim_height) < 0.01
    assert np.abs(arm_q - sim_q).max() < 0.05
    assert sim_time >= seconds


@pytest.mark.realtime
@pytest.mark.parametrize("fault,value", [(BusFault.SILENT_ID, 4), (BusFault.PORT_CLOSED, None)])
def test_an_arm_bus_fault_trips_the_safety_layer_in_real_time(fault: BusFault, value: object) -> None:
    with _realtime_robot(mode="lockstep", ramp_time_s=0.2) as (emu, safe, _):
        _stand_wall(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        t0 = time.monotonic()
        emu.inject(fault, value)
        _stand_wall(safe, 1.0, until=lambda: safe.safety_state is SafetyState.DAMPED)
        assert safe.safety_state is SafetyState.DAMPED
        print(f"\n{fault.value}: injected -> tripped in {(time.monotonic() - t0) * 1e3:.0f} ms of wall time")


@pytest.mark.realtime
def test_hw_emulate_serves_one_robot_to_the_backends_in_real_time() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "wbc.cli", "hw", "emulate", "--robot", "go1-arm", "--arm",
                             "actuated", "--seconds", "30"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)
    try:
        line = proc.stdout.readline()
        found = re.search(r"legs on 127\.0\.0\.1:(\d+) \(UDP\), arm on (\S+) \(Dynamixel", line)
        assert found, line
        robot = QuadrupedArmRobot(
            UnitreeRobot(UnitreeRobotConfig(robot="go1", target_host="127.0.0.1", target_port=int(found[1]))),
            DynamixelArm(DynamixelArmConfig(robot="go1-arm", port=found[2], **ARM)))
        with robot:
            first = robot.read()
            for _ in range(10):
                robot.advance(0.01)
            assert robot.read().num_joints == 15 and robot.read().tick > first.tick
    finally:
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    packets = re.search(r"arm bus: packets decoded (\d+)", out)
    assert packets and int(packets[1]) > 50 and "Traceback" not in err


def test_a_stall_past_both_write_deadlines_says_the_legs_and_the_arm_each_damped_once() -> None:
    """A 70 ms stall: the legs' link and the arm's bus each damp once on their 50 ms write deadline. The layer's event
    counted them together as "damped itself 2 time(s)", as if the robot had stalled twice."""
    with _whole_robot(ramp_time_s=0.2) as (emu, safe, events):
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        assert safe.safety_state is SafetyState.RUN
        emu.clock.advance(0.07)  # the loop stalls past both deadlines, not the stale timeout
        _stand(safe, 0.02)
        assert events[-1].reason == "write_deadline", events[-1]
        assert events[-1].detail.startswith("the legs and the arm each damped once since the last look: "), events[-1]


def test_a_silent_arm_servo_is_named_as_the_stale_source_while_the_legs_answer() -> None:
    """The elbow stops answering: the joined frame goes stale, and the layer's trip says it is the arm's state, the
    legs' stream fresh. It said "tick N unchanged" as if the robot's stream had stopped."""
    with _whole_robot(ramp_time_s=0.2) as (emu, safe, events):
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        emu.inject(BusFault.SILENT_ID, 4)
        _stand(safe, 1.0, until=lambda: safe.safety_state is SafetyState.DAMPED)
        assert events[-1].reason == "stale_state", events[-1]
        assert re.fullmatch(r"the arm's state: 0\.\d{3} s old, its bus's servos not answering \(the legs' state "
                            r"stream fresh, \d+ ms old; limit 0\.1 s\)", events[-1].detail), events[-1]
        assert "stopped answering" in events[-1].remedy and "arm's cable" in events[-1].remedy


def test_a_stalled_host_loop_is_named_as_the_stale_source_while_the_robot_answers() -> None:
    """The control loop stops for 300 ms (a SIGSTOP) while both devices answer: the layer trips at its next read and
    says that the host's loop was late since its last read. It said that the robot's tick stood still."""
    with _whole_robot(ramp_time_s=0.2) as (emu, safe, events):
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        emu.clock.advance(0.3)
        _stand(safe, 0.02)
        assert events[-1].reason == "stale_state", events[-1]
        assert events[-1].detail.startswith("the host's control loop was late: 3"), events[-1]
        assert events[-1].detail.endswith("ms since its last read (limit 100 ms), while the robot's state stream "
                                          "went on"), events[-1]


def test_silent_legs_are_named_as_the_stale_source() -> None:
    with _whole_robot(ramp_time_s=0.2) as (emu, safe, events):
        _stand(safe, 3.0, until=lambda: safe.safety_state is SafetyState.RUN)
        emu.inject(Fault.SILENCE)
        _stand(safe, 1.0, until=lambda: safe.safety_state is SafetyState.DAMPED)
        assert events[-1].reason == "stale_state", events[-1]
        assert re.fullmatch(r"the legs' state stream: tick \d+ unchanged for 0\.1\d\d s \(limit 0\.1 s\)",
                            events[-1].detail), events[-1]
