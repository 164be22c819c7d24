"""Progress of a run: a live bar on a terminal, plain lines in a log.

A bar redraws one line with carriage returns, which a CI log (or ``make demo > log``) keeps as one long smear or
hundreds of fragments. When the stream is not a terminal, `LineProgress` prints a full line instead, at every tenth
of the run and at least every `every_s` seconds, each saying how far it is, how long it took and about how long is left.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

from tqdm import tqdm

__all__ = ["LineProgress", "progress"]


class LineProgress:
    """Progress as plain lines, for logs.

    Args:
        total: trials in the whole run.
        initial: trials already done (a resumed run).
        stream: where the lines go.
        every_s: the longest silence between two lines [s].
        clock: seconds, monotonic (a test passes its own).
    """

    def __init__(self, total: int, initial: int = 0, *, stream: TextIO | None = None, every_s: float = 30.0,
                 clock=time.monotonic) -> None:
        self.total = total
        self.done = initial
        self.stream = stream if stream is not None else sys.stderr
        self.every_s = every_s
        self.clock = clock
        self._start = clock()
        self._played = 0
        self._last_line = self._start
        self._last_tenth = self._tenth()
        self._closed = False
        self._line(f"trials: {self.done}/{self.total} done, {self.total - self.done} to play")

    def _tenth(self) -> int:
        return 10 * self.done // self.total if self.total else 10

    def _line(self, text: str) -> None:
        print(text, file=self.stream, flush=True)
        self._last_line = self.clock()

    def update(self, n: int = 1) -> None:
        """`n` more trials finished; print a line if a tenth was crossed or `every_s` passed."""
        self.done += n
        self._played += n
        now = self.clock()
        tenth = self._tenth()
        if tenth > self._last_tenth or now - self._last_line >= self.every_s:
            self._last_tenth = tenth
            elapsed = now - self._start
            left = elapsed / self._played * (self.total - self.done) if self._played else float("nan")
            eta = f", about {_duration(left)} left" if self.done < self.total else ""
            self._line(f"trials: {self.done}/{self.total} ({100 * self.done // max(self.total, 1)} %), "
                       f"{_duration(elapsed)} elapsed{eta}")

    def close(self) -> None:
        """Print the closing line if the last update did not."""
        if self._closed:
            return
        self._closed = True
        if self._tenth() <= self._last_tenth and self.done < self.total:
            self._line(f"trials: stopped at {self.done}/{self.total} after {_duration(self.clock() - self._start)}")


def _duration(seconds: float) -> str:
    if seconds != seconds:  # NaN
        return "?"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def progress(total: int, initial: int, enabled: bool, stream: TextIO | None = None):
    """A progress display for a run of `total` trials: a bar on a terminal, lines otherwise, None when disabled."""
    if not enabled:
        return None
    stream = stream if stream is not None else sys.stderr
    if not stream.isatty():
        return LineProgress(total, initial, stream=stream)
    return tqdm(total=total, initial=initial, unit="trial", file=stream, dynamic_ncols=True, desc="trials")
