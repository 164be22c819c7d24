"""What ``wbc view`` does: play a trial (or replay a stored one) in the browser, and/or record it to HTML.

- live: a meshcat server bound to ``ViewConfig.host`` (127.0.0.1 by default), the trial played through the
  runner with the viewer as its observer, paced by a `Player` (speed, pauses, single steps);
- record: the same frames keyed into a `Recording` and written as one self-contained HTML file; with a recording
  and no live viewer the trial runs at full speed and no server is started.
"""

from __future__ import annotations

import sys
import webbrowser
from dataclasses import dataclass, field
from pathlib import Path

from wbc.arena.record import TrialRecord
from wbc.arena.sim_trial import run_trial
from wbc.control.spec import ControllerSpec
from wbc.errors import ConfigError
from wbc.scenario.trial import Trial
from wbc.viz.live import LiveObserver, LiveViewer
from wbc.viz.player import KeyboardControls, Player, PlayerConfig
from wbc.viz.record import Recording
from wbc.viz.replay import StoredEpisode
from wbc.viz.server import MeshcatServer, ServerConfig

__all__ = ["ViewConfig", "ViewResult", "replay_episode", "view_trial"]


@dataclass(frozen=True, kw_only=True)
class ViewConfig:
    """Options of ``wbc view``.

    Attributes:
        live: stream to a browser through a meshcat server.
        host: address the server listens on (127.0.0.1: this machine only).
        record: write a self-contained HTML replay here (None: no recording).
        record_fps: frames per second of the recording [1/s].
        player: pacing of the live view.
        open_browser: open the page in the default browser.
        wait_for_browser: play only once a browser has connected.
        keep_open: after the trial, keep the server up until q is typed (only when stdin is a terminal).
    """

    live: bool = True
    host: str = "127.0.0.1"
    record: Path | None = None
    record_fps: float = 50.0
    player: PlayerConfig = field(default_factory=PlayerConfig)
    open_browser: bool = False
    wait_for_browser: bool = False
    keep_open: bool = True


@dataclass(frozen=True)
class ViewResult:
    """What a view produced.

    Attributes:
        trial_record: the trial's record (None for replays).
        recording: the written HTML file, or None.
        frames_drawn: frames sent to the live viewer.
        frames_recorded: frames in the recording.
        paths: scene paths by role (robot, arm, push, ...).
    """

    trial_record: TrialRecord | None
    recording: Path | None
    frames_drawn: int
    frames_recorded: int
    paths: dict[str, list[str]]


def _start_live(cfg: ViewConfig) -> tuple[MeshcatServer, LiveViewer, Player]:
    controls = KeyboardControls().start()
    if not controls.interactive and (cfg.player.pause_at or cfg.player.start_paused):
        raise ConfigError("--pause-at and --paused need a terminal on stdin to resume (keys p and s); run "
                          "interactively, or record with --record and pause in the page")
    server = MeshcatServer(ServerConfig(host=cfg.host)).start()
    viewer = LiveViewer(server)
    print(f"viewer: {server.web_url}  (listening on {cfg.host} only)", file=sys.stderr)
    if cfg.open_browser:
        webbrowser.open(server.web_url, new=2)
    if cfg.wait_for_browser:
        print("waiting for a browser to open the page ...", file=sys.stderr)
        viewer.vis.wait()
    return server, viewer, Player(cfg.player, controls)


def _linger(cfg: ViewConfig, player: Player) -> None:
    """Keep the page served after the trial until the person types q (stdin a terminal only)."""
    controls = player.controls
    if cfg.keep_open and isinstance(controls, KeyboardControls) and controls.interactive and not controls.stopped:
        print("finished; q + Enter closes the viewer", file=sys.stderr)
        try:
            controls.wait_stopped()
        except KeyboardInterrupt:
            pass


def view_trial(trial: Trial, controller: ControllerSpec | str, cfg: ViewConfig) -> ViewResult:
    """Play `trial` with `controller` (resolved, or a name) in simulation, live in the browser and/or recorded."""
    name = controller if isinstance(controller, str) else controller.name
    server = viewer = player = None
    if cfg.live:
        server, viewer, player = _start_live(cfg)
    try:
        observer = LiveObserver(viewer, player, recording_fps=cfg.record_fps if cfg.record else None)
        row, _ = run_trial(trial, controller, observer=observer)
        written = None
        if cfg.record is not None:
            written = observer.recordings[-1].save(cfg.record, title=f"{name}: {trial.scenario} "
                                                   f"{trial.band} seed {trial.seed} trial {trial.index}")
        if cfg.live:
            _linger(cfg, player)
        paths = (viewer.paths if viewer is not None else observer.recordings[-1].paths)
        return ViewResult(trial_record=row, recording=written, frames_drawn=player.drawn if player else 0,
                          frames_recorded=observer.recordings[-1].frames if cfg.record else 0, paths=paths)
    finally:
        if server is not None:
            server.stop()


def replay_episode(stored: StoredEpisode, cfg: ViewConfig) -> ViewResult:
    """Replay a stored episode, live in the browser and/or into a recording."""
    written, recorded, drawn, paths = None, 0, 0, {}
    if cfg.record is not None:
        rec = Recording(stored.content(), fps=cfg.record_fps)
        for frame in stored.frames():
            rec.add(frame)
        t = stored.trial
        written = rec.save(cfg.record, title=f"{stored.controller}: {t.scenario} {t.band} seed {t.seed} "
                                             f"trial {t.index} (replay)")
        recorded, paths = rec.frames, rec.paths
    if cfg.live:
        server, viewer, player = _start_live(cfg)
        try:
            viewer.load(stored.content())
            for frame in stored.frames():
                if player.stopped:
                    break
                if player.due(frame.t):
                    player.wait(frame.t)
                    viewer.show(frame)
                    player.drew(frame.t)
            drawn, paths = player.drawn, viewer.paths
            _linger(cfg, player)
        finally:
            server.stop()
    return ViewResult(trial_record=None, recording=written, frames_drawn=drawn, frames_recorded=recorded, paths=paths)
