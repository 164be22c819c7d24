"""`Player`: paces a stream of frames for a person watching: real time, slow motion, pause and single steps.

The player sits in the runner's observer hook (or in a replay loop). For each frame it decides whether to draw it
(`due`: about `fps` frames per wall-clock second), blocks until the wall clock has caught up with the frame's time
divided by `speed` (`wait`), and after the frame is drawn blocks for as long as it is paused (`drew`). Blocking the
hook pauses the simulation itself, so a paused live trial resumes exactly where it stopped.

Keys (one per line on stdin, read by `KeyboardControls` when stdin is a terminal): ``p`` pause / resume, ``s``
single step (``step_s`` of trial time, then pause again), ``+`` / ``-`` twice / half the speed, ``q`` stop pacing
(the trial finishes at full speed without drawing).
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

from wbc.errors import ConfigError

__all__ = ["Controls", "KeyboardControls", "Player", "PlayerConfig"]


@dataclass(frozen=True, kw_only=True)
class PlayerConfig:
    """How to play.

    Attributes:
        speed: trial seconds per wall-clock second (1 real time, 0.25 four times slower); 0 means as fast as
            possible.
        fps: frames drawn per wall-clock second.
        pause_at: trial times at which to pause [s] (e.g. just before a push).
        step_s: trial time a single step advances [s].
        start_paused: pause before the first frame.
    """

    speed: float = 1.0
    fps: float = 30.0
    pause_at: tuple[float, ...] = ()
    step_s: float = 0.02
    start_paused: bool = False

    def __post_init__(self) -> None:
        if not self.speed >= 0:
            raise ConfigError(f"--speed must be >= 0 (1 is real time, 0 as fast as possible), got {self.speed}")
        if not self.fps > 0:
            raise ConfigError(f"PlayerConfig.fps must be > 0, got {self.fps}")
        if not self.step_s > 0:
            raise ConfigError(f"--step must be > 0 s, got {self.step_s}")


class Controls:
    """Commands from the person watching, thread-safe (a keyboard thread or a test sets them)."""

    def __init__(self) -> None:
        self._lock = threading.Condition()
        self.paused = False
        self.steps = 0
        self.speed_factor = 1.0
        self.stopped = False

    def toggle_pause(self) -> None:
        """Pause, or resume."""
        with self._lock:
            self.paused = not self.paused
            self._lock.notify_all()

    def step(self) -> None:
        """Advance one step while paused (pauses first when playing)."""
        with self._lock:
            self.paused = True
            self.steps += 1
            self._lock.notify_all()

    def faster(self, factor: float) -> None:
        """Multiply the speed by `factor`."""
        with self._lock:
            self.speed_factor *= factor

    def stop(self) -> None:
        """Stop pacing and drawing."""
        with self._lock:
            self.stopped = True
            self.paused = False
            self._lock.notify_all()

    def wait_stopped(self) -> None:
        """Block until `stop`."""
        with self._lock:
            while not self.stopped:
                self._lock.wait()

    def wait_while_paused(self, timeout: float | None = None) -> bool:
        """Block while paused; True if a single step was granted (consumed here)."""
        with self._lock:
            while self.paused and self.steps == 0 and not self.stopped:
                if not self._lock.wait(timeout):
                    return False
            if self.paused and self.steps > 0:
                self.steps -= 1
                return True
            return False


class KeyboardControls(Controls):
    """`Controls` fed by lines typed on stdin (a daemon thread; nothing is read when stdin is not a terminal)."""

    interactive = False
    """True once `start` found a terminal to read keys from."""

    def start(self) -> KeyboardControls:
        """Start reading stdin if it is a terminal; print the keys."""
        if sys.stdin is not None and sys.stdin.isatty():
            self.interactive = True
            print("keys (then Enter): p pause/resume, s single step, + faster, - slower, q stop", file=sys.stderr)
            threading.Thread(target=self._read, daemon=True).start()
        return self

    def _read(self) -> None:
        for line in sys.stdin:
            key = line.strip()[:1]
            if key == "p" or line.strip() == "":
                self.toggle_pause()
            elif key in ("s", "n"):
                self.step()
            elif key == "+":
                self.faster(2.0)
            elif key == "-":
                self.faster(0.5)
            elif key == "q":
                self.stop()
                return


class Player:
    """Paces frames.

    Args:
        config: speed, frame rate, pauses.
        controls: pause/step/speed commands (default: none besides `config`).
        clock: wall clock [s] (a test hands in a fake one).
        sleep: sleeps [s].
    """

    def __init__(self, config: PlayerConfig | None = None, controls: Controls | None = None, *,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        self.config = config or PlayerConfig()
        self.controls = controls or Controls()
        self.controls.paused = self.config.start_paused or self.controls.paused
        self._clock = clock
        self._sleep = sleep
        self._pending_pauses = sorted(self.config.pause_at)
        self._anchor: tuple[float, float, float] | None = None  # (wall, trial time, speed) where pacing restarted
        self._last_drawn = -float("inf")
        self._step_until: float | None = None
        self.drawn = 0

    @property
    def stopped(self) -> bool:
        """True once the person asked to stop."""
        return self.controls.stopped

    def due(self, t: float) -> bool:
        """Whether the frame at trial time `t` [s] should be drawn."""
        if self.controls.stopped:
            return False
        if self.controls.paused or (self._pending_pauses and t >= self._pending_pauses[0]):
            return True
        if self._step_until is not None and t >= self._step_until:
            return True
        speed = self.config.speed * self.controls.speed_factor
        interval = (speed if speed > 0 else 1.0) / self.config.fps
        return t - self._last_drawn >= interval - 1e-9

    def wait(self, t: float) -> None:
        """Before drawing the frame at trial time `t` [s]: sleep until the wall clock catches up with it."""
        c = self.controls
        if c.stopped or c.paused:
            return
        if self._step_until is not None and t < self._step_until:
            return  # inside a single step: run through without pacing
        speed = self.config.speed * c.speed_factor
        if speed <= 0:
            return
        now = self._clock()
        if self._anchor is None or self._anchor[2] != speed:
            self._anchor = (now, t, speed)
            return
        wall0, t0, _ = self._anchor
        ahead = (t - t0) / speed - (now - wall0)
        if ahead > 0:
            self._sleep(ahead)
        elif ahead < -0.25:  # fell behind (a slow frame): pace from here instead of rushing to catch up
            self._anchor = (now, t, speed)

    def drew(self, t: float) -> None:
        """After drawing the frame at `t`: pause here if asked (a `pause_at` time, a finished step, a key)."""
        self._last_drawn = t
        self.drawn += 1
        c = self.controls
        if c.stopped:
            return
        if self._pending_pauses and t >= self._pending_pauses[0]:
            while self._pending_pauses and t >= self._pending_pauses[0]:
                self._pending_pauses.pop(0)
            c.paused = True
            print(f"paused at t = {t:.3f} s", file=sys.stderr)
        if self._step_until is not None:
            if t < self._step_until:
                return
            self._step_until = None
        if c.paused:
            if c.wait_while_paused():
                self._step_until = t + self.config.step_s
            self._anchor = None
