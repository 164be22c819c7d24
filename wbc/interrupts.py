"""Signals that ask a command to end, deferred to a point where ending loses nothing (`DeferredInterrupts`).

A training iteration caught in the middle of its update is no iteration's, and a hardware trial's results caught
half-written are no trial's: both defer Ctrl-C (SIGINT) and the requests to end that a batch scheduler, ``timeout``,
``docker stop`` or a closed terminal send (SIGTERM, SIGHUP) to the end of what is in progress. The first such signal
is noted and said on stderr; the handlers before are then back, so a second one interrupts at once.

A robot's close is held whole (`HeldInterrupts`): there the legs damp and an arm parks, and a second Ctrl-C that cut
it would leave the arm limp. Every such signal waits for the close's end, and the first is then delivered.
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["ASKS_TO_END", "DeferredInterrupts", "HeldInterrupts", "signal_label"]

ASKS_TO_END = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals `DeferredInterrupts` defers: Ctrl-C, a request to end (a scheduler's, ``timeout``'s, ``docker stop``'s,
before a SIGKILL after a grace period), and a closed terminal."""


def signal_label(signum: int) -> str:
    """How a message names a signal: ``Ctrl-C`` for SIGINT, else its name (``SIGTERM``)."""
    return "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name


def _say(line: str) -> None:
    """Print `line` on stderr; a closed terminal (SIGHUP) takes no more lines, and the work goes on all the same."""
    try:
        print(line, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


def _install(handler: Callable[[int, Any], None]) -> dict[int, Any]:
    """Put `handler` on each of `ASKS_TO_END` that the process does not ignore; the handlers before, by signal.

    A signal ignored when the command started stays ignored (``nohup``'s hangup, Ctrl-C of a script's background job).
    Interrupted on the way (a signal's handler raising), it puts back what it installed before it raises.
    """
    previous: dict[int, Any] = {}
    try:
        for signum in ASKS_TO_END:
            if signal.getsignal(signum) is signal.SIG_IGN:
                continue
            before = signal.signal(signum, handler)
            # None: a handler set outside Python; SIGINT's own in Python raises KeyboardInterrupt
            previous[signum] = before if before is not None else (
                signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL)
    except BaseException:
        _put_back(previous)
        raise
    return previous


def _put_back(previous: dict[int, Any]) -> None:
    """Put back the handlers `_install` replaced, Ctrl-C's last; a second pass puts back any an interruption left."""
    order = sorted(previous.items(), key=lambda item: item[0] == signal.SIGINT)
    try:
        for signum, handler in order:
            signal.signal(signum, handler)
    finally:
        for signum, handler in order:
            signal.signal(signum, handler)


class DeferredInterrupts:
    """While installed, the first of `ASKS_TO_END` is noted (`requested`) and said; the handlers before are put back.

    Use it as a context manager around the work to finish, then check `requested` (and raise, or carry on) where
    ending loses nothing. A signal the process ignores stays ignored. Outside the main thread, where Python runs no
    signal handler, it installs nothing.

    Args:
        says: the line printed on stderr when the first signal comes, given the signal's label (`signal_label`).
    """

    def __init__(self, says: Callable[[str], str]) -> None:
        self.says = says
        self.requested: int | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> DeferredInterrupts:
        if threading.current_thread() is threading.main_thread():
            self._previous = _install(self._note)
        return self

    def __exit__(self, *exc: object) -> None:
        self._restore()

    def _restore(self) -> None:
        previous, self._previous = self._previous, {}
        _put_back(previous)

    def _note(self, signum: int, frame: Any) -> None:
        self.requested = signum
        self._restore()
        _say(self.says(signal_label(signum)))


class HeldInterrupts:
    r"""While installed, every one of `ASKS_TO_END` is held, none interrupts; the first is delivered at the end.

    For work that must not be cut, however often the user presses Ctrl-C: a robot's close (`Robot.close`), where the
    legs damp and an arm parks. The work must end by itself (every close waits for a bounded time). The first signal
    is said when it comes (unless `says` is None), later ones are dropped; at the end, the handlers before are put
    back and the first goes to them. If the work ends by an error instead, the error goes on, with a note that the
    signal came: it ends the command already. A signal the process ignores stays ignored; one not of `ASKS_TO_END`
    (SIGQUIT, Ctrl-\) still acts at once. Only the outermost of nested ones installs anything: an inner one (a robot
    closing the robots it wraps) holds nothing of its own. Outside the main thread, where Python runs no signal
    handler, it installs nothing.

    Args:
        says: the line printed on stderr when the first signal comes, given the signal's label (`signal_label`);
            None prints nothing.
    """

    _installed = False  # one per process, in its main thread

    def __init__(self, says: Callable[[str], str] | None) -> None:
        self.says = says
        self.held: int | None = None
        self._previous: dict[int, Any] = {}
        self._outermost = False

    def __enter__(self) -> HeldInterrupts:
        if threading.current_thread() is threading.main_thread() and not HeldInterrupts._installed:
            self._previous = _install(self._note)
            HeldInterrupts._installed = self._outermost = True
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object) -> None:
        if not self._outermost:
            return
        HeldInterrupts._installed = self._outermost = False
        previous, self._previous = self._previous, {}
        _put_back(previous)
        if self.held is None:
            return
        if exc is not None:
            exc.add_note(f"({signal_label(self.held)} came while this was under way)")
            return
        signal.raise_signal(self.held)  # to the handlers put back: Ctrl-C's raises KeyboardInterrupt here

    def _note(self, signum: int, frame: Any) -> None:
        if self.held is not None:
            return
        self.held = signum
        if self.says is not None:
            _say(self.says(signal_label(signum)))
