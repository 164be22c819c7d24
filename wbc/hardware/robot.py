"""`Robot`: the one interface shared by the simulator backend and real robots.

Lifecycle: ``connect()`` -> (``read()`` / ``write()`` / ``advance()``)* -> ``close()``; a robot is also a context
manager. `write` validates and clamps every command in this base class, so no backend can skip it: a command of the
wrong length raises `CommandError` (non-finite values cannot even be built, see `MotorCommand`), and every field is
clamped to the motor's limits before the backend's `_send` sees it. `write` returns what was actually sent.

A command whose every value lies within the limits (the usual case) is sent as it is, and `write` returns the same
object: the check is one compiled pass over its rows (`within_bounds`), loaded when the robot connects.

`advance(dt)` lets ``dt`` seconds of robot time pass while the last command holds: a simulator steps its physics, a
real robot's backend waits for its clock. The runner therefore has one loop for both.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType

import numba
import numpy as np

from wbc.errors import CommandError, ConfigError, RobotNotConnectedError
from wbc.interrupts import HeldInterrupts
from wbc.robots.joint_table import JointTable
from wbc.types import MotorCommand, RobotState

__all__ = ["Robot", "KP_MAX", "KD_MAX", "COMMAND_ROWS", "clamp_command", "command_bounds", "exceeded_rows",
           "load_write_check", "within_bounds"]

COMMAND_ROWS = ("q", "dq", "kp", "kd", "tau")
"""A command's rows, in the order of `MotorCommand.rows` and `command_bounds`."""

KP_MAX = 1000.0  # [N m / rad] largest position gain a Unitree driver encodes (int16 / 32)
KD_MAX = 100.0  # [N m s / rad] largest velocity gain accepted (the driver encodes more; none is stable above)


def command_bounds(limits: JointTable, kp_max: float | np.ndarray = KP_MAX,
                   kd_max: float | np.ndarray = KD_MAX) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of a command's rows (q, dq, kp, kd, tau), each (5, n): what `clamp_command` clips to.

    `kp_max` and `kd_max` are the robot's own gain bounds (`Robot.gain_limits`).
    """
    zeros = np.zeros_like(limits.lower)
    lower = np.array((limits.lower, -limits.velocity_limit, zeros, zeros, -limits.torque_limit))
    upper = np.array((limits.upper, limits.velocity_limit, zeros + kp_max, zeros + kd_max, limits.torque_limit))
    return lower, upper


def exceeded_rows(cmd: MotorCommand, bounds: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Which of the command's rows (`COMMAND_ROWS`) hold a value outside `bounds`: five booleans."""
    rows = cmd.rows
    return ((rows < bounds[0]) | (rows > bounds[1])).any(axis=1)


def _waits_for_the_close(what: str) -> str:
    """The line said when a signal comes during a robot's close."""
    return f"wbc: {what} waits until the robot is closed (a real robot's legs damp, its arm parks), then acts"


@numba.njit(cache=True, nogil=True)
def within_bounds(rows: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> bool:  # pragma: no cover - compiled
    """Whether every value of `rows` lies within [`lower`, `upper`] (all (5, n)); a NaN lies within no bounds.

    One compiled pass, stopping at the first value outside: the check of every write and of the runner's count of
    clamped ticks, where `exceeded_rows` (which says which rows) costs several numpy calls.
    """
    for i in range(rows.shape[0]):
        for j in range(rows.shape[1]):
            if not lower[i, j] <= rows[i, j] <= upper[i, j]:
                return False
    return True


def load_write_check() -> None:
    """Load the compiled check of every write (`within_bounds`) now, from numba's cache on disk.

    A process's first call of compiled code loads numba itself: some 0.2-0.5 s of CPU. `Robot.connect` calls this,
    so that the cost does not land on the first command; a process that asks for real-time scheduling calls it
    before asking (`wbc.hardware.io_process`), so that the cost is not paid at a real-time priority, where it holds
    off every other real-time thread of the same priority on that CPU. Loaded once per process; later calls cost
    two compiled calls.
    """
    # a command's rows are read-only, which numba compiles apart
    zeros, frozen = np.zeros((5, 1)), np.zeros((5, 1))
    frozen.setflags(write=False)
    within_bounds(zeros, zeros, zeros)
    within_bounds(frozen, zeros, zeros)


def clamp_command(cmd: MotorCommand, limits: JointTable,
                  bounds: tuple[np.ndarray, np.ndarray] | None = None) -> MotorCommand:
    """Clamp a command to the motors' limits: position range, speed, gains and torque.

    Args:
        cmd: a (validated) command.
        limits: the motors' limits.
        bounds: `command_bounds(limits)`, when the caller keeps them (the hot path of every write).
    """
    lower, upper = bounds if bounds is not None else command_bounds(limits)
    rows = cmd.stacked()
    np.minimum(np.maximum(rows, lower, out=rows), upper, out=rows)
    # `cmd` was validated when it was built; clipping keeps it valid, so skip re-validation on this hot path.
    return MotorCommand._trusted(rows)


def _refuse_invalid(robot: str, cmd: MotorCommand, joints: tuple[str, ...]) -> None:
    """Raise `CommandError` naming the rows and joints of `cmd` that hold a non-finite value or a negative gain.

    Clamping would carry either to the motors: a NaN lies within no bounds (it clamps to NaN), and a negative gain
    clamps to 0, which turns a joint the controller meant to hold limp without a word.
    """
    def named(bad: np.ndarray) -> str:
        rows, cols = np.nonzero(bad)
        names = [f"{COMMAND_ROWS[r]}[{joints[c] if c < len(joints) else c}]" for r, c in zip(rows, cols, strict=True)]
        return ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")

    bad = ~np.isfinite(cmd.rows)
    if bad.any():
        raise CommandError(f"{robot}.write: the command holds a non-finite value at {named(bad)}; refused before it "
                           "reached a motor")
    negative = np.zeros_like(bad)
    negative[2:4] = cmd.rows[2:4] < 0  # kp, kd
    if negative.any():
        raise CommandError(f"{robot}.write: the command holds a negative gain at {named(negative)} (gains must be "
                           ">= 0; a negative one would be sent as 0, the joint limp); refused before it reached a "
                           "motor")


class Robot(ABC):
    """Abstract robot: proprioception in, low-level motor commands out.

    Attributes:
        gain_limits: the largest (kp, kd) a write passes on, each a number or one per joint: the Unitree driver's
            by default; a device whose loop is closed slower or over less (the arm's current loop over its bus) sets
            its own, and a robot of several devices (or a wrapper) gives each joint its device's.
    """

    gain_limits: tuple[float | np.ndarray, float | np.ndarray] = (KP_MAX, KD_MAX)

    def __init__(self) -> None:
        self._connected = False
        self._last_written: tuple[MotorCommand, MotorCommand] | None = None
        self._bounds: tuple[JointTable, tuple[np.ndarray, np.ndarray]] | None = None

    # -- lifecycle ------------------------------------------------------------------------------------------------
    @property
    def is_connected(self) -> bool:
        """True between `connect()` and `close()`."""
        return self._connected

    def connect(self) -> None:
        """Open the connection (or build the simulation). Idempotent."""
        if not self._connected:
            load_write_check()  # here, not at the first command
            self._connect()
            self._connected = True

    def close(self) -> None:
        """Release the connection; a real robot is left in damping mode. Idempotent.

        Called in the main thread, the close is never cut by Ctrl-C or a request to end (SIGTERM, SIGHUP): each
        waits for its end, then the first acts (`HeldInterrupts`). A real robot's close damps its legs and parks an
        arm, which a cut close would leave limp.
        """
        if self._connected:
            with HeldInterrupts(_waits_for_the_close):
                self._close()
                self._connected = False

    def __enter__(self) -> Robot:
        self.connect()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def _require_connected(self, action: str) -> None:
        if not self._connected:
            raise RobotNotConnectedError(f"{type(self).__name__}.{action}: not connected; call .connect() first")

    # -- data -----------------------------------------------------------------------------------------------------
    @property
    @abstractmethod
    def joint_names(self) -> tuple[str, ...]:
        """Actuated joints, house order."""

    @property
    @abstractmethod
    def limits(self) -> JointTable:
        """Per-joint motor limits used to clamp commands."""

    @property
    def num_joints(self) -> int:
        """Number of actuated joints."""
        return len(self.joint_names)

    def read(self) -> RobotState:
        """The latest proprioceptive frame (compare `tick` with the previous frame's to detect a stale one)."""
        self._require_connected("read")
        return self._read()

    def write(self, cmd: MotorCommand) -> MotorCommand:
        """Validate, clamp and send a command; return what was sent.

        A command built unchecked (`MotorCommand.trusted`) is held to what the constructor checks: a non-finite value
        or a negative gain is refused here, since clamping would carry it to the motors (a NaN lies within no bounds,
        and clamps to NaN; a negative kp or kd clamps to 0, a limp joint the controller never asked for).

        Raises:
            CommandError: the command has the wrong number of joints, or holds a non-finite value or a negative gain
                (nothing is sent; the robot keeps the last command it accepted, and its device's write deadline
                damps it if no valid command follows).
            RobotNotConnectedError: not connected.
        """
        self._require_connected("write")
        if not isinstance(cmd, MotorCommand):
            raise CommandError(f"{type(self).__name__}.write: expected a MotorCommand, got {type(cmd).__name__}")
        if cmd.num_joints != self.num_joints:
            raise CommandError(
                f"{type(self).__name__}.write: command has {cmd.num_joints} joints, this robot has "
                f"{self.num_joints} ({', '.join(self.joint_names)})"
            )
        last = self._last_written
        if last is not None and last[0] is cmd:
            applied = last[1]  # commands are immutable: the same object clamps to the same result
        else:
            limits = self.limits
            if self._bounds is None or self._bounds[0] is not limits:
                self._bounds = (limits, command_bounds(limits, *self.gain_limits))
            lower, upper = self._bounds[1]
            # within the limits, clamping would change nothing: the command is sent as it is
            if within_bounds(cmd.rows, lower, upper):
                applied = cmd
            else:
                _refuse_invalid(type(self).__name__, cmd, self.joint_names)
                applied = clamp_command(cmd, limits, self._bounds[1])
            self._last_written = (cmd, applied)
        self._send(applied)
        return applied

    def advance(self, dt: float) -> None:
        """Let `dt` seconds of robot time pass under the last command [s].

        Raises:
            ConfigError: `dt` is not positive, or not a period the backend can run (`MujocoRobot`: a whole number of
                physics steps).
            RobotNotConnectedError: not connected.
        """
        self._require_connected("advance")
        if not dt > 0:
            raise ConfigError(f"advance: dt must be a positive number of seconds, got {dt}")
        self._advance(dt)

    # -- backend hooks --------------------------------------------------------------------------------------------
    @abstractmethod
    def _connect(self) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...

    @abstractmethod
    def _read(self) -> RobotState: ...

    @abstractmethod
    def _send(self, cmd: MotorCommand) -> None: ...

    @abstractmethod
    def _advance(self, dt: float) -> None: ...
