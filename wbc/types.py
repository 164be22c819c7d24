"""Data that crosses the robot interface: what a robot reports, what a controller asks for.

All three are frozen dataclasses of numpy arrays. Joint vectors follow the house joint order: legs FR, FL, RR, RL x
(hip, thigh, calf) = 0..11, then the arm (waist yaw, shoulder pitch, elbow pitch) = 12..14 when the arm is actuated.
SI units; quaternions are (w, x, y, z).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.errors import CommandError

__all__ = ["BaseTruth", "RobotState", "MotorCommand", "VelocityCommand"]


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class RobotState:
    """One frame of proprioception, as a real robot delivers it (no simulator truth in here).

    Attributes:
        tick: frame counter of the robot's own clock; it advances with every fresh frame. A frame whose tick did not
            advance since the last read is stale (the Unitree SDK hands back its last good frame after a failed
            receive).
        time: timestamp of the frame [s], robot clock.
        q: joint positions, shape (n,) [rad].
        dq: joint velocities, shape (n,) [rad/s].
        tau_est: estimated joint torques, shape (n,) [N m].
        imu_quat: trunk orientation from the IMU, (w, x, y, z), body to world.
        gyro_in_body: angular velocity of the trunk in the IMU (body) frame, shape (3,) [rad/s].
        accel_in_body: specific force measured by the accelerometer in the body frame, shape (3,) [m/s^2]
            (reads +9.81 on z when standing still).
        foot_force: contact force estimates at the feet FR, FL, RR, RL, shape (4,) [N].

    The fields need not be of one instant: a real robot's IMU and foot sensors have latencies of their own, and in
    `MujocoRobot` ``tau_est``, the IMU fields and ``foot_force`` are MuJoCo's values at the start of the last physics
    step, one step (2 ms) older than ``q`` and ``dq``.
    """

    tick: int
    time: float
    q: np.ndarray
    dq: np.ndarray
    tau_est: np.ndarray
    imu_quat: np.ndarray
    gyro_in_body: np.ndarray
    accel_in_body: np.ndarray
    foot_force: np.ndarray

    @property
    def num_joints(self) -> int:
        """Number of joints reported."""
        return int(self.q.shape[0])


_COMMAND_FIELDS = ("q", "dq", "kp", "kd", "tau")
_FIELD_ROW = {name: row for row, name in enumerate(_COMMAND_FIELDS)}


def _rows_valid(rows: np.ndarray) -> bool:
    """Whether a (5, n) command array has n > 0, every entry finite and both gain rows non-negative.

    numpy, not compiled: this runs in the hardware I/O process too, where a compiled function's first call (loading
    it, ~0.4 s) would stall the link.
    """
    return rows.shape[1] > 0 and bool(np.isfinite(rows).all()) and rows[2:4].min() >= 0.0


def _adopt_rows(cmd: MotorCommand, rows: np.ndarray) -> None:
    """Make a (5, n) array, read-only from here on, the storage of `cmd`'s fields.

    The array is kept as ``_rows``: `MotorCommand.rows` hands it out without stacking the fields again, and each field
    is a view of its row, made when first read (`MotorCommand.__getattr__`): a command that goes from a controller to
    a robot's clamp and motors is read as rows, so most fields are never made.
    """
    rows.setflags(write=False)
    state = cmd.__dict__
    state.clear()  # the arrays given to the constructor, if any, give way to the rows' views
    state["_rows"] = rows


@dataclass(frozen=True)
class MotorCommand:
    """Per-joint low-level command with Unitree semantics.

    Every motor applies, at its own rate, tau = kp (q - q_measured) + kd (dq - dq_measured) + tau, clamped to the
    motor's torque limit. Construction checks the command: every field must be a finite 1-D array, all of one
    length, with kp and kd non-negative; anything else raises `CommandError` before it can reach a motor.

    Attributes:
        q: target joint positions, shape (n,) [rad].
        dq: target joint velocities, shape (n,) [rad/s].
        kp: position gains, shape (n,) [N m / rad], >= 0.
        kd: velocity gains, shape (n,) [N m s / rad], >= 0.
        tau: feed-forward torques, shape (n,) [N m].
    """

    q: np.ndarray
    dq: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    tau: np.ndarray

    def __post_init__(self) -> None:
        # fast path (every control tick): the five fields stack into one (5, n) float array, checked in two
        # reductions; anything malformed (ragged, not 1-D, not numeric) or faulty falls through to the slow path,
        # which names the fault.
        q, dq, kp, kd, tau = self.q, self.dq, self.kp, self.kd, self.tau
        nd = np.ndarray
        if (type(q) is nd and type(dq) is nd and type(kp) is nd and type(kd) is nd and type(tau) is nd
                and not (q.dtype.kind == "c" or dq.dtype.kind == "c" or kp.dtype.kind == "c" or kd.dtype.kind == "c"
                         or tau.dtype.kind == "c")):  # complex: the cast would drop the imaginary part (slow path)
            try:
                stacked = np.array((q, dq, kp, kd, tau), dtype=np.float64)
            except (TypeError, ValueError):
                stacked = None
            if stacked is not None and stacked.ndim == 2 and _rows_valid(stacked):
                _adopt_rows(self, stacked)
                return
        # slow path: find the first fault and name it
        n = None
        for name in _COMMAND_FIELDS:
            raw = getattr(self, name)
            if np.iscomplexobj(raw):  # a float cast would drop the imaginary part with a mere warning
                raise CommandError(f"MotorCommand.{name}: complex values; a command holds real numbers")
            try:
                a = np.array(raw, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise CommandError(f"MotorCommand.{name}: not a numeric array ({exc})") from None
            if a.ndim != 1:
                raise CommandError(f"MotorCommand.{name}: expected a 1-D array, got shape {a.shape}")
            if n is None:
                n = a.shape[0]
            elif a.shape[0] != n:
                raise CommandError(
                    f"MotorCommand.{name}: length {a.shape[0]} differs from MotorCommand.q length {n}"
                )
            bad = ~np.isfinite(a)
            if bad.any():
                raise CommandError(
                    f"MotorCommand.{name}: non-finite value at joint index {int(np.flatnonzero(bad)[0])}"
                )
            if name in ("kp", "kd") and (a < 0).any():
                raise CommandError(
                    f"MotorCommand.{name}: negative gain at joint index {int(np.flatnonzero(a < 0)[0])}"
                )
            object.__setattr__(self, name, _readonly(a))

    def __eq__(self, other: object) -> bool:
        """Equal when every field holds the same values, of the same length (NaN, in a trusted command, equals nothing).

        The dataclass's own comparison compared the fields' arrays as a tuple, asking an array for its truth value.
        """
        if not isinstance(other, MotorCommand):
            return NotImplemented
        return bool(np.array_equal(self.rows, other.rows))

    def __getattr__(self, name: str) -> np.ndarray:
        """A field of a command stored as rows (see `_adopt_rows`), made when first read: a view of its row."""
        row, rows = _FIELD_ROW.get(name), self.__dict__.get("_rows")
        if row is None or rows is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        view = rows[row]
        self.__dict__[name] = view
        return view

    @property
    def num_joints(self) -> int:
        """Number of joints commanded."""
        rows = self.__dict__.get("_rows")  # read off the rows where they are the storage: no field is made
        return int(self.q.shape[0] if rows is None else rows.shape[1])

    @property
    def rows(self) -> np.ndarray:
        """The five fields as rows of one read-only (5, n) array: q, dq, kp, kd, tau.

        The fields' own storage when they are its rows, as a validated command's are (no copy).
        """
        rows = self.__dict__.get("_rows")
        if rows is not None:
            return rows
        out = np.array((self.q, self.dq, self.kp, self.kd, self.tau))
        out.setflags(write=False)
        return out

    def stacked(self) -> np.ndarray:
        """The five fields as rows of one (5, n) array: q, dq, kp, kd, tau (a new array)."""
        return self.rows.copy()

    @classmethod
    def from_rows(cls, rows: np.ndarray) -> MotorCommand:
        """A command from one (5, n) float array of rows q, dq, kp, kd, tau, checked as the constructor checks.

        The array becomes the command's storage (read-only from here on), so nothing is stacked or copied. Anything the
        fast check refuses goes through the constructor, which names the fault.

        Raises:
            CommandError: not a (5, n) array, or a field the constructor refuses.
        """
        if not (isinstance(rows, np.ndarray) and rows.ndim == 2 and rows.shape[0] == 5):
            raise CommandError(f"MotorCommand.from_rows: expected a (5, n) array of rows q, dq, kp, kd, tau, got "
                               f"{type(rows).__name__} of shape {np.shape(rows)}")
        if rows.dtype == np.float64 and _rows_valid(rows):
            obj = object.__new__(cls)
            _adopt_rows(obj, rows)
            return obj
        return cls(*rows)

    @classmethod
    def trusted(cls, rows: np.ndarray) -> MotorCommand:
        """A command from a (5, n) float array of rows q, dq, kp, kd, tau, unchecked: its caller guarantees them.

        For code that itself guarantees what the constructor checks (every entry finite, both gain rows non-negative):
        a controller whose compiled tick checks the rows it fills (the MPC's, `wbc.mpc.compiled.command_rows`), or
        code that derives a command from a validated one (clamping it). Nothing is checked here. Every robot still
        clamps a command to its motors' limits before it reaches a wire or a simulator (`wbc.hardware.robot.Robot`'s
        ``write``), whoever built it. `rows` becomes read-only and is shared by the fields.
        """
        obj = object.__new__(cls)
        _adopt_rows(obj, rows)
        return obj

    _trusted = trusted  # the name the robots' clamping and the hardware layer call it by

    @classmethod
    def hold(cls, q: np.ndarray, kp: float | np.ndarray, kd: float | np.ndarray) -> MotorCommand:
        """A PD hold of positions `q` with zero target velocity and no feed-forward torque."""
        q = np.asarray(q, dtype=np.float64)
        n = q.shape[0]
        return cls(
            q=q, dq=np.zeros(n), kp=np.broadcast_to(kp, (n,)).copy(), kd=np.broadcast_to(kd, (n,)).copy(),
            tau=np.zeros(n),
        )

    @classmethod
    def damping(cls, n: int, kd: float) -> MotorCommand:
        """Pure damping (kp = 0, zero targets): the safe state a motor falls back to."""
        return cls(q=np.zeros(n), dq=np.zeros(n), kp=np.zeros(n), kd=np.full(n, float(kd)), tau=np.zeros(n))


@dataclass(frozen=True)
class VelocityCommand:
    """Desired base motion, in the yaw-aligned body frame.

    Attributes:
        vx: forward velocity [m/s].
        vy: lateral velocity (left positive) [m/s].
        yaw_rate: yaw rate (counter-clockwise positive) [rad/s].
    """

    vx: float = 0.0
    vy: float = 0.0
    yaw_rate: float = 0.0

    def as_array(self) -> np.ndarray:
        """(vx, vy, yaw_rate) as a float array."""
        return np.array([self.vx, self.vy, self.yaw_rate], dtype=np.float64)


@dataclass(frozen=True)
class BaseTruth:
    """The trunk's true state as a runner logs it every tick: the simulator's (part of `SimTruth`) or motion capture.

    Attributes:
        base_position_in_world: trunk origin, shape (3,) [m].
        base_quat: trunk orientation (w, x, y, z).
        base_linvel_in_world: trunk origin velocity, shape (3,) [m/s].
        base_angvel_in_body: trunk angular velocity in the trunk frame, shape (3,) [rad/s].
    """

    base_position_in_world: np.ndarray
    base_quat: np.ndarray
    base_linvel_in_world: np.ndarray
    base_angvel_in_body: np.ndarray
