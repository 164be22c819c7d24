"""`ControllerFailure`: a controller broke during an episode, and where (phase, tick, time, its own source line).

The runner (`wbc.arena.runner.run_episode`) raises it when the controller's ``reset`` or ``act`` raises, or when
``act`` returns a command the robot refuses (`wbc.errors.CommandError`: a NaN, the wrong number of joints, not a
`MotorCommand`). It carries the episode played up to that tick, so that whoever plays the trial records the failure
as the trial's outcome (``controller_error`` in `wbc.arena.trial_record.TrialRecord`) instead of losing the whole run.

The place named is the controller's own (`wbc.control.failure_site`, which the contract checker names too): the
innermost frame of the exception's traceback in the controller's code, or where its method is defined.
"""

from __future__ import annotations

import math
import unicodedata

from wbc.arena.episode import Episode
from wbc.control.failure_site import failure_site, own_frame
from wbc.errors import CONTROLLER_ERRORS, WbcError
from wbc.scenario.trial import Trial

__all__ = ["CONTROLLER_ERRORS", "PRINTED_ERROR_CHARS", "ControllerFailure", "escape_controls", "printed_error",
           "read_counters"]

PRINTED_ERROR_CHARS = 1000
"""The most characters of a controller's error a printed line shows (`printed_error`); trials.csv keeps them all."""

_PRINTED_TAIL_CHARS = 200
"""Of those, how many come from the error's end, where the controller's own ``[file:line]`` is."""


def escape_controls(text: str) -> str:
    """`text` with every control character (NUL, ESC, DEL, tab ...) written as its escape (backslash, x, hex).

    A controller's exception text is its own: a NUL in it was stored raw in trials.csv, where tools that read text
    stop or fail, and printed raw on the terminal (an escape sequence acts there). Line breaks never reach a record:
    `ControllerFailure.record_error` joins the lines first.
    """
    return "".join(ch.encode("unicode_escape").decode("ascii") if unicodedata.category(ch) == "Cc" else ch
                   for ch in text)


def printed_error(text: str, most: int = PRINTED_ERROR_CHARS, *, kept_in: str | None = "trials.csv") -> str:
    """A recorded error as a printed line shows it: its control characters escaped, cut to `most` characters.

    A controller whose message runs to thousands of characters printed a line as long. The cut keeps the error's
    beginning (the controller, the trial, the tick, the exception) and its end (the controller's own ``[file:line]``),
    and says how much it leaves out between them and where the whole text is kept (`kept_in`; None: nowhere, a trial
    watched in the viewer).
    """
    text = escape_controls(text)
    if len(text) <= most:
        return text
    tail = min(_PRINTED_TAIL_CHARS, most // 2)
    where = f": the whole error is in {kept_in}" if kept_in else ""
    return f"{text[:most - tail]} ... ({len(text) - most} characters left out{where}) ... {text[-tail:]}"


class ControllerFailure(WbcError, RuntimeError):
    """A controller raised, or returned a command the robot refused, during an episode.

    Args:
        controller: the controller that failed.
        phase: ``build`` (its factory raised, in the process playing the trial), ``reset`` (it raised in
            ``reset``), ``act`` (it raised in ``act``), ``command`` (``act`` returned a
            command the robot refused) or ``counters`` (``counters`` raised or returned something that is not a dict
            of counts, after the episode).
        tick: the control tick it failed at (0-based; 0 for ``reset``).
        time_s: the episode time of that tick [s].
        exc: the exception.
        episode: the episode up to the tick before the failure (not a fall: ``fell`` False).
        hint: how to fix it, where the house can tell (a command of the legs alone on a robot whose arm is actuated:
            `wbc.control.arm_mode_hint`), or None.

    Attributes:
        phase, tick, time_s, episode, hint: as given.
        error_type: the exception's type name.
        error_message: the exception's message.
        where: ``file:line`` of the controller's own code (module docstring), or None if unknown.
    """

    def __init__(self, controller: object, *, phase: str, tick: int, time_s: float, exc: BaseException,
                 episode: Episode, hint: str | None = None) -> None:
        self.phase = phase
        self.hint = hint
        self.tick = tick
        self.time_s = time_s
        self.episode = episode
        self.error_type = type(exc).__name__
        self.error_message = str(exc)
        self.where = (own_frame(exc) if phase == "build"
                      else failure_site(exc, controller, "act" if phase == "command" else phase))
        super().__init__(self.describe())

    def describe(self) -> str:
        """One line: what failed, at which tick and time, the exception, a hint, and the controller's own file:line."""
        what = {"build": "building it raised", "reset": "reset raised", "act": "act raised",
                "command": "act returned a command the robot refused:",
                "counters": "counters() failed:"}[self.phase]
        if self.phase in ("build", "reset", "counters"):
            when = "after the episode" if self.phase == "counters" else "before the first tick"
        else:
            when = (f"at tick {self.tick} (t = {self.time_s:.3f} s)" if math.isfinite(self.time_s)
                    else f"at tick {self.tick}")
        at = f" [{self.where}]" if self.where else ""
        hint = f"; {self.hint}" if self.hint else ""
        return f"{what} {self.error_type} {when}: {self.error_message}{hint}{at}"

    def record_error(self, controller: str, trial: Trial) -> str:
        """The trial record's ``error``, on one line: the controller, the trial (band, seed, index) and `describe`.

        Its lines are joined with `` / `` and its other control characters escaped (`escape_controls`).

        Args:
            controller: the controller's name as the arena knows it.
            trial: the trial it failed in.
        """
        text = (f"controller {controller}, band {trial.band}, seed {trial.seed}, trial {trial.index}: "
                f"{self.describe()}")
        return escape_controls(" / ".join(line.strip() for line in text.splitlines() if line.strip()))


def read_counters(controller: object, name: str, trial: Trial, episode: Episode,
                  error: str) -> tuple[dict[str, int], str]:
    """The controller's event counts after a trial, checked, and the trial's error.

    A controller whose ``counters`` raises, or returns what is not a dict of whole counts
    (`wbc.arena.trial_record.check_counters`), has failed: the trial's error says so (phase ``counters``), unless it had
    failed already, whose error is kept (a second one would only hide the first).

    Args:
        controller: the controller, after its episode.
        name: its name as the arena knows it.
        trial: the trial played.
        episode: the episode played.
        error: the trial's error so far (empty when the controller has not failed).

    Returns:
        (counts, error): the counts (empty when they could not be read) and the trial's error.
    """
    from wbc.arena.trial_record import check_counters  # record imports this module's neighbours; import when used

    try:
        return check_counters(controller.counters()), error
    except CONTROLLER_ERRORS as exc:  # any: the controller's code is not ours
        if error:
            return {}, error
        played = float(episode.t[-1]) if len(episode.t) else 0.0
        failure = ControllerFailure(controller, phase="counters", tick=len(episode.t), time_s=played, exc=exc,
                                    episode=episode)
        return {}, failure.record_error(name, trial)
