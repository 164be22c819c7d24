"""Exception tree of `wbc`: one root, one subclass per kind of failure.

Messages say what was wrong and how to fix it (valid names, the field at fault, the extra to install).
"""

from __future__ import annotations

__all__ = [
    "WbcError",
    "UnknownNameError",
    "ConfigError",
    "CommandError",
    "RobotNotConnectedError",
    "MissingExtraError",
]


class WbcError(Exception):
    """Root of every error raised on purpose by `wbc`."""


class UnknownNameError(WbcError, KeyError):
    """A name (robot, arm mode, controller ...) is not in its registry; the message lists the valid ones."""

    def __init__(self, kind: str, name: str, valid: list[str] | tuple[str, ...]) -> None:
        self.kind = kind
        self.name = name
        self.valid = tuple(sorted(valid))
        super().__init__(f"unknown {kind} {name!r}; valid {kind}s: {', '.join(self.valid)}")

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0])


class ConfigError(WbcError, ValueError):
    """A configuration value is invalid (wrong range, shape or type)."""


class CommandError(WbcError, ValueError):
    """A motor command was rejected before reaching any motor (non-finite, wrongly shaped)."""


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


# --- arena
__all__ += ["RecordError", "ResultsDirError", "EpisodeFileError", "MissingCapabilityError"]


class RecordError(WbcError, ValueError):
    """A trial record or a ``trials.csv`` row is malformed.

    A field is missing or mistyped, a trial is repeated, or a record comes from another scenario version; the message
    names the field (and the file and line) at fault.
    """


class ResultsDirError(WbcError):
    """A results directory cannot be used as asked.

    It holds another run, or results where none were expected, or fewer trials than the run needs; the message says
    which option fixes it (``--resume``, another ``--out``).
    """


class EpisodeFileError(WbcError, ValueError):
    """An episode file (``.npz``) is not an `Episode` this version can read; the message names the file and field."""


class MissingCapabilityError(ConfigError):
    """A robot or controller lacks a capability the run asks for.

    Base truth, fall detection, a ground-truth debug switch: the message names the capability's protocol and how to
    run without it.
    """
