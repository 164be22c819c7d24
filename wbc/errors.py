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


# --- learned / mujoco
__all__ += ["NetworkMismatchError", "PolicyInputError"]


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
