"""The ``wbc`` command."""

from __future__ import annotations

import os
import sys
import threading
import traceback

from wbc.starting import requests_to_end_interrupt, say_interrupted_while_starting

if sys.argv[:1] == ["-m"]:
    # ``python -m wbc.cli``: the command's modules load here, before its ``__main__`` runs (Python names the program
    # "-m" until then); a signal while they load ends it as the console script's entry does (`wbc.command`)
    requests_to_end_interrupt()
    try:
        from wbc.cli.main import main as _run
    except KeyboardInterrupt:
        raise SystemExit(say_interrupted_while_starting()) from None
else:
    from wbc.cli.main import main as _run

__all__ = ["main"]

INTERNAL_ERROR = 70
"""The exit status of a command that an unexpected exception (a bug) ended: ``EX_SOFTWARE`` of sysexits.h."""

LINGER_S = 2.0
"""How long the command waits at its end for threads it did not start to finish [s]."""


def main(argv: list[str] | None = None) -> int:
    """The ``wbc`` command: `wbc.cli.main.main`, and, from the command line, an exit that no stray thread holds up.

    Run from the shell (`argv` None), a thread that a controller or plug-in started and never ended would keep the
    process alive after its results are written: the command waits `LINGER_S` for such threads, then names them and
    exits without them; an unexpected exception (a bug) prints its traceback and exits `INTERNAL_ERROR`. Called with
    an `argv` (a test, a script), it returns, or raises, as `wbc.cli.main.main` does.
    """
    if argv is not None:
        return _run(argv)
    try:
        code = _run(argv)
    except Exception:  # a bug: its traceback, and a status of its own, not 1 (a controller errored) nor 2 (an error)
        traceback.print_exc()
        print("wbc: internal error: the traceback above is a bug in wbc; please report it with the command that "
              f"gave it (exit status {INTERNAL_ERROR})", file=sys.stderr)
        return INTERNAL_ERROR
    exit_past_stray_threads(code)
    return code


def exit_past_stray_threads(code: int, linger_s: float = LINGER_S) -> None:
    """Exit with `code` now if non-daemon threads are still running after `linger_s`, naming them; else return."""
    stray = [t for t in threading.enumerate() if t is not threading.main_thread() and not t.daemon]
    for thread in stray:
        thread.join(timeout=linger_s / max(1, len(stray)))
    stray = [t for t in stray if t.is_alive()]
    if not stray:
        return
    names = ", ".join(t.name for t in stray[:5]) + (" ..." if len(stray) > 5 else "")
    print(f"wbc: warning: {len(stray)} thread(s) still running at the end ({names}): started by a controller or "
          "plug-in and never ended; exiting without waiting for them", file=sys.stderr)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
