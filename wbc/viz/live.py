"""`LiveViewer`: draws frames on a running meshcat server, and `LiveObserver`, the runner hook that feeds it.

Only what changed since the last frame is sent (a transform, a visibility flag). The server keeps the scene, so a
browser opened at any time sees the current state. The observer draws any robot by what it can offer: a simulator
(`wbc.viz.sim_frames.SimulatedWorld`) with its ground, contacts and pushes; a robot seen through its own sensors
(`wbc.hardware.capabilities.ConfigurationEstimate`, a hardware trial's) from its state alone, on flat ground.
"""

from __future__ import annotations

import contextlib
import io
import sys
import threading
from collections.abc import Callable

import meshcat
import numpy as np

from wbc.control.protocol import Controller
from wbc.errors import ConfigError
from wbc.hardware.capabilities import ConfigurationEstimate
from wbc.hardware.robot import Robot
from wbc.types import VelocityCommand
from wbc.viz.content import SceneContent
from wbc.viz.frame import Pose, VizFrame
from wbc.viz.player import Player
from wbc.viz.recording import Recording
from wbc.viz.server import MeshcatServer
from wbc.viz.signals import TrialSignals
from wbc.viz.sim_frames import SimulatedWorld, frame_from_sim
from wbc.viz.state_frames import frame_from_estimate

FrameMaker = Callable[[Robot, Controller, VelocityCommand, float], VizFrame]
"""Builds the frame of a tick: (robot, controller, command, time [s]) -> frame."""

__all__ = ["FrameMaker", "LiveObserver", "LiveViewer", "scene_of"]


class LiveViewer:
    """A meshcat scene on a server, updated frame by frame.

    Args:
        server: a started server.
    """

    def __init__(self, server: MeshcatServer) -> None:
        self.server = server
        with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints the URL itself; the CLI says it better
            self.vis = meshcat.Visualizer(zmq_url=server.zmq_url)
        self.content: SceneContent | None = None
        self._sent: dict[str, Pose] = {}

    @property
    def paths(self) -> dict[str, list[str]]:
        """Scene paths of the current content, by role (see `SceneContent.paths`)."""
        return self.content.paths if self.content is not None else {}

    def load(self, content: SceneContent) -> None:
        """Replace the scene with `content`."""
        self.vis["wbc"].delete()
        self._sent = {}
        self.content = content
        content.setup(self.vis)

    def show(self, frame: VizFrame) -> None:
        """Draw `frame` (only the changes are sent)."""
        for path, pose in self.content.poses(frame).items():
            old = self._sent.get(path)
            node = self.vis[path]
            if old is None or old.visible != pose.visible:
                node.set_property("visible", bool(pose.visible))
            if pose.visible and (old is None or not np.allclose(old.matrix, pose.matrix, atol=1e-6)):
                node.set_transform(pose.matrix)
            if pose.visible or old is None:
                self._sent[path] = pose
            else:
                self._sent[path] = Pose(old.matrix, visible=False)


def scene_of(robot: Robot) -> tuple[Callable[[], SceneContent], FrameMaker] | None:
    """How to build the scene of `robot` and its frames, by the capability it offers; None if it offers none.

    A simulator (`SimulatedWorld`) is drawn with its ground, contacts and pushes; a robot that estimates its own
    configuration (`ConfigurationEstimate`) from its state alone, on flat ground. The scene is built by calling the
    first element (once per visualizer that shows it: building one loads the meshes).
    """
    if isinstance(robot, SimulatedWorld):
        return (lambda: SceneContent.for_robot(robot)), frame_from_sim
    if isinstance(robot, ConfigurationEstimate):
        return (lambda: SceneContent.for_description(robot.description)), frame_from_estimate
    return None


class LiveObserver:
    """The runner's observer: paces with a `Player`, draws on a `LiveViewer`, records.

    At the first tick of every episode the scene is rebuilt from the robot (robot, arm mode, ground; `scene_of`), so
    one observer serves a series of trials. A robot that offers neither a simulation nor an estimate of its own
    configuration is not drawn (said once on standard error).

    For a real robot, whose loop must never wait for the viewer, `prepare` builds the scene before the episode (a
    `wbc.arena.runner.PreparingObserver`) and ``background=True`` draws on a thread of its own: a tick then only hands
    over its frame, and the drawing thread shows the newest one (frames it had no time for are skipped).

    Args:
        viewer: where to draw (None: draw nowhere, e.g. when only recording).
        player: pacing (None: no pacing, every tick as fast as possible); not with `background`.
        recording_fps: when set, also record every episode (see `recordings`) at this rate [1/s], with its time
            plots (see `signals`, one per recording).
        background: draw on a thread of this observer's instead of in the tick.
    """

    def __init__(self, viewer: LiveViewer | None, player: Player | None = None, *,
                 recording_fps: float | None = None, background: bool = False) -> None:
        if background and player is not None:
            raise ConfigError("LiveObserver: a player paces the loop in the tick, a background viewer never blocks "
                              "it; give one or the other")
        self.viewer = viewer
        self.player = player
        self.recording_fps = recording_fps
        self.recordings: list[Recording] = []
        self.signals: list[TrialSignals] = []
        self.name = ""
        self.last_frame: VizFrame | None = None
        self._last_t = float("inf")
        self._quiet_until = -float("inf")  # [s] ticks before this time have no frame to key (recording only)
        self._make: FrameMaker | None = None
        self._told = False
        self._prepared: Robot | None = None
        self._drawer = _Drawer(viewer) if background and viewer is not None else None
        self._last_drawn = -float("inf")
        self._simulated: SimulatedWorld | None = None  # the episode's robot, when it is a simulation

    def prepare(self, robot: Robot) -> None:
        """Build the scene of `robot` now, for the episode it plays next (its first tick then draws at once)."""
        self._start_episode(robot)
        self._prepared = robot

    def close(self) -> None:
        """Stop the drawing thread, if any (the frames not drawn yet are dropped)."""
        if self._drawer is not None:
            self._drawer.stop()

    def _start_episode(self, robot: Robot) -> None:
        self._simulated = robot if isinstance(robot, SimulatedWorld) else None
        scene = scene_of(robot)
        self._make = None if scene is None else scene[1]
        if scene is None:
            if not self._told:
                print(f"viewer: {type(robot).__name__} is neither a simulation nor a robot that estimates its own "
                      "configuration (wbc.hardware.capabilities.ConfigurationEstimate): nothing to draw",
                      file=sys.stderr)
                self._told = True
            return
        if self.viewer is not None:
            if self._drawer is not None:
                self._drawer.idle()
            self.viewer.load(scene[0]())
        if self.recording_fps is not None:
            self.recordings.append(Recording(scene[0](), fps=self.recording_fps))
            self.signals.append(TrialSignals(self.name))

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """One tick (the `wbc.arena.runner.TickObserver` signature)."""
        if self._last_t <= t < self._quiet_until:  # recording only, and no frame due yet: most ticks
            self._last_t = t
            return
        new_episode = t < self._last_t
        self._last_t = t
        if new_episode:
            if self._prepared is not robot:
                self._start_episode(robot)
            self._prepared = None
            self._last_drawn = -float("inf")
            self._quiet_until = -float("inf")
        if self._make is None:
            return
        if self._drawer is not None:
            self._tick_in_background(t, robot, controller, command)
            return
        rec = self.recordings[-1] if self.recording_fps is not None else None
        if rec is not None and rec.frames == 0:
            rec.tick_s = 1.0 / controller.rate_hz  # each frame keyed at its nearest tick (`frame_key`)
        draw = self.viewer is not None and (self.player is None or self.player.due(t))
        keyed = rec is not None and rec.key_of(t) > rec.last_key
        if not (draw or keyed):
            return
        frame = self.last_frame = self._make(robot, controller, command, t)
        if keyed:
            rec.add(frame)
            self._sample(frame, robot)
            if self.viewer is None:  # nothing else to do before the next frame is due (it rounds to the next key)
                self._quiet_until = rec.next_key_s
        if draw:
            if self.player is not None:
                self.player.wait(t)
            self.viewer.show(frame)
            if self.player is not None:
                self.player.drew(t)  # blocks here while paused, the paused frame on screen

    def _sample(self, frame: VizFrame, robot: Robot) -> None:
        """Sample the time plots of the episode being recorded with the frame just keyed."""
        plan_com = None
        if frame.plan is not None and len(frame.plan.get("com_path_in_world", ())):
            path = np.asarray(frame.plan["com_path_in_world"])
            plan_com = path[min(1, len(path) - 1)]
        self.signals[-1].add_frame(frame, robot if robot is self._simulated else None, plan_com)

    def _tick_in_background(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        rec = self.recordings[-1] if self.recording_fps is not None else None
        if rec is not None and rec.frames == 0:
            rec.tick_s = 1.0 / controller.rate_hz
        keyed = rec is not None and rec.key_of(t) > rec.last_key
        draw = t - self._last_drawn >= 1.0 / _BACKGROUND_FPS - 1e-9
        if not (draw or keyed):
            return
        frame = self._make(robot, controller, command, t)
        if keyed:
            rec.add(frame)
            self._sample(frame, robot)
        if draw:
            self._last_drawn = t
            self._drawer.submit(frame)


_BACKGROUND_FPS = 30.0  # [1/s of episode time] frames handed to a background drawer


class _Drawer:
    """A thread that shows the newest frame handed to it on a `LiveViewer`."""

    def __init__(self, viewer: LiveViewer) -> None:
        self.viewer = viewer
        self._frame: VizFrame | None = None
        self._busy = False
        self._stopped = False
        self._lock = threading.Condition()
        self._thread = threading.Thread(target=self._run, name="wbc-viewer", daemon=True)
        self._thread.start()

    def submit(self, frame: VizFrame) -> None:
        """Show `frame` next, in place of any frame still waiting."""
        with self._lock:
            self._frame = frame
            self._lock.notify_all()

    def idle(self) -> None:
        """Drop the waiting frame and wait until the one being shown is done (before the scene is replaced)."""
        with self._lock:
            self._frame = None
            while self._busy:
                self._lock.wait()

    def stop(self) -> None:
        """Stop the thread."""
        with self._lock:
            self._stopped = True
            self._frame = None
            self._lock.notify_all()
        self._thread.join(timeout=5.0)

    def _run(self) -> None:
        while True:
            with self._lock:
                while self._frame is None and not self._stopped:
                    self._lock.wait()
                if self._stopped:
                    return
                frame, self._frame, self._busy = self._frame, None, True
            try:
                self.viewer.show(frame)
            finally:
                with self._lock:
                    self._busy = False
                    self._lock.notify_all()
