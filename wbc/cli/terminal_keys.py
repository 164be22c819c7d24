"""`TerminalKeys`: single key presses at the terminal, without Enter, for an operator during ``wbc hw run``.

The terminal is put in cbreak mode (each key is delivered at once and not echoed; Ctrl-C still interrupts) when the
first key is asked for, so a confirmation typed before the trial reads its line as usual, and its settings are put
back by `close`. A daemon thread reads the keys into a queue; `poll` (a `wbc.arena.operator.KeySource`) empties it.
When the stream is not a terminal nothing is read and `poll` returns nothing.
"""

from __future__ import annotations

import os
import select
import sys
import termios
import threading
import tty
from typing import TextIO

__all__ = ["TerminalKeys"]

_POLL = 0.05  # [s] how often the reader looks whether it should stop


class TerminalKeys:
    """Keys from a terminal, one at a time.

    Args:
        stream: the terminal (default: standard input).
        announce: printed on standard error when reading starts (the keys and what they do).
    """

    def __init__(self, stream: TextIO | None = None, announce: str = "") -> None:
        self._stream = stream if stream is not None else sys.stdin
        self._announce = announce
        self._keys: list[str] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._saved: list | None = None
        self._fd: int | None = None

    @property
    def interactive(self) -> bool:
        """True when the stream is a terminal (keys can be read from it)."""
        try:
            return self._stream is not None and self._stream.isatty()
        except (ValueError, OSError):  # a closed stream
            return False

    def poll(self, t: float) -> list[str]:
        """The keys pressed since the last poll, oldest first; the first call starts reading.

        Args:
            t: trial time [s] (unused: a person presses keys when they like).
        """
        if self._thread is None and self._fd is None and self.interactive:
            self._start()
        with self._lock:
            keys, self._keys = self._keys, []
        return keys

    def _start(self) -> None:
        fd = self._stream.fileno()
        self._fd = fd
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        if self._announce:
            print(self._announce, file=sys.stderr, flush=True)
        self._thread = threading.Thread(target=self._read, args=(fd,), name="wbc-terminal-keys", daemon=True)
        self._thread.start()

    def _read(self, fd: int) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([fd], [], [], _POLL)
            if not ready:
                continue
            try:
                data = os.read(fd, 32)
            except OSError:
                return
            if not data:
                return
            with self._lock:
                self._keys += list(data.decode("utf-8", errors="replace"))

    def close(self) -> None:
        """Stop reading and put the terminal's settings back. Idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
            self._thread = None
        if self._fd is not None and self._saved is not None:
            try:
                termios.tcsetattr(self._fd, termios.TCSADRAIN, self._saved)
            except termios.error:
                pass  # the terminal went away: nothing to restore
            self._saved = None

    def __enter__(self) -> TerminalKeys:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
