"""`LivePage`: the trial page of a trial being played, served on 127.0.0.1, with pushes and commands from the page.

A small HTTP server, bound to the loopback address whatever ``--host`` says (a browser on this machine may push the
robot; nobody else may), serves:

- ``GET /``: the trial page (`wbc.viz.page`) in its live form: the scene built from the same commands as a recording,
  posed from ``/state`` as the trial plays, the plots growing; once the trial has ended, the recorded page itself
  (the live page reloads into it, so scrubbing and slow motion work over the whole trial);
- ``GET /state``: the trial time, the newest poses, the plots so far and the trial's duration (JSON), and which
  trial's scene the page should hold (a page opened before the trial's first tick reloads into its scene);
- ``POST /push``: ``{"force_n", "heading_deg", "duration_s", "point_in_base": [x, y, z], "t"}`` a horizontal push
  towards world heading ``heading_deg`` (0 along world x, 90 along world y), applied at trial time ``t`` (default:
  now) through the same `wbc.scenario.push.Push` the scenarios use and the robot's `Pushable` hook;
- ``POST /command``: ``{"vx", "vy", "yaw_rate"}`` the velocity command from the next control tick on (a
  `wbc.scenario.trial.CommandChange` of the trial's schedule, at the time of the tick that first plays it);
- ``POST /control``: ``{"pause": true|false}`` or ``{"speed": s}`` the pacing of the live trial.

A request that is not a JSON object of these fields, in range (a push's ``t`` within the trial), is answered 400
with what is wrong; once the trial has ended, every request is refused so.

Every push and command change is kept (`pushes`, the command's `SteeredCommand.changes`, `operator_rows`) so the
viewer logs them in the episode: pushes in its `PushLog` (as a scenario's), both as operator actions (``browser``
key), and as marks on the page. Both take effect at a control tick and are kept with that tick's time, so a scenario
written from them (`wbc.viz.trial_export`) plays them again exactly.
"""

from __future__ import annotations

import json
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np

from wbc.errors import ConfigError
from wbc.hardware.capabilities import Pushable
from wbc.scenario.push import Push
from wbc.scenario.trial import CommandChange, CommandSchedule
from wbc.types import VelocityCommand
from wbc.viz.content import SceneContent
from wbc.viz.frame import VizFrame
from wbc.viz.page import live_page_html
from wbc.viz.player import Controls
from wbc.viz.signals import Mark, TrialSignals

__all__ = ["LivePage", "PushRequest", "SteeredCommand"]

LOOPBACK = "127.0.0.1"
_MAX_FORCE_N = 2000.0  # as a scenario's pushes
_MAX_IMPULSE_NS = 200.0
_MAX_BODY = 1 << 16  # [bytes] a request's body: a push or a command is a few dozen


@dataclass(frozen=True)
class PushRequest:
    """A push asked for from the page.

    Attributes:
        force_n: magnitude [N], horizontal.
        heading_deg: world heading it pushes towards [deg].
        duration_s: how long it acts [s].
        point_in_base: application point in the trunk frame [m].
        t: trial time to apply it at [s] (None: at once).
    """

    force_n: float
    heading_deg: float
    duration_s: float
    point_in_base: tuple[float, float, float]
    t: float | None = None

    @classmethod
    def parse(cls, body: dict, *, duration: float | None = None) -> PushRequest:
        """The request in a POSTed JSON object.

        Args:
            body: the object.
            duration: the trial's length [s], past which ``t`` is refused (None: not known yet).

        Raises:
            ConfigError: a missing or out-of-range field (the message names it and its range).
        """
        try:
            req = cls(force_n=float(body["force_n"]), heading_deg=float(body.get("heading_deg", 0.0)),
                      duration_s=float(body.get("duration_s", 0.1)),
                      point_in_base=tuple(float(x) for x in body.get("point_in_base", (0.0, 0.0, 0.0))),
                      t=None if body.get("t") is None else float(body["t"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"push: {exc}; send force_n, heading_deg, duration_s, point_in_base [x, y, z], "
                              "t") from None
        if not 0.0 < req.force_n <= _MAX_FORCE_N:
            raise ConfigError(f"push: force_n must be in (0, {_MAX_FORCE_N:g}] N, got {req.force_n}")
        if not 0.01 <= req.duration_s <= 1.0:
            raise ConfigError(f"push: duration_s must be in [0.01, 1] s, got {req.duration_s}")
        if req.force_n * req.duration_s > _MAX_IMPULSE_NS:
            raise ConfigError(f"push: {req.force_n:g} N for {req.duration_s:g} s is more than {_MAX_IMPULSE_NS:g} N s")
        if len(req.point_in_base) != 3 or max(abs(x) for x in req.point_in_base) > 0.5:
            raise ConfigError(f"push: point_in_base must be 3 numbers within 0.5 m, got {req.point_in_base}")
        if not all(math.isfinite(x) for x in (req.heading_deg, *req.point_in_base)):
            raise ConfigError("push: heading_deg and point_in_base must be finite")
        if req.t is not None and not (0.0 <= req.t < math.inf and (duration is None or req.t < duration)):
            within = f"[0, {duration:g})" if duration is not None else "0 or later"
            raise ConfigError(f"push: t must be a trial time in {within} s (a push after the trial's end is never "
                              f"applied), got {req.t}")
        return req

    def push(self, now: float) -> Push:
        """The scenario `Push` it asks for, starting at its time or `now` [s], whichever is later."""
        start = now if self.t is None else max(now, self.t)
        return Push.horizontal(self.force_n, math.radians(self.heading_deg), self.point_in_base, start,
                               self.duration_s)


class SteeredCommand:
    """The trial's command schedule until the page sets a command; the page's latest command from then on.

    Attributes:
        schedule: the trial's own schedule.
        changes: the commands set from the page, each from the control tick that first played it, in time order.
    """

    def __init__(self, schedule: CommandSchedule) -> None:
        self.schedule = schedule
        self.changes: list[CommandChange] = []

    def at(self, t: float) -> VelocityCommand:
        """The command at time `t` [s].

        The page's latest command set by then; before the page's first, the schedule's (its own changes included).
        """
        for change in reversed(self.changes):
            if t >= change.at_s:
                return change.command
        return self.schedule.at(t)

    def change(self, t: float, command: VelocityCommand) -> None:
        """From time `t` [s] on (no earlier than the last change), play `command`."""
        if self.changes and t <= self.changes[-1].at_s:
            self.changes[-1] = CommandChange(at_s=self.changes[-1].at_s, command=command)
        else:
            self.changes.append(CommandChange(at_s=t, command=command))

    # the trial's record keeps the schedule's own values: the page's commands are logged as operator actions
    @property
    def vx(self) -> float:
        """The schedule's forward velocity [m/s]."""
        return self.schedule.vx

    @property
    def vy(self) -> float:
        """The schedule's lateral velocity [m/s]."""
        return self.schedule.vy

    @property
    def yaw_rate(self) -> float:
        """The schedule's yaw rate [rad/s]."""
        return self.schedule.yaw_rate

    @property
    def ramp_s(self) -> float:
        """The schedule's ramp [s]."""
        return self.schedule.ramp_s


class LivePage:
    """The live trial page and its endpoints (see the module docstring); a context manager that stops it.

    Args:
        port: the port to listen on (0: any free one).

    Attributes:
        url: the page (``http://127.0.0.1:PORT/``).
        pushes: the pushes applied from the page, in order.
        operator_rows: (time, ``browser``, action) of every push and command set from the page.
        trial_s: the length of the trial about to play [s], when known before its first tick (the viewer sets it),
            so that a push posted early for a time past its end is refused; `begin` sets it too.
    """

    def __init__(self, port: int = 0) -> None:
        self._lock = threading.Lock()
        self._server = ThreadingHTTPServer((LOOPBACK, port), _handler(self))
        self._server.daemon_threads = True
        self.url = f"http://{LOOPBACK}:{self._server.server_address[1]}/"
        self._thread: threading.Thread | None = None
        self.pushes: list[Push] = []
        self.operator_rows: list[tuple[float, str, str]] = []
        self.controls: Controls | None = None
        self.command: SteeredCommand | None = None
        self._queued: list[PushRequest] = []
        self._commands: list[VelocityCommand] = []
        self._t = 0.0
        self._poses: dict[str, list[float] | None] = {}
        self._signals: TrialSignals | None = None
        self._marks: list[Mark] = []
        self._scene: list[str] = []
        self._title = "wbc live"
        self._duration = 0.0
        self._fps = 50.0
        self._final: str | None = None
        self._content: SceneContent | None = None
        self.trial_s: float | None = None
        self._scene_id = 0  # trials begun: a page served before the trial's scene existed reloads once it does

    def start(self) -> LivePage:
        """Serve on a thread of its own."""
        self._thread = threading.Thread(target=self._server.serve_forever, name="wbc-live-page", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop serving (idempotent)."""
        if self._thread is not None:
            self._server.shutdown()
            self._thread.join(timeout=5.0)
            self._thread = None
        self._server.server_close()

    def __enter__(self) -> LivePage:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- the trial's side ----------------------------------------------------------------------------------------
    def begin(self, scene: list[str], content: SceneContent, signals: TrialSignals, *, title: str,
              duration: float, fps: float) -> None:
        """A trial starts: its scene commands (base64), what draws it, the signals being sampled."""
        with self._lock:
            self._scene, self._content, self._signals = scene, content, signals
            self._title, self._duration, self._fps, self._final = title, duration, fps, None
            self._scene_id += 1
            self.trial_s = duration

    def tick(self, t: float, robot: object) -> None:
        """Before the observer draws tick `t`: apply the pushes due (on a `Pushable` robot) and the command set."""
        with self._lock:
            self._t = t
            due = [r for r in self._queued if r.t is None or r.t <= t + 1e-9]
            self._queued = [r for r in self._queued if r not in due]
            commands, self._commands = self._commands, []
        if commands and self.command is not None:
            cmd = commands[-1]  # set since the last tick: the ones before it never played
            self.command.change(t, cmd)
            label = f"browser command vx {cmd.vx:g} vy {cmd.vy:g} yaw rate {cmd.yaw_rate:g}"
            with self._lock:
                self.operator_rows.append((t, "browser", label))
                self._marks.append(Mark(t, "command", label))
        for req in due:
            if not isinstance(robot, Pushable):
                continue
            push = req.push(t)
            robot.apply_push(push)
            label = (f"browser push {req.force_n:.0f} N towards {req.heading_deg:.0f} deg for {req.duration_s:g} s "
                     f"at ({', '.join(f'{x:g}' for x in req.point_in_base)})")
            with self._lock:
                self.pushes.append(push)
                self.operator_rows.append((push.start, "browser", label))
                self._marks.append(Mark(push.start, "browser_push", label, push.duration))

    def show(self, frame: VizFrame) -> None:
        """The frame just drawn: its poses become the page's (call at the page's rate, from the trial's thread)."""
        if self._content is None:
            return
        poses = {}
        for path, pose in self._content.poses(frame).items():
            full = path if path.startswith("/") else f"/meshcat/{path}"
            poses[full] = np.asarray(pose.matrix).T.reshape(-1).tolist() if pose.visible else None
        with self._lock:
            self._poses.update(poses)
            self._t = frame.t

    def finish(self, final_html: str) -> None:
        """The trial has ended: the page becomes the recorded page `final_html`."""
        with self._lock:
            self._final = final_html

    @property
    def marks(self) -> list[Mark]:
        """The events set from the page (pushes, commands)."""
        with self._lock:
            return list(self._marks)

    # -- the page's side -----------------------------------------------------------------------------------------
    def _page(self) -> str:
        with self._lock:
            if self._final is not None:
                return self._final
            return live_page_html(self._scene, title=self._title, duration=self._duration, fps=self._fps,
                                  scene_id=self._scene_id)

    def _state(self) -> dict[str, object]:
        with self._lock:
            runs = [self._signals.to_json()] if self._signals is not None else []
            for run in runs:
                run["marks"] = run["marks"] + [m.to_json() for m in self._marks]
            return {"t": self._t, "done": self._final is not None, "poses": self._poses, "scene": self._scene_id,
                    "data": {"duration": self._duration, "runs": runs}}

    def _post(self, route: str, body: dict) -> dict[str, object]:
        with self._lock:
            if self._final is not None and route in ("/push", "/command", "/control"):
                raise ConfigError(f"{route[1:]}: the trial has ended")
            duration = self.trial_s
        if route == "/push":
            req = PushRequest.parse(body, duration=duration)
            with self._lock:
                self._queued.append(req)
            return {"queued": True}
        if route == "/command":
            try:
                cmd = VelocityCommand(vx=float(body.get("vx", 0.0)), vy=float(body.get("vy", 0.0)),
                                      yaw_rate=float(body.get("yaw_rate", 0.0)))
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"command: {exc}; send vx, vy, yaw_rate") from None
            if not (abs(cmd.vx) <= 3.0 and abs(cmd.vy) <= 2.0 and abs(cmd.yaw_rate) <= 3.0):
                raise ConfigError("command: |vx| <= 3 m/s, |vy| <= 2 m/s, |yaw_rate| <= 3 rad/s, as in a scenario")
            if self.command is None:
                raise ConfigError("command: no trial is playing")
            with self._lock:
                self._commands.append(cmd)
            return {"set": True}
        if route == "/control":
            if self.controls is None:
                raise ConfigError("control: this trial is not paced")
            pause, speed = body.get("pause"), body.get("speed")
            if "pause" in body and not isinstance(pause, bool):
                raise ConfigError(f"control: pause must be true or false, got {json.dumps(pause)}")
            if "speed" in body and (isinstance(speed, bool) or not isinstance(speed, int | float)
                                    or not 0.01 <= speed <= 100):
                raise ConfigError(f"control: speed must be a number in [0.01, 100], got {json.dumps(speed)}")
            if "pause" in body and pause != self.controls.paused:
                self.controls.toggle_pause()
            if "speed" in body:
                self.controls.speed_factor = float(speed)
            return {"paused": self.controls.paused, "speed": self.controls.speed_factor}
        raise ConfigError(f"no such endpoint {route}; valid: /push, /command, /control")


def _handler(page: LivePage) -> Callable[..., BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args: object) -> None:  # quiet: the terminal belongs to the trial
            return

        def _send(self, code: int, body: bytes, kind: str) -> None:
            self.send_response(code)
            self.send_header("Content-Type", kind)
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)

        def do_GET(self) -> None:  # noqa: N802 - the standard library's name
            route = self.path.split("?", 1)[0]
            if route == "/":
                self._send(200, page._page().encode("utf-8"), "text/html; charset=utf-8")
            elif route == "/state":
                self._send(200, json.dumps(page._state(), allow_nan=False).encode(), "application/json")
            else:
                self._send(404, b"not found", "text/plain")

        def do_POST(self) -> None:  # noqa: N802 - the standard library's name
            try:
                length = int(self.headers.get("Content-Length") or 0)
                if not 0 <= length <= _MAX_BODY:
                    raise ValueError(length)
            except ValueError:
                self._send(400, json.dumps({"error": f"Content-Length must be a number of bytes in [0, {_MAX_BODY}], "
                                                     f"got {self.headers.get('Content-Length')!r}"}).encode(),
                           "application/json")
                return
            # JSON only: a page of another origin cannot send it without a preflight this server never grants
            if self.headers.get("Content-Type", "").split(";")[0].strip() != "application/json":
                self._send(415, b'{"error": "send Content-Type: application/json"}', "application/json")
                return
            try:
                body = json.loads(self.rfile.read(length) or b"{}")
                if not isinstance(body, dict):
                    raise ConfigError("send a JSON object")
                reply = page._post(self.path.split("?", 1)[0], body)
            except (ConfigError, ValueError) as exc:  # ValueError: not JSON, or not UTF-8
                self._send(400, json.dumps({"error": str(exc)}).encode(), "application/json")
                return
            self._send(200, json.dumps(reply).encode(), "application/json")

    return Handler
