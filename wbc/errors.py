"""Exception tree of `wbc`: one root, one subclass per kind of failure.

Messages say what was wrong and how to fix it (valid names, the field at fault, the extra to install).
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from os import PathLike

__all__ = [
    "CONTROLLER_ERRORS",
    "WbcError",
    "UnknownNameError",
    "with_aliases",
    "ConfigError",
    "CommandError",
    "FileFieldError",
    "InputFileError",
    "ScenarioError",
    "RobotNotConnectedError",
    "MissingExtraError",
    "BenchError",
    "AnalysisError",
    "PolicyInputError",
    "NetworkMismatchError",
    "MpcProblemFileError",
    "RecordError",
    "ResultsDirError",
    "ClusterError",
    "EpisodeError",
    "EpisodeFileError",
    "MissingCapabilityError",
    "FrameError",
    "SafetyResetError",
    "PortBusyError",
    "TargetRefusedError",
    "RobotLinkError",
    "NoStateStreamError",
    "TargetInUseError",
    "ArmRefusedError",
    "IoProcessStopped",
    "PacketError",
    "SerialPortError",
    "StandUpError",
]

CONTROLLER_ERRORS: tuple[type[BaseException], ...] = (Exception, SystemExit)
"""What a controller's code may raise that costs only its own part (a trial, a check): every `Exception`, and
`SystemExit` (a plug-in that calls ``sys.exit``, or an ``argparse`` inside it that exits), which would otherwise end
the whole command without a word and lose the other controllers' trials. `KeyboardInterrupt` still stops the run."""


def _rebuild_error(cls: type[WbcError], args: tuple[object, ...]) -> WbcError:
    """An error of `cls` with `args`, its constructor not called (`WbcError.__reduce__`; pickle sets its state)."""
    err = cls.__new__(cls, *args)
    err.args = args
    return err


class WbcError(Exception):
    """Root of every error raised on purpose by `wbc`.

    It pickles with its message and attributes whatever its subclass's constructor takes, so that an error raised in
    a worker process (a bench's spawned process, an arena worker) reaches the parent as itself.
    """

    def __reduce__(self) -> tuple[object, ...]:
        """Rebuild without calling the constructor: the message (``args``) and the attributes (``__dict__``).

        A subclass whose constructor takes other arguments than its message (`UnknownNameError`, `FileFieldError`)
        could not be rebuilt from ``args`` alone, and the pool that carried it back would break instead.
        """
        return _rebuild_error, (type(self), self.args), self.__dict__ or None


def with_aliases(name: str, aliases: Mapping[str, str]) -> str:
    """``go1-arm (or go1)``: `name` with the aliases (alias -> name) that name it, as a refusal lists it."""
    others = [alias for alias, named in aliases.items() if named == name]
    return f"{name} (or {', '.join(others)})" if others else name


class UnknownNameError(WbcError, KeyError):
    """A name (robot, arm mode, controller ...) is not in its registry; the message lists the valid ones.

    When a valid name (or an alias of one) is close to the one given (`difflib.get_close_matches`, a typo such as
    ``mcp`` for ``mpc``), the message suggests it first.

    Attributes:
        kind: what the name names (``controller``, ``robot`` ...).
        name: the name given.
        valid: the valid names, sorted, each once.
        aliases: other names accepted for valid ones (alias -> valid name), listed beside them: ``go1-arm (or go1)``.
        suggestion: the valid name or alias closest to `name`, or None when none is close.
    """

    def __init__(self, kind: str, name: str, valid: list[str] | tuple[str, ...], *, where: str = "",
                 aliases: Mapping[str, str] | None = None) -> None:
        """`where` (e.g. ``scenario 'turn'``), when given, opens the message: whose names these are."""
        self.kind = kind
        self.name = name
        self.valid = tuple(sorted(set(valid)))  # each once, though two sources may name it
        self.aliases = dict(sorted((aliases or {}).items()))
        known = self.valid + tuple(self.aliases)
        close = difflib.get_close_matches(str(name), known, n=1) if len(str(name)) <= 200 else []
        self.suggestion = close[0] if close else None
        hint = f"; did you mean {self.suggestion!r}?" if self.suggestion is not None else ""
        shown = repr(name) if len(repr(name)) <= 120 else f"{repr(name)[:90]}... ({len(str(name))} characters)"
        listed = ", ".join(with_aliases(valid_name, self.aliases) for valid_name in self.valid)
        super().__init__(f"{where + ': ' if where else ''}unknown {kind} {shown}{hint}; valid {kind}s: {listed}")

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0])


class ConfigError(WbcError, ValueError):
    """A configuration value is invalid (wrong range, shape or type)."""


class CommandError(WbcError, ValueError):
    """A motor command was rejected before reaching any motor (non-finite, wrongly shaped)."""


class InputFileError(WbcError, ValueError):
    """A file handed to `wbc` cannot be read safely (`wbc.input_files`).

    It is missing, not a regular file, too large, not UTF-8, nested too deep, or not parseable; the message names the
    file (and line) and the limit it broke.
    """


class FileFieldError(WbcError, ValueError):
    """A declarative input file (TOML) is missing, unreadable or invalid at a known line and field.

    ``str(err)`` reads ``path:line: [table] key: what is wrong``; the line and the field are left out when unknown.

    Attributes:
        path: the file at fault, as given.
        line: 1-based line of the offending key or table header, or None.
        field: ``[table] key`` (``[[bands]] #2 key`` in arrays of tables, 1-based), ``[table]``, or None.
        reason: what is wrong and how to fix it, without the location.
    """

    def __init__(self, path: str | PathLike[str], reason: str, *, line: int | None = None,
                 field: str | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.field = field
        self.reason = reason
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {field}: {reason}" if field else f"{where}: {reason}")


class ScenarioError(FileFieldError):
    """A scenario file (or the lock of published scenarios) is missing, unreadable or invalid."""


class RobotNotConnectedError(WbcError, RuntimeError):
    """A robot was used before `connect()` or after `close()`."""


class MissingExtraError(WbcError, ImportError):
    """An optional dependency is missing; the message names the extra that installs it."""

    def __init__(self, module: str, extra: str) -> None:
        super().__init__(
            f"the optional module {module!r} is not installed; install it with: pip install 'wbc[{extra}]'"
        )
        self.module = module
        self.extra = extra


class BenchError(WbcError, RuntimeError):
    """A speed bench cannot measure what it was asked to (a reference that fails, a controller it cannot time)."""


class AnalysisError(WbcError, ValueError):
    """An analysis cannot be computed from the robot model it was given; the message names the missing part."""


class PolicyInputError(WbcError, ValueError):
    """A policy network was called with inputs it does not take; the message says what to pass instead.

    Extrinsics missing for a policy that observes them, or given to one that does not; no adaptation module to
    estimate them.
    """


class NetworkMismatchError(WbcError, ValueError):
    """A network does not fit what it is combined with; the message names both sides and what to change.

    The policy file format it is exported to, a composite's parts, the policy a warm start copies, the teacher of
    a BC term, or the procedure it is given to (RMA phase 2).
    """


class MpcProblemFileError(WbcError, ValueError):
    """A dumped MPC problem file (``MpcProblem.save``) is missing arrays or is not one; the message names the file."""

    def __init__(self, path: str, missing: list[str] | tuple[str, ...]) -> None:
        super().__init__(
            f"{path} is not a complete MPC problem file: missing {', '.join(missing)}; dump it again with "
            "MpcProblem.save from this version of wbc (older dumps lack what solve needs to rebuild the states)"
        )
        self.path = path
        self.missing = tuple(missing)


class RecordError(WbcError, ValueError):
    """A trial record, a ``trials.csv`` row or a run's identity (``run.json``) is malformed.

    A field is missing or mistyped, a trial is repeated, or a record comes from another scenario version; the message
    names the field (and the file and line) at fault.
    """


class ResultsDirError(WbcError):
    """A results directory cannot be used as asked.

    It holds another run, or results where none were expected, or fewer trials than the run needs; the message says
    which option fixes it (``--resume``, another ``--out``).
    """


class ClusterError(WbcError, RuntimeError):
    """The Ray cluster cannot play the run as it is recorded; the run stops, its stored trials kept for ``--resume``.

    A worker node whose wbc or result-changing packages differ from the driver's, a controller file missing there or
    different, a node or an object Ray lost more often than it is retried, an address that cannot be reached. None of
    these is the controller's: no trial is recorded for it. The message names the node (or address), what differs and
    both values.
    """


class EpisodeError(WbcError, ValueError):
    """An `Episode` holds a value no episode can; the message names the episode and the field.

    A time that runs backwards, a NaN pose, a row count that is not the ticks'.
    """


class EpisodeFileError(EpisodeError):
    """An episode file (``.npz``) is not an `Episode` this version can read; the message names the file and field."""


class MissingCapabilityError(ConfigError):
    """A robot or controller lacks a capability the run asks for.

    Base truth, fall detection, a ground-truth debug switch: the message names the capability's protocol and how to
    run without it.
    """


class FrameError(WbcError, ValueError):
    """A Unitree low-level frame from the wire was rejected by a decoder and must not be used.

    The SDK accepts more than it should (a longer frame, any levelFlag); `wbc.hardware.unitree` rejects a frame of
    the wrong length, a wrong header, a bad CRC or a non-finite value, counts it in its `DecodeStats` and raises
    this error, which says what was wrong and where the frame most likely came from.

    Attributes:
        reason: why, one of ``length``, ``header``, ``crc``, ``non_finite`` (the `DecodeStats` counter it bumped).
        robot: the layout the frame was decoded with (``go1``, ``a1``).
        frame_kind: ``LowState`` or ``LowCmd``.
    """

    def __init__(self, reason: str, robot: str, frame_kind: str, detail: str) -> None:
        self.reason = reason
        self.robot = robot
        self.frame_kind = frame_kind
        super().__init__(f"{robot} {frame_kind} rejected ({reason}): {detail}")


class SafetyResetError(WbcError, RuntimeError):
    """`SafeRobot.reset` was refused: the state is stale, a remote button is held, or a safety check still fails.

    The message lists each reason and what to do about it.
    """


class PortBusyError(WbcError, OSError):
    """A UDP port could not be bound because another socket holds it.

    The vendor SDK then runs silently on an ephemeral port, deaf to the robot; `wbc` refuses instead. The message
    names the address and says how to free or change it.

    Attributes:
        host: the address asked for.
        port: the port asked for.
    """

    def __init__(self, host: str, port: int, detail: str) -> None:
        self.host = host
        self.port = port
        super().__init__(f"cannot bind UDP {host}:{port}: {detail}; another process (or an unclosed robot) holds the "
                         "port: close it, or choose another local port (port 0 picks a free one)")


class TargetRefusedError(ConfigError):
    """A hardware link was pointed at a real robot without saying that a real robot is meant.

    A real robot is an address outside 127.0.0.0/8 (`wbc.hardware.unitree.check_target`) or a serial device that is
    not a pseudo-terminal (`wbc.hardware.serial_port_policy.check_serial_port`). The message names the address or
    the device and the switch (``allow_hardware=True``, ``--allow-hardware``) that allows it.
    """


class RobotLinkError(WbcError, RuntimeError):
    """The link to a robot failed: no valid state arrived in time, or the link thread died; the message says which."""


class NoStateStreamError(RobotLinkError):
    """A robot's link connected and no valid state came within its connect timeout: no live state stream at all.

    Nothing answered, or everything that came was refused (another model's frames, another address); the message
    counts what came and says what to check. ``wbc hw check`` reports it as its result (status 1), not as an error.
    """


class TargetInUseError(RobotLinkError):
    """A robot's low-level address is held by another link on this machine (`wbc.hardware.unitree.target_lock`).

    Each link binds a port of its own, so a second one to the same robot would connect as well and its frames would
    reach the robot between the first's; it is refused before its socket exists.

    Attributes:
        host: the robot's address.
        port: its port.
        pid: the process that holds it, as its lock file says, or None where that is not written.
    """

    def __init__(self, host: str, port: int, pid: int | None) -> None:
        self.host = host
        self.port = port
        self.pid = pid
        holder = f" (pid {pid})" if pid is not None else ""
        super().__init__(f"{host}:{port}: another wbc process{holder} is connected to this robot (a hw run, its I/O "
                         "process, a hw check or a bench); nothing was sent to it: wait for that one to end, or stop "
                         "it, then run again")


class ArmRefusedError(RobotLinkError):
    """An arm's backend found a servo it will not drive when it connected.

    A hardware error latched in it, or no answer to its ping (silent, or its answers corrupt). Nothing was driven:
    the bus was closed again. The message names the servo, what was read and what to do.
    ``wbc hw check`` reports it as its result (status 1), with what the servos that answer say, not as an error.
    """


class IoProcessStopped(RobotLinkError):
    """A robot's I/O process (`wbc.hardware.io_process`) was stopped by SIGTERM or SIGQUIT, and stopped in order.

    Connected, it closed the robot as the controller's close does (the legs damped, the arm parked); the controller's
    process raises this only once the I/O process has said that the robot is closed, and its ``close`` does not raise
    it at all (the robot is closed, as asked). Stopped before it connected the robot, it sent the robot nothing.

    Attributes:
        signal_name: the signal, ``SIGTERM`` or ``SIGQUIT``.
        connected: whether it had connected the robot (and so closed it) when the signal came.
    """

    def __init__(self, signal_name: str, *, connected: bool) -> None:
        self.signal_name = signal_name
        self.connected = connected
        super().__init__(f"the I/O process was stopped by {signal_name}: it closes the robot as on close, leaving it "
                         "damped, and exits" if connected else
                         f"the I/O process was stopped by {signal_name} before it connected the robot: nothing was "
                         "sent to it")


class PacketError(WbcError, ValueError):
    """A Dynamixel Protocol 2.0 packet was rejected by the codec (`wbc.hardware.dynamixel`) and must not be used.

    Attributes:
        reason: why, one of ``short``, ``header``, ``length``, ``crc``, ``params`` (parameters that do not fit
            the instruction).
    """

    def __init__(self, reason: str, detail: str) -> None:
        self.reason = reason
        super().__init__(f"Dynamixel packet rejected ({reason}): {detail}")


class StandUpError(WbcError, RuntimeError):
    """A robot could not be stood up under its safety layer before a hardware trial, so the trial was not played.

    The layer tripped (the message names its reason and what it measured) or its ramp did not reach the standing
    pose in time; the robot was left in damping.
    """


class SerialPortError(RobotLinkError):
    """A serial port (the arm's Dynamixel bus adapter) could not be opened, or failed while in use.

    The serial layer raises several unrelated types for one cause (a closed or unplugged port raises
    `termios.error`, which is neither `OSError` nor pyserial's `SerialException`); the Dynamixel backend turns each
    into this error, naming the port and the original exception.

    Attributes:
        port: the device path.
    """

    def __init__(self, port: str, detail: str) -> None:
        self.port = port
        super().__init__(f"serial port {port}: {detail}")
