"""The ``wbc`` console script: the command (`wbc.cli.main`), ended in its own words from its first moment.

Loading the command's modules takes a second or more (MuJoCo, the controllers, the arena). A Ctrl-C in that time
printed the import's traceback, and a SIGTERM or SIGHUP ended the process without a word (status 143, 129) before the
command's own handlers (`wbc.cli.main.main`) were installed. Here they end it from the start as they end it later:
``wbc: interrupted while starting: nothing was done``, status 130. SIGTERM and SIGHUP raise `KeyboardInterrupt` until
the command installs its own handlers, which restore these when it ends; a SIGHUP ignored when the command starts
(``nohup``) stays ignored (`wbc.starting`, which ``python -m wbc`` and ``python -m wbc.cli`` use too). They are
installed before the command's modules load; the package's own start (``wbc``,
which loads numpy, about a tenth of a second) comes before this module runs. A signal that comes after the command
has ended (while it waits for threads a plug-in left running) ends it with status 130 without a word.
"""

from __future__ import annotations

from wbc.starting import requests_to_end_interrupt, say_interrupted_while_starting

__all__ = ["main"]


def main() -> int:
    """Run the ``wbc`` command with ``sys.argv``; its exit status (130 when interrupted while it loads)."""
    requests_to_end_interrupt()
    try:
        from wbc.cli import main as command
    except KeyboardInterrupt:
        return say_interrupted_while_starting()
    try:
        return command()
    except KeyboardInterrupt:  # after the command's end, which said its last words
        return 130
