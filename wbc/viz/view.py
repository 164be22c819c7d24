"""What ``wbc view`` does: play a trial (or replay a stored one) in the browser, and/or record it to HTML.

- live: a meshcat server bound to ``ViewConfig.host`` (127.0.0.1 by default), the trial played through the
  runner with the viewer as its observer, paced by a `Player` (speed, pauses, single steps);
- record: the same frames keyed into a `Recording` and written as one self-contained HTML file, the trial page
  (`wbc.viz.page`: the scene beside its time plots); with a recording and no live viewer the trial runs at full
  speed and no server is started;
- A / B: two controllers' runs of one trial in one page, the second as a ghost (`view_ab`, `replay_ab`);
- export: the trial as played, pushes and commands from the live page included, written as a scenario that replays
  it for every controller (`wbc.viz.trial_export`).
"""

from __future__ import annotations

import base64
import dataclasses
import functools
import sys
import time
import webbrowser
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from wbc.arena.episode import Episode, OperatorLog, PushLog
from wbc.arena.sim_trial import run_trial
from wbc.arena.trial_record import TrialRecord
from wbc.control.protocol import Controller
from wbc.control.spec import ControllerSpec
from wbc.errors import ConfigError
from wbc.hardware.robot import Robot
from wbc.scenario.push import Push
from wbc.scenario.trial import Trial
from wbc.types import VelocityCommand
from wbc.viz.ab import CapturedRun, ab_recording, capture_trial
from wbc.viz.errors import ViewerError
from wbc.viz.live import LiveObserver, LiveViewer
from wbc.viz.live_page import LivePage, SteeredCommand
from wbc.viz.page import save_trial_page, trial_page
from wbc.viz.player import KeyboardControls, Player, PlayerConfig
from wbc.viz.recording import Recording, frame_key
from wbc.viz.replay import StoredEpisode
from wbc.viz.server import MeshcatServer, ServerConfig
from wbc.viz.signals import Mark, TrialSignals
from wbc.viz.trial_export import ExportedScenario, export_trial

__all__ = ["ABResult", "RecordingTime", "ViewConfig", "ViewResult", "replay_ab", "replay_episode", "view_ab",
           "view_trial"]


@dataclass(frozen=True, kw_only=True)
class ViewConfig:
    """Options of ``wbc view``.

    Attributes:
        live: stream to a browser through a meshcat server.
        host: address the server listens on (127.0.0.1: this machine only).
        record: write a self-contained HTML replay here (None: no recording).
        record_fps: frames per second of the recording [1/s].
        player: pacing of the live view.
        open_browser: open the page in the default browser: the served page live, else the recorded one.
        wait_for_browser: play only once a browser has connected.
        keep_open: after the trial, keep the server up until q is typed (only when stdin is a terminal).
        save_episode: write the episode (with the pushes and commands set from the page) to this ``.npz``.
        export_scenario: write a scenario that replays the trial as played (with the pushes and commands set from
            the page) to this ``.toml`` (`wbc.viz.trial_export`).
        debug_truth: throw the controllers' ground-truth debug switch (`wbc.arena.sim_trial.run_trial`), as a run
            with ``--debug-truth`` plays its trials.
    """

    live: bool = True
    host: str = "127.0.0.1"
    record: Path | None = None
    record_fps: float = 50.0
    player: PlayerConfig = field(default_factory=PlayerConfig)
    open_browser: bool = False
    wait_for_browser: bool = False
    keep_open: bool = True
    save_episode: Path | None = None
    export_scenario: Path | None = None
    debug_truth: bool = False


@dataclass(frozen=True, kw_only=True)
class RecordingTime:
    """Where the wall time of a recorded trial went, measured in the run itself.

    The viewer's share is the time spent in its per-tick observer (building the scene, making, keying and sampling
    frames) and in writing the page; the rest of the run is the trial's simulation (robot, controller, physics), as
    it would run without a viewer.

    Attributes:
        total_s: the whole run, from the trial's start to the page written [s].
        viewer_s: the viewer's share of it [s].
    """

    total_s: float
    viewer_s: float

    @property
    def simulation_s(self) -> float:
        """The trial's simulation without the viewer [s]."""
        return self.total_s - self.viewer_s

    @property
    def ratio(self) -> float:
        """The recorded run's time over the simulation's alone (1: recording costs nothing)."""
        return self.total_s / self.simulation_s if self.simulation_s > 0 else float("inf")

    def line(self) -> str:
        """One line for a person."""
        return (f"recording took {self.total_s:.2f} s: the trial's simulation {self.simulation_s:.2f} s + the viewer "
                f"{self.viewer_s:.2f} s ({self.ratio:.2f}x the simulation alone)")


class _Stopwatch:
    """A runner observer around another that adds up the wall time spent in it [s]."""

    def __init__(self, observer: Callable[..., None]) -> None:
        self.observer = observer
        self.seconds = 0.0

    def __call__(self, t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        """One tick (the `wbc.arena.runner.TickObserver` signature)."""
        start = time.perf_counter()
        try:
            self.observer(t, robot, controller, command)
        finally:
            self.seconds += time.perf_counter() - start


@dataclass(frozen=True)
class ViewResult:
    """What a view produced.

    Attributes:
        trial_record: the trial's record (None for replays).
        recording: the written HTML file, or None.
        frames_drawn: frames sent to the live viewer.
        frames_recorded: frames in the recording.
        paths: scene paths by role (robot, arm, push, ...).
        episode: the episode played (None for replays), with the pushes and commands set from the page.
        timing: where the time of a recorded trial played at full speed went (None when live or not recorded).
        exported: the scenario written with ``export_scenario`` (None without).
    """

    trial_record: TrialRecord | None
    recording: Path | None
    frames_drawn: int
    frames_recorded: int
    paths: dict[str, list[str]]
    episode: Episode | None = None
    timing: RecordingTime | None = None
    exported: ExportedScenario | None = None


def _trial_name(trial: Trial) -> str:
    return f"{trial.scenario} {trial.band} seed {trial.seed} trial {trial.index}"


def _start_live(cfg: ViewConfig) -> tuple[MeshcatServer, LiveViewer, Player]:
    controls = KeyboardControls().start()
    if not controls.interactive and (cfg.player.pause_at or cfg.player.start_paused):
        raise ConfigError("--pause-at and --paused need a terminal on stdin to resume (keys p and s); run "
                          "interactively, or record with --record and pause in the page")
    server = MeshcatServer(ServerConfig(host=cfg.host)).start()
    viewer = LiveViewer(server)
    print(f"viewer: {server.web_url}  (listening on {server.listening})", file=sys.stderr)
    if cfg.open_browser:
        webbrowser.open(server.web_url, new=2)
    if cfg.wait_for_browser:
        print("waiting for a browser to open the page ...", file=sys.stderr)
        viewer.vis.wait()
    return server, viewer, Player(cfg.player, controls)


def _open_recorded(cfg: ViewConfig, written: Path) -> None:
    """With ``open_browser`` and nothing served, open the recorded page (a live view opens its served page)."""
    if cfg.open_browser and not cfg.live:
        webbrowser.open(written.resolve().as_uri(), new=2)


def _linger(cfg: ViewConfig, player: Player) -> None:
    """Keep the page served after the trial until the person types q (stdin a terminal only)."""
    controls = player.controls
    if cfg.keep_open and isinstance(controls, KeyboardControls) and controls.interactive and not controls.stopped:
        print("finished; q + Enter closes the viewer", file=sys.stderr)
        try:
            controls.wait_stopped()
        except KeyboardInterrupt:
            pass


def view_trial(trial: Trial, controller: ControllerSpec | str, cfg: ViewConfig, page: LivePage | None = None
               ) -> ViewResult:
    """Play `trial` with `controller` (resolved, or a name) in simulation, live in the browser and/or recorded.

    Live, the trial page is served too (`LivePage`, on 127.0.0.1: `page`, or one started here): the scene beside its
    plots, with pushes and velocity commands from the page. They are applied through the scenario's `Push` and the
    robot's push hook, and logged in the returned episode: pushes in its `PushLog`, both as operator actions. With
    ``cfg.export_scenario`` the trial as played is then written as a scenario that replays it (`export_trial`).

    Raises:
        ViewerError: ``cfg.export_scenario`` is not a ``.toml`` file in an existing directory (before anything plays).
    """
    name = controller if isinstance(controller, str) else controller.name
    export = cfg.export_scenario
    if export is not None and (export.suffix.lower() != ".toml" or not export.resolve().parent.is_dir()):
        raise ViewerError(f"--export-scenario {export}: give a .toml file in an existing directory")
    server = viewer = player = None
    own_page = False
    if cfg.live:
        server, viewer, player = _start_live(cfg)
        if page is None:
            page, own_page = LivePage().start(), True
        print(f"trial page: {page.url}  (plots; pushes and commands from the page; 127.0.0.1 only)",
              file=sys.stderr)
    try:
        started = time.perf_counter()
        recording_fps = cfg.record_fps if (cfg.record is not None or page is not None) else None
        observer = LiveObserver(viewer, player, recording_fps=recording_fps)
        observer.name = name
        played = trial
        if page is not None:
            page.command = SteeredCommand(trial.command)
            page.trial_s = trial.duration_s  # a push posted before the first tick is checked against it
            page.controls = player.controls if player is not None else None
            played = dataclasses.replace(trial, command=page.command)
        watch = _Stopwatch(_with_page(observer, page, trial, name, cfg))
        row, episode = run_trial(played, controller, observer=watch, debug_truth=cfg.debug_truth)
        if not observer.recordings and (cfg.record is not None or page is not None):
            # no tick was played (the controller could not be built, or failed in reset): no page to show
            raise ViewerError(f"nothing to show: {row.error or 'no tick was played'}")
        ran = time.perf_counter()  # from here on, everything is the viewer's: marks, the page
        signals = observer.signals[-1] if observer.signals else None
        if signals is not None:
            signals.mark_episode(episode)
        if page is not None:
            episode = _log_page_actions(episode, page)
            if signals is not None:
                signals.marks = sorted(signals.marks + page.marks, key=lambda m: m.t)
        written = timing = None
        title = f"{name}: {_trial_name(trial)}"
        if cfg.record is not None:
            written = save_trial_page(cfg.record, observer.recordings[-1], [signals], title=title,
                                      duration=trial.duration_s)
            _open_recorded(cfg, written)
            done = time.perf_counter()
            if not cfg.live:
                timing = RecordingTime(total_s=done - started, viewer_s=watch.seconds + done - ran)
        if page is not None and signals is not None:
            page.finish(trial_page(observer.recordings[-1], [signals], title=title, duration=trial.duration_s))
        if cfg.save_episode is not None:
            episode.save(str(cfg.save_episode))
        exported = None
        if export is not None:
            exported = export_trial(export, trial, controller=name, played_s=episode.survived_s,
                                    browser_pushes=page.pushes if page is not None else (),
                                    browser_commands=page.command.changes if page is not None else ())
        if cfg.live:
            _linger(cfg, player)
        paths = (viewer.paths if viewer is not None else observer.recordings[-1].paths)
        return ViewResult(trial_record=row, recording=written, frames_drawn=player.drawn if player else 0,
                          frames_recorded=observer.recordings[-1].frames if cfg.record else 0, paths=paths,
                          episode=episode, timing=timing, exported=exported)
    finally:
        if server is not None:
            server.stop()
        if own_page:
            page.stop()


_PAGE_FPS = 30.0  # [1/s of trial time] poses handed to a live page


def _with_page(observer: LiveObserver, page: LivePage | None, trial: Trial, name: str, cfg: ViewConfig
               ) -> LiveObserver | Callable[..., None]:
    """The observer, and around it the live page's share of each tick: pushes due, the newest poses."""
    if page is None:
        return observer
    shown = [-float("inf"), False]

    def tick(t: float, robot: Robot, controller: Controller, command: VelocityCommand) -> None:
        page.tick(t, robot)
        observer(t, robot, controller, command)
        if not observer.recordings:
            return
        if not shown[1]:
            rec = observer.recordings[-1]
            page.begin([base64.b64encode(c).decode() for c in rec.window.commands()], rec.content,
                       observer.signals[-1], title=f"{name}: {_trial_name(trial)} (live)",
                       duration=trial.duration_s, fps=cfg.record_fps)
            shown[1] = True
        frame = observer.last_frame
        if frame is not None and frame.t - shown[0] >= 1.0 / _PAGE_FPS - 1e-9:
            shown[0] = frame.t
            page.show(frame)

    return tick


def _log_page_actions(episode: Episode, page: LivePage) -> Episode:
    """The episode with the pushes and commands set from the page: pushes in its log, both as operator actions."""
    pushes = [p for p in page.pushes if p.start < episode.survived_s]
    if not pushes and not page.operator_rows:
        return episode
    log = episode.pushes
    merged = [Push(force_in_world=log.force_in_world[j], offset_in_base=log.offset_in_base[j],
                   start=float(log.start[j]), duration=float(log.duration[j])) for j in range(len(log))]
    merged = sorted(merged + pushes, key=lambda p: p.start)
    rows = sorted(episode.operator_events.rows() + page.operator_rows, key=lambda r: r[0])
    return dataclasses.replace(episode, pushes=PushLog.of(merged), operator_events=OperatorLog.of(rows))


def _no_export(cfg: ViewConfig, what: str) -> None:
    if cfg.export_scenario is not None:
        raise ViewerError(f"--export-scenario writes the trial one controller plays (wbc view CTRL --scenario FILE "
                          f"--trial I), not {what}")


def replay_episode(stored: StoredEpisode, cfg: ViewConfig) -> ViewResult:
    """Replay a stored episode, live in the browser and/or into a recording."""
    _no_export(cfg, "a stored episode")
    written, recorded, drawn, paths = None, 0, 0, {}
    if cfg.record is not None:
        rec = Recording(stored.content(), fps=cfg.record_fps, tick_s=stored.episode.control_dt)
        for frame in stored.frames():
            rec.add(frame)
        record = stored.record
        signals = TrialSignals.of_episode(stored.controller, stored.episode,
                                          outcome=record.outcome if record is not None else None,
                                          error=record.error if record is not None else "").thinned(cfg.record_fps)
        # a hardware trial's arm faults, beside the safety layer's trip they caused
        signals.marks = sorted(signals.marks + [Mark(t, "safety", what) for t, what in stored.arm_faults],
                               key=lambda m: m.t)
        written = save_trial_page(cfg.record, rec, [signals], duration=stored.trial.duration_s,
                                  title=f"{stored.controller}: {_trial_name(stored.trial)} (replay)")
        _open_recorded(cfg, written)
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


@dataclass(frozen=True)
class ABResult:
    """What an A / B view produced.

    Attributes:
        recording: the written page.
        names: the two controllers, the first drawn opaque, the second as the ghost.
        trial_records: each run's record (None for stored episodes).
        divergence_s: when the runs first part [s] (None if they never do).
        fall_s: when each fell [s] (None if it did not).
        frames: frames recorded of each run.
    """

    recording: Path
    names: tuple[str, str]
    trial_records: tuple[TrialRecord | None, TrialRecord | None]
    divergence_s: float | None
    fall_s: tuple[float | None, float | None]
    frames: tuple[int, int]


def _write_ab(a: CapturedRun, b: CapturedRun, trial: Trial, cfg: ViewConfig, path: Path, suffix: str) -> ABResult:
    rec, marks = ab_recording(a, b, cfg.record_fps)
    written = save_trial_page(path, rec, [a.signals, b.signals], marks=marks, duration=trial.duration_s,
                              title=f"{a.name} vs {b.name} (ghost): {_trial_name(trial)}{suffix}")
    if cfg.open_browser:
        webbrowser.open(written.resolve().as_uri(), new=2)

    def fall(run: CapturedRun) -> float | None:
        return next((m.t for m in run.signals.marks if m.kind == "fall"), None)

    return ABResult(recording=written, names=(a.name, b.name), trial_records=(a.record, b.record),
                    divergence_s=marks[0].t if marks else None, fall_s=(fall(a), fall(b)),
                    frames=(len(a.frames), len(b.frames)))


def view_ab(trial: Trial, controllers: tuple[ControllerSpec | str, ControllerSpec | str], cfg: ViewConfig,
            path: Path) -> ABResult:
    """Play `trial` with both controllers in simulation and write one page of both runs to `path`."""
    _no_export(cfg, "an A / B view")
    run = functools.partial(run_trial, debug_truth=cfg.debug_truth)
    a, b = (capture_trial(trial, c, cfg.record_fps, run=run) for c in controllers)
    return _write_ab(a, b, trial, cfg, path, "")


def replay_ab(first: StoredEpisode, second: StoredEpisode, cfg: ViewConfig, path: Path) -> ABResult:
    """Write one page of two stored runs of the same trial (`second` the ghost) to `path`."""
    _no_export(cfg, "an A / B view")
    runs = []
    for stored in (first, second):
        run = CapturedRun(stored.controller, stored.content(),
                          signals=TrialSignals.of_episode(stored.controller, stored.episode).thinned(cfg.record_fps),
                          tick_s=stored.episode.control_dt)
        last = -1
        for frame in stored.frames():
            k = frame_key(frame.t, cfg.record_fps, run.tick_s)
            if k > last:
                run.frames.append(frame)
                last = k
        runs.append(run)
    return _write_ab(runs[0], runs[1], first.trial, cfg, path, " (replay)")
