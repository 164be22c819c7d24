"""How the ``wbc`` command ends when a signal comes while its modules load: one line, status 130.

Loading the command's modules takes a second or more (MuJoCo, the controllers, the arena). Each way of starting the
command (the console script, `wbc.command`; ``python -m wbc``; ``python -m wbc.cli``, whose package loads them before
its ``__main__`` runs) installs `requests_to_end_interrupt` before they load and says `INTERRUPTED_WHILE_STARTING` if
a `KeyboardInterrupt` comes while they do. This module loads nothing of its own.
"""

from __future__ import annotations

import signal
import sys

__all__ = ["INTERRUPTED_WHILE_STARTING", "requests_to_end_interrupt", "say_interrupted_while_starting"]

INTERRUPTED_WHILE_STARTING = "wbc: interrupted while starting: nothing was done"
"""The command's one line when a Ctrl-C, SIGTERM or SIGHUP comes while its modules load."""


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def requests_to_end_interrupt() -> None:
    """SIGTERM and SIGHUP raise `KeyboardInterrupt` from now on, as Ctrl-C does; one ignored (``nohup``) stays so.

    The command installs its own handlers once loaded (`wbc.cli.main.main`) and restores these when it ends.
    """
    for signum in (signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, _interrupt)


def say_interrupted_while_starting() -> int:
    """Say `INTERRUPTED_WHILE_STARTING` on stderr (a closed terminal takes the line with it); the exit status, 130."""
    try:
        print(INTERRUPTED_WHILE_STARTING, file=sys.stderr, flush=True)
    except OSError:
        pass
    return 130
