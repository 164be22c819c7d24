"""`Recording`: a trial as a meshcat animation in one self-contained HTML file that opens without a server.

`Recording` is a meshcat window that keeps the scene in memory instead of sending it to a server: the scene is built
on it with the ordinary ``meshcat.Visualizer`` API, frames are added as animation keys, and `html` writes meshcat's
viewer script inline with every scene command (base64, applied in order), so the file needs no network and no
server. The page plays the animation once; meshcat's panel (Animations) has play, pause, the time slider and
``timeScale`` for slow motion. Opening the file with ``#t=3.2`` in the URL pauses it at 3.2 s (``#t=3.2&play``
plays on from there).

Keys are thinned: a track gets a key only where its value changes (and just before, so a held value is not
interpolated), and visibility only where it flips. Adding a frame only keeps it; the frames are posed and keyed a
chunk at a time, with numpy over the chunk (`SceneContent.poses_many`, `_NodeKeys`), which keeps recording cheap
beside the simulation and its memory bounded whatever the trial's length.
"""

from __future__ import annotations

import base64
import html as html_lib
import math
from pathlib import Path

import meshcat
import numpy as np
import umsgpack
from meshcat.animation import Animation
from meshcat.servers.zmqserver import VIEWER_ROOT

from wbc.errors import ConfigError
from wbc.viz.content import SceneContent
from wbc.viz.errors import ViewerError
from wbc.viz.frame import PoseTrack, VizFrame

__all__ = ["GHOST_COLOR", "Recording", "frame_key", "viewer_script"]

GHOST_COLOR = (0.35, 0.55, 1.0, 0.35)
"""RGB and opacity of a ghost robot (the second run of an A / B view)."""
_GHOST_SKIP = ("wbc/contacts", "wbc/command", "wbc/plan", "/")

_APPLY_SCRIPT = """
// In order and synchronously: later commands (the animation) must win over earlier ones (initial visibility).
for (var i = 0; i < wbcCommands.length; i++) {
  var raw = atob(wbcCommands[i]), bytes = new Uint8Array(raw.length);
  for (var j = 0; j < raw.length; j++) { bytes[j] = raw.charCodeAt(j); }
  viewer.handle_command_bytearray(bytes);
}
"""

_SEEK_SCRIPT = """
(function () {
  var m = /[#&]t=([0-9.]+)/.exec(window.location.hash);
  if (!m) { return; }
  var t = parseFloat(m[1]), play = /[#&]play/.test(window.location.hash);
  var tries = 0;
  var timer = setInterval(function () {
    var a = viewer.animator;
    if ((a && a.actions && a.actions.length > 0) || ++tries > 200) {
      clearInterval(timer);
      if (a && a.actions && a.actions.length > 0) {
        a.pause(); a.seek(t); a.display_progress(t);
        if (play) { a.play(); }
      }
    }
  }, 50);
})();
"""


def viewer_script() -> str:
    """The viewer script of meshcat (three.js and the viewer), as shipped by the meshcat package."""
    return (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")


class _SceneWindow:
    """A meshcat "window" that stores the scene tree (objects, transforms, properties, animation) in memory."""

    def __init__(self) -> None:
        self.nodes: dict[str, dict[str, object]] = {}
        self.order: list[str] = []

    def _node(self, path: str) -> dict[str, object]:
        if path not in self.nodes:
            self.nodes[path] = {"object": None, "transform": None, "properties": {}}
            self.order.append(path)
        return self.nodes[path]

    def send(self, command: object) -> None:
        """Store one meshcat command, as the meshcat server's tree would."""
        data = command.lower()
        node = self._node(data["path"])
        # single precision: 4 bytes a number instead of 8 (a micrometre at 10 m); the browser holds float32 anyway
        packed = umsgpack.packb(data, force_float_precision="single")
        kind = data["type"]
        if kind == "set_object":
            node["object"] = packed
        elif kind == "set_transform":
            node["transform"] = packed
        elif kind == "set_property":
            node["properties"][data["property"]] = packed
        elif kind == "set_animation":
            node["animation"] = packed
        elif kind == "delete":
            for p in [p for p in self.order if p == data["path"] or p.startswith(data["path"] + "/")]:
                self.nodes.pop(p)
                self.order.remove(p)
        else:
            raise ViewerError(f"a recording cannot store the meshcat command {kind!r}")

    def commands(self) -> list[bytes]:
        """Every stored command, parents before children, objects before their properties and transforms."""
        out: list[bytes] = []
        for path in self.order:
            node = self.nodes[path]
            if node["object"] is not None:
                out.append(node["object"])
            out.extend(node["properties"].values())
            if node["transform"] is not None:
                out.append(node["transform"])
        out.extend(n["animation"] for n in self.nodes.values() if n.get("animation") is not None)
        return out


_TOL = 1e-5
"""A transform component moving less than this between two frames is held, not keyed."""
_CHUNK = 256
"""Frames buffered before they are posed and keyed as one batch (bounds the buffer of a long trial)."""
_PROPS = (("position", "vector3"), ("quaternion", "quaternion"), ("scale", "vector3"))


class _NodeKeys:
    """The animation keys of one node: its visibility where it flips, its transform where it moves.

    A transform is keyed where any component of its position, quaternion or scale differs from the frame before by
    more than `_TOL`; the frame before is keyed too when it was not (the value held up to there is not
    interpolated). Frames come a batch at a time (`add_track`); each batch continues from the last frame of the one
    before.
    """

    def __init__(self) -> None:
        self.visible: list[tuple[int, bool]] = []
        self.frames: dict[str, list[np.ndarray]] = {prop: [] for prop, _ in _PROPS}
        self.values: dict[str, list[np.ndarray]] = {prop: [] for prop, _ in _PROPS}
        self._last: dict[str, tuple[int, np.ndarray, bool]] = {}  # prop -> last frame, its value, whether keyed

    def add_track(self, ks: np.ndarray, track: PoseTrack) -> None:
        """The node's poses over a batch of frames: at frame ``ks[i]`` for each i in ``track.frames``."""
        ks = ks[track.frames]
        if not len(ks):
            return
        vis = np.asarray(track.visible, dtype=bool)
        flips = np.empty(len(vis), dtype=bool)
        flips[0] = not self.visible or self.visible[-1][1] != bool(vis[0])
        flips[1:] = vis[1:] != vis[:-1]
        self.visible.extend((k, v) for k, v in zip(ks[flips].tolist(), vis[flips].tolist(), strict=True))
        if vis.any():
            for (prop, _), values in zip(_PROPS, _decompose(np.asarray(track.matrices)[vis]), strict=True):
                self._key(prop, ks[vis], values)

    def _key(self, prop: str, frames: np.ndarray, values: np.ndarray) -> None:
        last = self._last.get(prop)
        if last is not None:  # the chunk continues from the last frame of the one before
            frames = np.concatenate([[last[0]], frames])
            values = np.concatenate([last[1][None, :], values])
        moved = np.abs(np.diff(values, axis=0)).max(axis=1) > _TOL
        changed = np.concatenate([[True if last is None else last[2]], moved])
        held = np.zeros_like(changed)
        held[:-1] = changed[1:] & ~changed[:-1]
        keep = changed | held
        if last is not None:
            keep[0] = held[0]  # keyed already, unless it is the held value before a change
        idx = np.flatnonzero(keep)
        if len(idx):
            self.frames[prop].append(frames[idx])
            self.values[prop].append(values[idx])
        self._last[prop] = (int(frames[-1]), values[-1].copy(), bool(changed[-1]))

    def keys(self, prop: str) -> tuple[np.ndarray, np.ndarray]:
        """(frames, values) of the keys of `prop`."""
        if not self.frames[prop]:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 4 if prop == "quaternion" else 3))
        return np.concatenate(self.frames[prop]), np.concatenate(self.values[prop])


def _decompose(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions, quaternions x y z w, scales) of transforms with positive scale along their axes, shape (n, 4, 4).

    Returns:
        Shapes (n, 3), (n, 4) and (n, 3).
    """
    rot = m[:, :3, :3]
    scale = np.sqrt(np.einsum("nij,nij->nj", rot, rot))  # the columns' lengths
    r = rot / np.where(scale > 0.0, scale, 1.0)[:, None, :]
    return m[:, :3, 3].copy(), _quaternions(r), scale


def _quaternions(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices `r`, shape (n, 3, 3), each by the largest of its four forms.

    The sign is the one with w >= 0, so that keys compare equal when a pose holds.
    """
    q = np.empty((len(r), 4))
    r00, r11, r22 = r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]
    trace = r00 + r11 + r22
    a = trace > 0.0
    b = ~a & (r00 > r11) & (r00 > r22)
    c = ~a & ~b & (r11 > r22)
    d = ~(a | b | c)
    if a.any():
        x, s = r[a], 0.5 / np.sqrt(trace[a] + 1.0)
        q[a] = np.stack([(x[:, 2, 1] - x[:, 1, 2]) * s, (x[:, 0, 2] - x[:, 2, 0]) * s, (x[:, 1, 0] - x[:, 0, 1]) * s,
                         0.25 / s], axis=1)
    if b.any():
        x = r[b]
        s = 2.0 * np.sqrt(np.maximum(1.0 + x[:, 0, 0] - x[:, 1, 1] - x[:, 2, 2], 1e-12))
        q[b] = np.stack([0.25 * s, (x[:, 0, 1] + x[:, 1, 0]) / s, (x[:, 0, 2] + x[:, 2, 0]) / s,
                         (x[:, 2, 1] - x[:, 1, 2]) / s], axis=1)
    if c.any():
        x = r[c]
        s = 2.0 * np.sqrt(np.maximum(1.0 + x[:, 1, 1] - x[:, 0, 0] - x[:, 2, 2], 1e-12))
        q[c] = np.stack([(x[:, 0, 1] + x[:, 1, 0]) / s, 0.25 * s, (x[:, 1, 2] + x[:, 2, 1]) / s,
                         (x[:, 0, 2] - x[:, 2, 0]) / s], axis=1)
    if d.any():
        x = r[d]
        s = 2.0 * np.sqrt(np.maximum(1.0 + x[:, 2, 2] - x[:, 0, 0] - x[:, 1, 1], 1e-12))
        q[d] = np.stack([(x[:, 0, 2] + x[:, 2, 0]) / s, (x[:, 1, 2] + x[:, 2, 1]) / s, 0.25 * s,
                         (x[:, 1, 0] - x[:, 0, 1]) / s], axis=1)
    q[q[:, 3] < 0.0] *= -1.0
    return q / np.linalg.norm(q, axis=1, keepdims=True)


class _AnimationCommand:
    """meshcat's ``set_animation`` with each numeric track as two float32 arrays (frame times, values).

    three.js reads a track either as a list of {time, value} keys (what meshcat's Python writes) or as ``times``
    and ``values`` arrays; the arrays are a quarter of the size and cost nothing to pack. Boolean tracks (few keys:
    only where visibility flips) keep the key list.
    """

    def __init__(self, clips: list[tuple[str, list[dict[str, object]]]], fps: float, play: bool) -> None:
        self.clips, self.fps, self.play = clips, fps, play

    def lower(self) -> dict[str, object]:
        return {"type": "set_animation", "path": "", "options": {"play": self.play, "repetitions": 1},
                "animations": [{"path": path, "clip": {"fps": self.fps, "name": "default", "tracks": tracks}}
                               for path, tracks in self.clips]}


def _floats(values: np.ndarray) -> umsgpack.Ext:
    return umsgpack.Ext(_FLOAT32_EXT, np.asarray(values, dtype="<f4").tobytes())


_FLOAT32_EXT = 0x17  # meshcat's msgpack extension code for a Float32Array


def frame_key(t: float, fps: float, tick_s: float = 0.0) -> int:
    """The animation frame (index at `fps` [1/s]) that a control tick at `t` [s] is the nearest tick to, or after.

    A controller of period `tick_s` [s] is drawn at frame ``k`` by its tick nearest to ``k / fps``: the first tick
    from ``k / fps - tick_s / 2`` on, so the tick at ``k / fps`` exactly when there is one (a 500 Hz or 50 Hz
    controller at 50 frames a second). Rounding ``t * fps`` instead drew a 500 Hz controller's tick at 0.012 s at
    0.02 s. With `tick_s` 0 (unknown), the first tick at or after ``k / fps``.
    """
    return math.floor((t + 0.5 * tick_s) * fps + 1e-6)


class Recording:
    """Record frames of one trial into a self-contained HTML replay.

    Args:
        content: what to draw (its `setup` is run here).
        fps: animation frame rate [1/s]; each frame is keyed at its nearest control tick (`frame_key`).
        tick_s: the control period of the frames' source [s] (0: unknown; see `frame_key`); settable until the
            first frame.

    Attributes:
        vis: the meshcat visualizer that draws into this recording (for extra objects).
    """

    def __init__(self, content: SceneContent, *, fps: float = 50.0, tick_s: float = 0.0) -> None:
        if not fps > 0:
            raise ConfigError(f"the recording's frame rate (--fps) must be > 0, got {fps}")
        self.content = content
        self.fps = fps
        self.tick_s = tick_s
        self.window = _SceneWindow()
        self.vis = meshcat.Visualizer(window=self.window)
        content.setup(self.vis)
        self._nodes: dict[str, _NodeKeys] = {}  # full path -> its keys, in the order first keyed
        self._full: dict[tuple[int, str], _NodeKeys] = {}  # (-1 or ghost index, scene path) -> its node's keys
        self._last_frame = -1
        self.frames = 0
        self._ghosts: list[tuple[SceneContent, meshcat.Visualizer]] = []
        self._ghost_last: list[int] = []
        self._ghost_tick: list[float] = []
        self._pending: dict[int, list[tuple[int, VizFrame]]] = {-1: []}  # owner -> frames not keyed yet

    @property
    def last_key(self) -> int:
        """Index of the last keyed frame (-1 before the first); a frame at t is keyed if its `frame_key` exceeds it."""
        return self._last_frame

    def key_of(self, t: float) -> int:
        """The animation frame a tick at `t` [s] of this recording's source would be keyed at (`frame_key`)."""
        return frame_key(t, self.fps, self.tick_s)

    @property
    def next_key_s(self) -> float:
        """The earliest tick time [s] that `add` would key (no tick before it rounds to a new frame)."""
        return (self._last_frame + 1 - 1e-6) / self.fps - 0.5 * self.tick_s - 1e-9

    @property
    def paths(self) -> dict[str, list[str]]:
        """Scene paths of the recorded content, by role (see `SceneContent.paths`)."""
        return self.content.paths

    def add(self, frame: VizFrame) -> bool:
        """Add `frame` as the animation's state at its time; frames closer than 1/fps to the last are skipped.

        Frames are keyed `_CHUNK` at a time, their node poses computed over the batch (`SceneContent.poses_many`):
        a frame handed over is not changed afterwards (no `VizFrame` is).

        Returns:
            True if the frame was keyed.
        """
        k = frame_key(frame.t, self.fps, self.tick_s)
        if k <= self._last_frame:
            return False
        self._last_frame = k
        self.frames += 1
        pending = self._pending[-1]
        pending.append((k, frame))
        if len(pending) >= _CHUNK:
            self._key_pending(-1)
        return True

    def _key_pending(self, owner: int) -> None:
        """Key the frames of `owner` (-1: the recording's robot; else a ghost's index) still waiting."""
        pending = self._pending[owner]
        if not pending:
            return
        self._pending[owner] = []
        ks = np.array([k for k, _ in pending], dtype=np.int64)
        frames = [f for _, f in pending]
        content, vis = (self.content, self.vis) if owner < 0 else self._ghosts[owner]
        full = self._full
        for path, track in content.poses_many(frames).items():
            node = full.get((owner, path))
            if node is None:
                if owner >= 0 and path.startswith(_GHOST_SKIP):
                    continue
                node = self._node(owner, path, path if owner < 0 and path.startswith("/") else vis[path].path.lower())
            node.add_track(ks, track)

    def add_ghost(self, content: SceneContent, *, color: tuple[float, float, float, float] = GHOST_COLOR,
                  tick_s: float = 0.0) -> int:
        """Add a second robot to the scene, drawn translucent (a ghost), under ``ghost<i>/``; its index.

        The ghost's ground, contact arrows, command arrow and plan are not drawn (the first robot's are); its push
        arrow is. Its camera does not move (the first robot's follows the trunk). `tick_s` is its source's control
        period [s] (`frame_key`).
        """
        i = len(self._ghosts)
        content.follow = False
        vis = self.vis[f"ghost{i}"]
        content.setup(vis)
        for path in content.paths["robot"] + content.paths["arm"]:
            vis[path].set_property("color", list(color))
        for path in content.paths["terrain"]:
            vis[path].set_property("visible", False)
        self._ghosts.append((content, vis))
        self._ghost_last.append(-1)
        self._ghost_tick.append(tick_s)
        self._pending[i] = []
        return i

    def add_to_ghost(self, i: int, frame: VizFrame) -> bool:
        """Add `frame` of ghost `i` (see `add_ghost`) at its time; True if keyed."""
        k = frame_key(frame.t, self.fps, self._ghost_tick[i])
        if k <= self._ghost_last[i]:
            return False
        self._ghost_last[i] = k
        pending = self._pending[i]
        pending.append((k, frame))
        if len(pending) >= _CHUNK:
            self._key_pending(i)
        return True

    def _node(self, owner: int, path: str, full: str) -> _NodeKeys:
        node = self._nodes.get(full)
        if node is None:
            node = self._nodes[full] = _NodeKeys()
        self._full[(owner, path)] = node
        return node

    def _tracks(self) -> list[tuple[str, str, str, np.ndarray, list]]:
        """(full path, property, three.js type, key frames, key values) of every track, in the order first keyed."""
        for owner in list(self._pending):
            self._key_pending(owner)
        out = []
        for full, node in self._nodes.items():
            out.append((full, "visible", "boolean", np.array([k for k, _ in node.visible], dtype=np.int64),
                        [v for _, v in node.visible]))
            for prop, jstype in _PROPS:
                frames, values = node.keys(prop)
                if not len(frames):
                    continue
                if prop == "scale" and np.all(np.abs(values - 1.0) <= _TOL):
                    continue  # unscaled throughout: no track
                out.append((full, prop, jstype, frames, values))
        return out

    def animation(self) -> Animation:
        """The meshcat animation of the frames added so far (as meshcat's Python builds it: keys, not arrays)."""
        anim = Animation(default_framerate=self.fps)
        for full, prop, jstype, frames, values in self._tracks():
            clip = anim.at_frame(self.vis[full], 0).get_clip()
            for k, value in zip(frames.tolist(), values if prop == "visible" else values.tolist(), strict=True):
                clip.set_property(k, prop, jstype, value)
        return anim

    def _animation_command(self, play: bool) -> _AnimationCommand:
        clips: dict[str, list[dict[str, object]]] = {}
        for full, prop, jstype, frames, values in self._tracks():
            if jstype == "boolean":
                entry = {"name": f".{prop}", "type": "boolean",
                         "keys": [{"time": k, "value": v} for k, v in zip(frames.tolist(), values, strict=True)]}
            else:
                entry = {"name": f".{prop}", "type": jstype, "times": _floats(frames),
                         "values": _floats(values.reshape(-1))}
            clips.setdefault(full, []).append(entry)
        return _AnimationCommand(list(clips.items()), self.fps, play)

    def scene_commands(self, *, play: bool = True) -> list[str]:
        """Every meshcat command of the scene and its animation, base64, in the order to apply them."""
        self.window.send(self._animation_command(play))
        return [base64.b64encode(c).decode() for c in self.window.commands()]

    def html(self, title: str = "wbc replay") -> str:
        """The self-contained replay page (the animation is set on the scene first)."""
        script = viewer_script()
        commands = ",\n".join(f'"{c}"' for c in self.scene_commands())
        return (
            "<!DOCTYPE html>\n<html>\n<head><meta charset=\"utf-8\"><title>" + html_lib.escape(title) + "</title>\n"
            "<style>body { margin: 0; } #meshcat-pane { width: 100vw; height: 100vh; overflow: hidden; }</style>\n"
            "</head>\n<body>\n<div id=\"meshcat-pane\"></div>\n<script>\n" + script + "\n</script>\n<script>\n"
            "var viewer = new MeshCat.Viewer(document.getElementById(\"meshcat-pane\"));\n"
            "var wbcCommands = [\n" + commands + "\n];\n" + _APPLY_SCRIPT + _SEEK_SCRIPT
            + "</script>\n</body>\n</html>\n"
        )

    def save(self, path: str | Path, title: str = "wbc replay") -> Path:
        """Write the replay page to `path`.

        Raises:
            ViewerError: the file cannot be written.
        """
        path = Path(path)
        try:
            path.write_text(self.html(title), encoding="utf-8")
        except OSError as exc:
            raise ViewerError(f"{path}: cannot write the recording ({exc.strerror})") from None
        return path
