"""The operator of a hardware trial: keys pressed during it, what each does, and the log of what was done.

Keys come from a `KeySource`: the terminal in ``wbc hw run`` (`wbc.cli.terminal_keys.TerminalKeys`), a script in a
test or a scripted trial (`ScriptedKeys`). `OperatorConsole` sits in the runner's observer hook, so it runs in the
control thread after every tick (where `wbc.hardware.safety.SafeRobot.estop` must be called): it polls the keys,
does what they mean (`OPERATOR_ACTIONS`) and logs each action with the tick's time, for the episode
(`wbc.arena.episode.OperatorLog`). Then it hands the tick on to the next observer (a viewer).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Protocol, runtime_checkable

from wbc.arena.episode import OperatorLog
from wbc.arena.runner import TickObserver
from wbc.control.protocol import Controller
from wbc.errors import ConfigError
from wbc.hardware.robot import Robot
from wbc.types import VelocityCommand

__all__ = ["OPERATOR_ACTIONS", "KeySource", "OperatorConsole", "ScriptedKeys"]

OPERATOR_ACTIONS: dict[str, str] = {"e": "estop", " ": "estop", "p": "push"}
"""Key -> action: ``e`` or the space bar is the software e-stop (damping, latched: the trial ends), ``p`` marks a
push the operator gave the robot by hand (logged with its time; nothing is sent)."""


@runtime_checkable
class KeySource(Protocol):
    """Where an operator's key presses come from."""

    def poll(self, t: float) -> Sequence[str]:
        """The keys pressed since the last poll, oldest first (never blocks).

        Args:
            t: the trial time now [s]; negative before the trial, while the robot is stood up (a scripted source
                presses by it; a terminal ignores it).
        """


class ScriptedKeys:
    """Keys pressed at given trial times, as a person would at the terminal: for tests and scripted trials.

    Args:
        presses: (trial time [s], key) pairs; each is delivered by the first poll at or after its time.
        clock: what `delivered` stamps each key with (default `time.monotonic`; a test's clock, e.g. the robot's
            `wall_time`, to compare with what its emulator logged).

    Attributes:
        delivered: (key, the clock's time when the poll delivered it), in order.
    """

    def __init__(self, presses: Iterable[tuple[float, str]], *, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._pending = sorted((float(t), str(k)) for t, k in presses)
        for t, key in self._pending:
            if len(key) != 1:
                raise ConfigError(f"ScriptedKeys: a press is one key, got {key!r} at t = {t} s")
        self.delivered: list[tuple[str, float]] = []

    def poll(self, t: float) -> list[str]:
        """The scripted keys due by trial time `t` [s]."""
        due = [k for at, k in self._pending if at <= t]
        self._pending = [(at, k) for at, k in self._pending if at > t]
        now = self._clock()
        self.delivered += [(k, now) for k in due]
        return due


class OperatorConsole:
    """The runner observer that turns key presses into actions during a hardware trial.

    Args:
        keys: the key source (None: nobody at the keys; the console only passes ticks on).
        estop: the software e-stop to call on an ``estop`` key (`SafeRobot.estop`), with who stopped it (``operator
            key 'e'``) for its event.
        then: the next observer (a viewer), called after the keys are handled; None: none.
        say: where the acknowledgement of a marked push goes, one line (default: standard error); an e-stop is
            acknowledged by the safety layer's own line.
    """

    def __init__(self, keys: KeySource | None, estop: Callable[[str], None], then: TickObserver | None = None, *,
                 say: Callable[[str], None] | None = None) -> None:
        self.keys = keys
        self.estop = estop
        self.then = then
        self.say = say if say is not None else _to_stderr
        self._log: list[tuple[float, str, str]] = []

    def before_trial(self, t: float) -> None:
        """Between ticks before the trial (the robot standing up): the e-stop works, other keys are dropped.

        Args:
            t: the time on the trial's clock, negative before it starts [s] (given to the key source).
        """
        if self.keys is not None:
            for key in self.keys.poll(t):
                if OPERATOR_ACTIONS.get(key.lower()) == "estop":
                    self.estop(f"operator key {key!r}, before the trial")

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """One tick (the `wbc.arena.runner.TickObserver` signature)."""
        if self.keys is not None:
            for key in self.keys.poll(t):
                action = OPERATOR_ACTIONS.get(key.lower())
                if action is None:
                    continue
                if action == "estop":
                    self.estop(f"operator key {key!r} at {t:.2f} s of the trial")
                self._log.append((t, key, action))
                if action == "push":
                    self.say(f"operator: key {key!r}: a push by hand marked at {t:.2f} s of the trial")
        if self.then is not None:
            self.then(t, robot, controller, command)

    def log(self) -> OperatorLog:
        """Every action taken so far."""
        return OperatorLog.of(self._log)


def _to_stderr(line: str) -> None:
    try:
        print(line, file=sys.stderr)
    except OSError:
        pass  # the terminal was closed (SIGHUP): the action is logged all the same
