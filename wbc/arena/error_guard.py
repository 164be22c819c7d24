"""`ErrorGuard`: stops a controller that keeps failing, and `ControllerErrors`: what each failing controller did.

A controller that raises (or returns a command the robot refuses) on one trial has that trial recorded with the
outcome ``controller_error`` (`wbc.arena.sim_trial.run_trial`), and the run goes on. One that fails on
``max_consecutive`` trials in a row is stopped: the arena hands out none of its remaining trials, and the other
controllers play on. "In a row" is in the run's own order of trials (the order it hands them out), never in the order
they finish, so that the trials a stopped controller is counted on are the same whatever the number of workers: a
controller stops at the same trial with one worker or eight. Trials of it beyond that one that a pool had under way
finish and are stored (nothing played is thrown away), and are left out of the summary and the report (`counted`).
A resumed run feeds the guard the stored records first, so a controller stopped before is stopped again without
playing.

At the end of a run, `ControllerErrors` says, per controller that failed at least once, how many trials failed,
the first failure's message and whether (and with how many trials left) it was stopped; the command prints one
line each and exits with status 1.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from wbc.arena.controller_failure import printed_error
from wbc.arena.trial_record import CONTROLLER_ERROR, OUTCOMES, TrialRecord
from wbc.errors import ConfigError

__all__ = ["DEFAULT_MAX_CONSECUTIVE_ERRORS", "ControllerErrors", "ErrorGuard", "outcome_counts"]

DEFAULT_MAX_CONSECUTIVE_ERRORS = 3
"""A controller failing on this many trials in a row is stopped (``--max-consecutive-errors``)."""


@dataclass(frozen=True, kw_only=True)
class ControllerErrors:
    """The failures of one controller in a run.

    Attributes:
        controller: the controller's name.
        errored: its trials recorded with the outcome ``controller_error``.
        recorded: its trials recorded in all.
        first: the first failure's message (the record's ``error``), in the run's order of trials.
        stopped: it was stopped after failing on `limit` trials in a row, with trials left to play.
        limit: the guard's number of consecutive failures (0: never stops).
        not_played: its trials left unplayed because it was stopped (those played beyond its stop are among them).
        beyond: its trials beyond the one that stopped it that a pool had under way: stored in ``trials.csv``, and not
            counted. It depends on the workers, and is said in `line` only, not in the summary (`as_dict`).
    """

    controller: str
    errored: int
    recorded: int
    first: str
    stopped: bool = False
    limit: int = DEFAULT_MAX_CONSECUTIVE_ERRORS
    not_played: int = 0
    beyond: int = 0

    def line(self) -> str:
        """One line for the end of the command: the controller, how many trials failed, the first message.

        The message's control characters are escaped, and it is cut (`wbc.arena.controller_failure.printed_error`).
        """
        under_way = (f" ({self.beyond} of them under way then: played, stored in trials.csv and not counted)"
                     if self.beyond else "")
        stop = (f"; STOPPED after {self.limit} consecutive errors, {self.not_played} trial(s) not played{under_way}"
                if self.stopped else "")
        return (f"controller {self.controller}: {self.errored} of {self.recorded} trial(s) failed with a controller "
                f"error{stop}; first: {printed_error(self.first)}")

    def as_dict(self) -> dict[str, object]:
        """The JSON form (``summary.json``'s ``controller_errors``)."""
        return {"errored": self.errored, "recorded": self.recorded, "first": self.first, "stopped": self.stopped,
                "max_consecutive_errors": self.limit, "not_played": self.not_played}

    @classmethod
    def from_dict(cls, controller: str, data: Mapping[str, Any]) -> ControllerErrors:
        """Read back `as_dict` (a summary read from ``summary.json``)."""
        return cls(controller=controller, errored=data["errored"], recorded=data["recorded"], first=data["first"],
                   stopped=data["stopped"], limit=data["max_consecutive_errors"], not_played=data["not_played"])


class ErrorGuard:
    """Counts each controller's consecutive failures in the run's order of trials; stops those that reach the limit.

    Args:
        controllers: the controllers played.
        limit: consecutive failures that stop a controller; 0 never stops one.
        order: the trials' keys (band, seed, trial) in the order the run hands them out, the same for every
            controller. A controller's streak runs along it: a record is counted when every trial before it is.
            Records of trials not in it are not counted towards a streak. Empty only with a limit of 0.

    Raises:
        ConfigError: a negative limit, or a limit without an order to count along.
    """

    def __init__(self, controllers: Sequence[str], limit: int, order: Sequence[tuple[str, int, int]]) -> None:
        if limit < 0:
            raise ConfigError(f"--max-consecutive-errors must be >= 0 (0: never stop a controller), got {limit}")
        if limit and not order:
            raise ConfigError("ErrorGuard: a limit of errors in a row needs the run's order of trials to count along")
        self.limit = limit
        self._position = {key: i for i, key in enumerate(order)}
        self._failed: dict[str, dict[int, bool]] = {c: {} for c in controllers}  # position -> failed, not yet counted
        self._next = dict.fromkeys(controllers, 0)  # the first position whose outcome is not yet known
        self._streak = dict.fromkeys(controllers, 0)
        self._stop: dict[str, int] = {}  # the position of the trial that stopped the controller

    def observe(self, record: TrialRecord) -> None:
        """Take one finished trial (in any order); the streak advances over the trials known without a gap."""
        controller = record.controller
        position = self._position.get(record.run_key[1:])
        if controller not in self._failed or position is None or controller in self._stop:
            return
        failed = self._failed[controller]
        failed[position] = record.outcome == CONTROLLER_ERROR
        while self._next[controller] in failed:
            self._streak[controller] = self._streak[controller] + 1 if failed.pop(self._next[controller]) else 0
            self._next[controller] += 1
            if self.limit and self._streak[controller] >= self.limit:
                self._stop[controller] = self._next[controller] - 1
                return

    def observe_all(self, records: Iterable[TrialRecord]) -> None:
        """Take finished trials (a resumed run's stored records)."""
        for record in records:
            self.observe(record)

    def stopped(self, controller: str) -> bool:
        """`controller` failed on `limit` trials in a row: hand out no more of its trials."""
        return controller in self._stop

    def counted(self, record: TrialRecord) -> bool:
        """`record` counts in the run's results: it is not beyond the trial that stopped its controller.

        One beyond it that a pool had under way then is stored, and not counted.
        """
        stop = self._stop.get(record.controller)
        position = self._position.get(record.run_key[1:])
        return stop is None or position is None or position <= stop

    def report(self, records: Sequence[TrialRecord], budget: int) -> list[ControllerErrors]:
        """The failures of each controller that failed at least once, in the guard's controller order.

        Args:
            records: the run's records, in the order they finished; those not `counted` are left out.
            budget: trials each controller was to play.
        """
        out = []
        for controller in self._failed:
            mine = [r for r in records if r.controller == controller and self.counted(r)]
            # the first in the run's order, not the first to finish: the summary is the same whatever the workers
            errors = sorted((r for r in mine if r.outcome == CONTROLLER_ERROR),
                            key=lambda r: self._position.get(r.run_key[1:], len(self._position)))
            if not errors:
                continue
            stopped = self.stopped(controller) and len(mine) < budget  # not when its last trial stopped it
            beyond = sum(r.controller == controller and not self.counted(r) for r in records)
            out.append(ControllerErrors(controller=controller, errored=len(errors), recorded=len(mine),
                                        first=errors[0].error, stopped=stopped, limit=self.limit,
                                        not_played=max(0, budget - len(mine)) if stopped else 0, beyond=beyond))
        return out


def outcome_counts(records: Iterable[TrialRecord]) -> dict[str, int]:
    """How many of `records` ended in each outcome (every one of `OUTCOMES`, zeros included)."""
    counts = dict.fromkeys(OUTCOMES, 0)
    for record in records:
        counts[record.outcome] += 1
    return counts
