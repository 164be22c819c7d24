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


# --- mpc


class MpcProblemFileError(WbcError, ValueError):
    """A dumped MPC problem file (``MpcProblem.save``) is missing arrays or is not one; the message names the file."""

    def __init__(self, path: str, missing: list[str] | tuple[str, ...]) -> None:
        super().__init__(
            f"{path} is not a complete MPC problem file: missing {', '.join(missing)}; dump it again with "
            "MpcProblem.save from this version of wbc (older dumps lack what solve needs to rebuild the states)"
        )
        self.path = path
        self.missing = tuple(missing)
