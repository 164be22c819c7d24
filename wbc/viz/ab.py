"""A / B on one trial: two controllers' runs of the same seeded trial in one scene and on the same plots.

The first run's robot is drawn as usual; the second's is a translucent ghost (`Recording.add_ghost`) in the same
place on the same ground, so where their paths part is where they are seen to part. Each run's signals are overlaid
on the same plots (the second dashed), each fall is marked, and so is the first divergence: the first time the two
trunks are more than `DIVERGED_M` apart or their attitudes differ by more than `DIVERGED_RAD`.

Runs come from simulation (`capture_trial`: the trial played once per controller, frames captured at the
recording's rate) or from stored episodes (`frames_of` a `wbc.viz.replay.StoredEpisode`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wbc.arena.episode import Episode
from wbc.arena.sim_trial import run_trial
from wbc.arena.trial_record import TrialRecord
from wbc.control.protocol import Controller
from wbc.control.spec import ControllerSpec
from wbc.errors import ConfigError
from wbc.hardware.robot import Robot
from wbc.robots.conventions import quat_to_matrix
from wbc.scenario.trial import Trial
from wbc.types import VelocityCommand
from wbc.viz.content import SceneContent
from wbc.viz.frame import VizFrame
from wbc.viz.live import FrameMaker, scene_of
from wbc.viz.recording import Recording, frame_key
from wbc.viz.signals import Mark, TrialSignals
from wbc.viz.sim_frames import SimulatedWorld

__all__ = ["DIVERGED_M", "DIVERGED_RAD", "CapturedRun", "FrameCapture", "ab_recording", "capture_trial",
           "first_divergence"]

DIVERGED_M = 0.05
"""Trunk positions further apart than this mark the runs' first divergence [m]."""
DIVERGED_RAD = 0.1
"""Roll or pitch differing by more than this marks it too [rad]."""


@dataclass
class CapturedRun:
    """One controller's run of a trial, as the viewer draws it.

    Attributes:
        name: the controller.
        content: what to draw (robot, ground).
        frames: the frames, at most one per recording frame.
        signals: the time plots and events.
        record: the trial's record (None for a stored episode).
        tick_s: its controller's period [s], by which its frames are keyed (`wbc.viz.recording.frame_key`).
    """

    name: str
    content: SceneContent
    frames: list[VizFrame] = field(default_factory=list)
    signals: TrialSignals | None = None
    record: TrialRecord | None = None
    tick_s: float = 0.0


class FrameCapture:
    """A runner observer that keeps the frames (and samples the plots) of one episode at `fps` [1/s]."""

    def __init__(self, name: str, fps: float) -> None:
        self.name = name
        self.fps = fps
        self.run: CapturedRun | None = None
        self._make: FrameMaker | None = None
        self._simulated: SimulatedWorld | None = None  # the robot, when it is a simulation
        self._last_key = -1

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """One tick (the `wbc.arena.runner.TickObserver` signature)."""
        if self.run is None:
            scene = scene_of(robot)
            if scene is None:
                raise ConfigError(f"{type(robot).__name__}: nothing to draw (not a simulation)")
            self.run = CapturedRun(self.name, scene[0](), signals=TrialSignals(self.name),
                                   tick_s=1.0 / controller.rate_hz)
            self._make = scene[1]
            self._simulated = robot if isinstance(robot, SimulatedWorld) else None
        k = frame_key(t, self.fps, self.run.tick_s)
        if k <= self._last_key:
            return
        self._last_key = k
        frame = self._make(robot, controller, command, t)
        self.run.frames.append(frame)
        plan_com = None
        if frame.plan is not None and len(frame.plan.get("com_path_in_world", ())):
            path = np.asarray(frame.plan["com_path_in_world"])
            plan_com = path[min(1, len(path) - 1)]
        self.run.signals.add_frame(frame, robot if robot is self._simulated else None, plan_com)


def capture_trial(trial: Trial, controller: ControllerSpec | str, fps: float,
                  run: Callable[..., tuple[TrialRecord, Episode]] = run_trial) -> CapturedRun:
    """Play `trial` with `controller` in simulation and keep its frames and plots (events marked)."""
    name = controller if isinstance(controller, str) else controller.name
    capture = FrameCapture(name, fps)
    record, episode = run(trial, controller, observer=capture)
    if capture.run is None:
        raise ConfigError(f"controller {name}: the trial played no tick, nothing to show")
    capture.run.signals.mark_episode(episode)
    capture.run.record = record
    return capture.run


def _attitude(qpos: np.ndarray) -> tuple[float, float]:
    rot = quat_to_matrix(qpos[3:7])
    return math.atan2(rot[2, 1], rot[2, 2]), -math.asin(max(-1.0, min(1.0, rot[2, 0])))


def first_divergence(a: list[VizFrame], b: list[VizFrame], fps: float, *, tick_a: float = 0.0,
                     tick_b: float = 0.0) -> float | None:
    """The first frame time [s] the two runs part (`DIVERGED_M`, `DIVERGED_RAD`), comparing their frames keyed alike.

    Each run's frames are keyed by `frame_key` with its own control period (`tick_a`, `tick_b` [s]); the time is the
    frame's, ``k / fps``, so it does not depend on which run is first.
    """
    by_key = {frame_key(f.t, fps, tick_b): f for f in b}
    for fa in a:
        k = frame_key(fa.t, fps, tick_a)
        fb = by_key.get(k)
        if fb is None:
            continue
        if float(np.linalg.norm(np.asarray(fa.qpos[:3]) - np.asarray(fb.qpos[:3]))) > DIVERGED_M:
            return k / fps
        ra, rb = _attitude(np.asarray(fa.qpos)), _attitude(np.asarray(fb.qpos))
        if max(abs(ra[0] - rb[0]), abs(ra[1] - rb[1])) > DIVERGED_RAD:
            return k / fps
    return None


def ab_recording(a: CapturedRun, b: CapturedRun, fps: float) -> tuple[Recording, list[Mark]]:
    """One recording of both runs (`b` the ghost) and the marks of neither alone (the first divergence)."""
    rec = Recording(a.content, fps=fps, tick_s=a.tick_s)
    ghost = rec.add_ghost(b.content, tick_s=b.tick_s)
    for frame in a.frames:
        rec.add(frame)
    for frame in b.frames:
        rec.add_to_ghost(ghost, frame)
    marks = []
    t = first_divergence(a.frames, b.frames, fps, tick_a=a.tick_s, tick_b=b.tick_s)
    if t is not None:
        marks.append(Mark(t, "divergence", f"{a.name} and {b.name} part (trunks {DIVERGED_M * 100:.0f} cm or "
                                           f"{math.degrees(DIVERGED_RAD):.0f} deg apart)"))
    return rec, marks
