"""`check_robot`: the contract every `Robot` backend must honour (like Gymnasium's ``check_env``).

It drives a robot through its lifecycle and checks shapes, units-level sanity, validation, clamping and the tick
semantics that let a caller detect stale frames. Run it in a backend's tests; it raises `RobotContractError`
listing every violation it found.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wbc.errors import CommandError, RobotNotConnectedError, WbcError
from wbc.hardware.robot import Robot
from wbc.types import MotorCommand, RobotState

__all__ = ["RobotContractError", "check_robot"]


class RobotContractError(WbcError, AssertionError):
    """A robot backend broke the `Robot` contract; the message lists each violation."""


def _check_state(state: object, n: int, problems: list[str]) -> None:
    if not isinstance(state, RobotState):
        problems.append(f"read() returned {type(state).__name__}, not RobotState")
        return
    shapes = {"q": (n,), "dq": (n,), "tau_est": (n,), "imu_quat": (4,), "gyro_in_body": (3,),
              "accel_in_body": (3,), "foot_force": (4,)}
    for name, shape in shapes.items():
        a = np.asarray(getattr(state, name))
        if a.shape != shape:
            problems.append(f"RobotState.{name} has shape {a.shape}, expected {shape}")
        elif not np.all(np.isfinite(a)):
            problems.append(f"RobotState.{name} holds non-finite values")
    if not isinstance(state.tick, int | np.integer):
        problems.append(f"RobotState.tick is {type(state.tick).__name__}, expected int")
    if np.asarray(state.imu_quat).shape == (4,) and abs(np.linalg.norm(state.imu_quat) - 1.0) > 1e-3:
        problems.append(f"RobotState.imu_quat is not unit length (norm {np.linalg.norm(state.imu_quat):.4f})")
    if np.asarray(state.foot_force).shape == (4,) and np.any(np.asarray(state.foot_force) < 0):
        problems.append("RobotState.foot_force has negative entries")


def check_robot(make_robot: Callable[[], Robot], *, dt: float = 0.002) -> None:
    """Check a backend against the `Robot` contract.

    Args:
        make_robot: builds a fresh, unconnected robot.
        dt: control period used when advancing time [s].

    Raises:
        RobotContractError: listing every violation.
    """
    problems: list[str] = []
    robot = make_robot()
    if robot.is_connected:
        problems.append("a new robot reports is_connected before connect()")
    for action, call in (("read", robot.read), ("advance", lambda: robot.advance(dt))):
        try:
            call()
            problems.append(f"{action}() before connect() did not raise RobotNotConnectedError")
        except RobotNotConnectedError:
            pass
    with robot:
        if not robot.is_connected:
            problems.append("is_connected is False inside the context manager")
        n = robot.num_joints
        if len(robot.limits.names) != n or tuple(robot.limits.names) != tuple(robot.joint_names):
            problems.append("limits.names differ from joint_names")
        first = robot.read()
        _check_state(first, n, problems)
        lim = robot.limits

        hold = MotorCommand.hold(np.clip(first.q, lim.lower, lim.upper), 20.0, 1.0)
        sent = robot.write(hold)
        if not isinstance(sent, MotorCommand) or sent.num_joints != n:
            problems.append("write() did not return the MotorCommand that was sent")
        robot.advance(dt)
        second = robot.read()
        _check_state(second, n, problems)
        if isinstance(second, RobotState) and isinstance(first, RobotState) and not second.tick > first.tick:
            problems.append(f"tick did not advance across advance(dt): {first.tick} -> {second.tick}")

        wild = MotorCommand(q=lim.upper + 10.0, dq=lim.velocity_limit * 10.0, kp=np.full(n, 1e6),
                            kd=np.full(n, 1e6), tau=-(lim.torque_limit + 100.0))
        clamped = robot.write(wild)
        if np.any(clamped.q > lim.upper + 1e-12) or np.any(clamped.tau < -lim.torque_limit - 1e-12):
            problems.append("write() let an out-of-range position or torque through unclamped")
        if np.any(np.abs(clamped.dq) > lim.velocity_limit + 1e-12):
            problems.append("write() let an out-of-range velocity through unclamped")
        robot.write(hold)

        for bad_n in (n - 1, n + 1):
            try:
                robot.write(MotorCommand.hold(np.zeros(bad_n), 1.0, 0.1))
                problems.append(f"write() accepted a command for {bad_n} joints (robot has {n})")
            except CommandError:
                pass
            except Exception as exc:  # noqa: BLE001 - any other failure is a contract violation to report
                problems.append(f"write() of {bad_n} joints raised {type(exc).__name__}, not CommandError")
        try:
            robot.write(None)  # type: ignore[arg-type]
            problems.append("write(None) did not raise CommandError")
        except CommandError:
            pass
        except Exception as exc:  # noqa: BLE001
            problems.append(f"write(None) raised {type(exc).__name__}, not CommandError")
    if robot.is_connected:
        problems.append("is_connected is True after leaving the context manager")
    try:
        robot.read()
        problems.append("read() after close() did not raise RobotNotConnectedError")
    except RobotNotConnectedError:
        pass
    if problems:
        raise RobotContractError(f"{type(robot).__name__} breaks the Robot contract:\n- " + "\n- ".join(problems))
