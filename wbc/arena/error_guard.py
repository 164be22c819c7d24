"""`ErrorGuard`: stops a controller that keeps failing, and `ControllerErrors`: what each failing controller did.

A controller that raises (or returns a command the robot refuses) on one trial has that trial recorded with the
outcome ``controller_error`` (`wbc.arena.sim_trial.run_trial`), and the run goes on. One that fails on
``max_consecutive`` trials in a row, in the order its trials finished, is stopped: the arena hands out none of its
remaining trials (those already running finish and are stored), and the other controllers play on. A resumed run
feeds the guard the stored records first, so a controller stopped before is stopped again without playing.

At the end of a run, `ControllerErrors` says, per controller that failed at least once, how many trials failed,
the first failure's message and whether (and with how many trials left) it was stopped; the command prints one
line each and exits with status 1.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

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
        first: the first failure's message (the record's ``error``), in the order the trials finished.
        stopped: it was stopped after failing on `limit` trials in a row, with trials left to play.
        limit: the guard's number of consecutive failures (0: never stops).
        not_played: its trials left unplayed because it was stopped.
    """

    controller: str
    errored: int
    recorded: int
    first: str
    stopped: bool = False
    limit: int = DEFAULT_MAX_CONSECUTIVE_ERRORS
    not_played: int = 0

    def line(self) -> str:
        """One line for the end of the command: the controller, how many trials failed, the first message."""
        stop = (f"; STOPPED after {self.limit} consecutive errors, {self.not_played} trial(s) not played"
                if self.stopped else "")
        return (f"controller {self.controller}: {self.errored} of {self.recorded} trial(s) failed with a controller "
                f"error{stop}; first: {self.first}")

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
    """Counts each controller's consecutive failures and stops those that reach the limit.

    Args:
        controllers: the controllers played.
        limit: consecutive failures that stop a controller; 0 never stops one.

    Raises:
        ConfigError: a negative limit.
    """

    def __init__(self, controllers: Sequence[str], limit: int = DEFAULT_MAX_CONSECUTIVE_ERRORS) -> None:
        if limit < 0:
            raise ConfigError(f"--max-consecutive-errors must be >= 0 (0: never stop a controller), got {limit}")
        self.limit = limit
        self._streak = dict.fromkeys(controllers, 0)
        self._stopped: set[str] = set()

    def observe(self, record: TrialRecord) -> None:
        """Count one finished trial (in the order trials finish)."""
        if record.controller not in self._streak:
            return
        if record.outcome == CONTROLLER_ERROR:
            self._streak[record.controller] += 1
            if self.limit and self._streak[record.controller] >= self.limit:
                self._stopped.add(record.controller)
        else:
            self._streak[record.controller] = 0

    def observe_all(self, records: Iterable[TrialRecord]) -> None:
        """Count finished trials, in the order they finished (a resumed run's stored records)."""
        for record in records:
            self.observe(record)

    def stopped(self, controller: str) -> bool:
        """`controller` failed on `limit` trials in a row: hand out no more of its trials."""
        return controller in self._stopped

    def report(self, records: Sequence[TrialRecord], budget: int) -> list[ControllerErrors]:
        """The failures of each controller that failed at least once, in the guard's controller order.

        Args:
            records: the run's records, in the order they finished.
            budget: trials each controller was to play.
        """
        out = []
        for controller in self._streak:
            mine = [r for r in records if r.controller == controller]
            errors = [r for r in mine if r.outcome == CONTROLLER_ERROR]
            if not errors:
                continue
            stopped = self.stopped(controller) and len(mine) < budget  # not when its last trials were under way
            out.append(ControllerErrors(controller=controller, errored=len(errors), recorded=len(mine),
                                        first=errors[0].error, stopped=stopped, limit=self.limit,
                                        not_played=max(0, budget - len(mine)) if stopped else 0))
        return out


def outcome_counts(records: Iterable[TrialRecord]) -> dict[str, int]:
    """How many of `records` ended in each outcome (every one of `OUTCOMES`, zeros included)."""
    counts = dict.fromkeys(OUTCOMES, 0)
    for record in records:
        counts[record.outcome] += 1
    return counts
