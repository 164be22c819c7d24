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
from pathlib import Path

import meshcat
import numpy as np
import umsgpack
from meshcat.animation import Animation
from meshcat.servers.zmqserver import VIEWER_ROOT
from meshcat.transformations import quaternion_from_matrix

from wbc.errors import ConfigError
from wbc.viz.content import SceneContent
from wbc.viz.errors import ViewerError
from wbc.viz.frame import Pose, VizFrame

__all__ = ["Recording"]

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
        packed = umsgpack.packb(data)
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


def _same(a: object, b: object) -> bool:
    if isinstance(a, list):
        return bool(np.allclose(a, b, atol=1e-5))
    return a == b


def _decompose(m: np.ndarray) -> tuple[list[float], list[float], list[float]]:
    """(position, quaternion x y z w, scale) of a transform with positive scale along its axes."""
    scale = np.linalg.norm(m[:3, :3], axis=0)
    rot = np.eye(4)
    rot[:3, :3] = m[:3, :3] / np.where(scale > 0, scale, 1.0)
    w, x, y, z = quaternion_from_matrix(rot)
    return m[:3, 3].tolist(), [float(x), float(y), float(z), float(w)], scale.tolist()


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
        self._last_frame = -1
        self.frames = 0

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

    def _key(self, k: int, path: str, pose: Pose) -> None:
        full = path if path.startswith("/") else self.vis[path].path.lower()
        vis_track = self._tracks.setdefault((full, "visible"), _Track("boolean", discrete=True))
        vis_track.add(k, bool(pose.visible))
        if not pose.visible:
            return
        pos, quat, scale = _decompose(pose.matrix)
        for prop, jstype, value in (("position", "vector3", pos), ("quaternion", "quaternion", quat),
                                    ("scale", "vector3", scale)):
            self._tracks.setdefault((full, prop), _Track(jstype, discrete=False)).add(k, value)

    def animation(self) -> Animation:
        """The meshcat animation of the frames added so far."""
        anim = Animation(default_framerate=self.fps)
        for (full, prop), track in self._tracks.items():
            if prop == "scale" and all(_same(v, [1.0, 1.0, 1.0]) for _, v in track.keys):
                continue
            frame_vis = anim.at_frame(self.vis[full], 0)
            clip = frame_vis.get_clip()
            for k, value in track.keys:
                clip.set_property(k, prop, track.jstype, value)
        return anim

    def html(self, title: str = "wbc replay") -> str:
        """The self-contained replay page (the animation is set on the scene first)."""
        self.vis.set_animation(self.animation(), play=True, repetitions=1)
        script = (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")
        commands = ",\n".join(f'"{base64.b64encode(c).decode()}"' for c in self.window.commands())
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
