"""`Recording`: a trial as a meshcat animation in one self-contained HTML file that opens without a server.

`Recording` is a meshcat window that keeps the scene in memory instead of sending it to a server: the scene is built
on it with the ordinary ``meshcat.Visualizer`` API, frames are added as animation keys, and `html` writes meshcat's
viewer script inline with every scene command (base64, applied in order), so the file needs no network and no
server. The page plays the animation once; meshcat's panel (Animations) has play, pause, the time slider and
``timeScale`` for slow motion. Opening the file with ``#t=3.2`` in the URL pauses it at 3.2 s (``#t=3.2&play``
plays on from there).

Keys are thinned: a track gets a key only where its value changes (and just before, so a held value is not
interpolated), and visibility only where it flips.
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
from wbc.viz.frame import Pose, VizFrame

__all__ = ["GHOST_COLOR", "Recording", "viewer_script"]

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


class _Track:
    """Keys of one property of one node, added only where the value changes."""

    def __init__(self, jstype: str, discrete: bool) -> None:
        self.jstype = jstype
        self.discrete = discrete
        self.keys: list[tuple[int, object]] = []
        self._last: tuple[int, object] | None = None

    def add(self, frame: int, value: object) -> None:
        last = self._last
        if last is None or not _same(last[1], value):
            if last is not None and not self.discrete and self.keys and self.keys[-1][0] != last[0]:
                self.keys.append(last)  # hold the previous value up to here
            self.keys.append((frame, value))
        self._last = (frame, value)

    def hold(self, frame: int) -> None:
        """The value last added holds at `frame` too."""
        self._last = (frame, self._last[1])


def _same(a: object, b: object) -> bool:
    if isinstance(a, list):
        for x, y in zip(a, b, strict=True):
            if abs(x - y) > 1e-5:
                return False
        return True
    return a == b


def _decompose(m: np.ndarray) -> tuple[list[float], list[float], list[float]]:
    """(position, quaternion x y z w, scale) of a transform with positive scale along its axes."""
    rows = m.tolist()
    cols = [[rows[0][j], rows[1][j], rows[2][j]] for j in range(3)]
    scale = [math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) for c in cols]
    r = [[cols[j][i] / scale[j] if scale[j] > 0 else cols[j][i] for j in range(3)] for i in range(3)]
    return [rows[0][3], rows[1][3], rows[2][3]], _quaternion(r), scale


def _quaternion(r: list[list[float]]) -> list[float]:
    """Unit quaternion (x, y, z, w) of the rotation matrix `r` (rows), by the largest of its four forms."""
    trace = r[0][0] + r[1][1] + r[2][2]
    if trace > 0.0:
        s = 0.5 / math.sqrt(trace + 1.0)
        q = [(r[2][1] - r[1][2]) * s, (r[0][2] - r[2][0]) * s, (r[1][0] - r[0][1]) * s, 0.25 / s]
    elif r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = 2.0 * math.sqrt(max(1.0 + r[0][0] - r[1][1] - r[2][2], 1e-12))
        q = [0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s, (r[2][1] - r[1][2]) / s]
    elif r[1][1] > r[2][2]:
        s = 2.0 * math.sqrt(max(1.0 + r[1][1] - r[0][0] - r[2][2], 1e-12))
        q = [(r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s, (r[0][2] - r[2][0]) / s]
    else:
        s = 2.0 * math.sqrt(max(1.0 + r[2][2] - r[0][0] - r[1][1], 1e-12))
        q = [(r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s, (r[1][0] - r[0][1]) / s]
    if q[3] < 0.0:  # one sign for the same rotation: keys compare equal when the pose holds
        q = [-x for x in q]
    n = math.sqrt(sum(x * x for x in q))
    return [x / n for x in q]


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


def _floats(values: list) -> umsgpack.Ext:
    return umsgpack.Ext(_FLOAT32_EXT, np.asarray(values, dtype="<f4").tobytes())


_FLOAT32_EXT = 0x17  # meshcat's msgpack extension code for a Float32Array


class Recording:
    """Record frames of one trial into a self-contained HTML replay.

    Args:
        content: what to draw (its `setup` is run here).
        fps: animation frame rate [1/s]; frames are keyed at their own time, rounded to this rate.

    Attributes:
        vis: the meshcat visualizer that draws into this recording (for extra objects).
    """

    def __init__(self, content: SceneContent, *, fps: float = 50.0) -> None:
        if not fps > 0:
            raise ConfigError(f"the recording's frame rate (--fps) must be > 0, got {fps}")
        self.content = content
        self.fps = fps
        self.window = _SceneWindow()
        self.vis = meshcat.Visualizer(window=self.window)
        content.setup(self.vis)
        self._tracks: dict[tuple[str, str], _Track] = {}
        self._full: dict[str, str] = {}  # scene path -> full path
        self._last_matrix: dict[str, bytes] = {}  # full path -> its last keyed transform
        self._last_frame = -1
        self.frames = 0
        self._ghosts: list[tuple[SceneContent, meshcat.Visualizer]] = []
        self._ghost_last: list[int] = []

    @property
    def last_key(self) -> int:
        """Index of the last keyed frame (-1 before the first); a frame at t is keyed if round(t fps) exceeds it."""
        return self._last_frame

    @property
    def paths(self) -> dict[str, list[str]]:
        """Scene paths of the recorded content, by role (see `SceneContent.paths`)."""
        return self.content.paths

    def add(self, frame: VizFrame) -> bool:
        """Add `frame` as the animation's state at its time; frames closer than 1/fps to the last are skipped.

        Returns:
            True if the frame was keyed.
        """
        k = int(round(frame.t * self.fps))
        if k <= self._last_frame:
            return False
        self._last_frame = k
        self.frames += 1
        for path, pose in self.content.poses(frame).items():
            self._key(k, path, pose)
        return True

    def add_ghost(self, content: SceneContent, *, color: tuple[float, float, float, float] = GHOST_COLOR) -> int:
        """Add a second robot to the scene, drawn translucent (a ghost), under ``ghost<i>/``; its index.

        The ghost's ground, contact arrows, command arrow and plan are not drawn (the first robot's are); its push
        arrow is. Its camera does not move (the first robot's follows the trunk).
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
        return i

    def add_to_ghost(self, i: int, frame: VizFrame) -> bool:
        """Add `frame` of ghost `i` (see `add_ghost`) at its time; True if keyed."""
        content, vis = self._ghosts[i]
        k = int(round(frame.t * self.fps))
        if k <= self._ghost_last[i]:
            return False
        self._ghost_last[i] = k
        for path, pose in content.poses(frame).items():
            if not path.startswith(_GHOST_SKIP):
                self._key(k, vis[path].path.lower(), pose)
        return True

    def _key(self, k: int, path: str, pose: Pose) -> None:
        full = self._full.get(path)
        if full is None:
            full = self._full[path] = path if path.startswith("/") else self.vis[path].path.lower()
        tracks = self._tracks
        vis_track = tracks.get((full, "visible"))
        if vis_track is None:
            vis_track = tracks[(full, "visible")] = _Track("boolean", discrete=True)
        vis_track.add(k, bool(pose.visible))
        if not pose.visible:
            return
        raw = pose.matrix.tobytes()
        if self._last_matrix.get(full) == raw:  # unchanged: the held keys just run on to this frame
            for prop in ("position", "quaternion", "scale"):
                track = tracks[(full, prop)]
                track.hold(k)
            return
        self._last_matrix[full] = raw
        pos, quat, scale = _decompose(pose.matrix)
        for prop, jstype, value in (("position", "vector3", pos), ("quaternion", "quaternion", quat),
                                    ("scale", "vector3", scale)):
            track = tracks.get((full, prop))
            if track is None:
                track = tracks[(full, prop)] = _Track(jstype, discrete=False)
            track.add(k, value)

    def animation(self) -> Animation:
        """The meshcat animation of the frames added so far (as meshcat's Python builds it: keys, not arrays)."""
        anim = Animation(default_framerate=self.fps)
        for (full, prop), track in self._tracks.items():
            if prop == "scale" and all(_same(v, [1.0, 1.0, 1.0]) for _, v in track.keys):
                continue
            frame_vis = anim.at_frame(self.vis[full], 0)
            clip = frame_vis.get_clip()
            for k, value in track.keys:
                clip.set_property(k, prop, track.jstype, value)
        return anim

    def _animation_command(self, play: bool) -> _AnimationCommand:
        clips: dict[str, list[dict[str, object]]] = {}
        for (full, prop), track in self._tracks.items():
            if prop == "scale" and all(_same(v, [1.0, 1.0, 1.0]) for _, v in track.keys):
                continue
            if track.jstype == "boolean":
                entry = {"name": f".{prop}", "type": "boolean",
                         "keys": [{"time": k, "value": v} for k, v in track.keys]}
            else:
                entry = {"name": f".{prop}", "type": track.jstype, "times": _floats([k for k, _ in track.keys]),
                         "values": _floats([x for _, v in track.keys for x in v])}
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
