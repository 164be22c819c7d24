"""The trial page: the 3D scene beside time plots on one timeline, as one self-contained HTML file.

`trial_page` writes a `Recording`'s scene (meshcat's viewer script and every scene command, inline) together with
the runs' `TrialSignals` as ``wbcData`` and the page script (`wbc.viz.page_script`): plots, event marks, play /
pause, slow motion, scrubbing and a camera that follows the trunk or stays put. Nothing is fetched: the file opens
offline. With two runs (an A / B view) the second robot is the recording's ghost and its lines are dashed.
"""

from __future__ import annotations

import html as html_lib
import json
from pathlib import Path

from wbc.viz.errors import ViewerError
from wbc.viz.page_script import PAGE_SCRIPT, PAGE_STYLE
from wbc.viz.recording import Recording, viewer_script
from wbc.viz.signals import PLOTS, Mark, TrialSignals

__all__ = ["DATA_START", "live_page_html", "page_data", "read_page_data", "save_trial_page", "trial_page"]

_APPLY = """
for (var i = 0; i < wbcCommands.length; i++) {
  var raw = atob(wbcCommands[i]), bytes = new Uint8Array(raw.length);
  for (var j = 0; j < raw.length; j++) { bytes[j] = raw.charCodeAt(j); }
  viewer.handle_command_bytearray(bytes);
}
"""

DATA_START = "var wbcData = "
"""What precedes the page's data (JSON, on one line) in the file; a test reads it back with this."""


def page_data(runs: list[TrialSignals], *, title: str, fps: float, duration: float | None = None,
              marks: list[Mark] | None = None, live: bool = False) -> dict[str, object]:
    """The page's ``wbcData``: title, frame rate, duration, plot order, runs and the marks of no single run."""
    if duration is None:
        duration = max((r.t[-1] for r in runs if r.t), default=0.0)
    return {"title": title, "fps": fps, "duration": duration, "order": list(PLOTS), "live": live,
            "autoplay": False, "runs": [r.to_json() for r in runs], "marks": [m.to_json() for m in marks or []]}


def trial_page(recording: Recording, runs: list[TrialSignals], *, title: str, marks: list[Mark] | None = None,
               duration: float | None = None) -> str:
    """The page of `recording` (its ghosts drawn as `runs[1:]`) with the plots of `runs`.

    Args:
        recording: the scene and its animation.
        runs: the signals of each robot in the scene, the first robot's first.
        title: the page's title.
        marks: events of no single run (the first divergence of an A / B view).
        duration: the timeline's length [s] (default: the longest run's).
    """
    data = page_data(runs, title=title, fps=recording.fps, duration=duration, marks=marks)
    return _html(title, data, recording.scene_commands(play=True))


def live_page_html(scene: list[str], *, title: str, duration: float, fps: float, scene_id: int = 0) -> str:
    """The live form of the trial page: the scene (base64 commands, no animation), posed from ``/state``.

    `scene_id` names the trial whose scene it holds (0: none yet); a page whose ``/state`` names another reloads.
    """
    data = page_data([], title=title, fps=fps, duration=duration, live=True) | {"scene": scene_id}
    return _html(title, data, scene)


def _html(title: str, data: dict[str, object], commands: list[str]) -> str:
    return (
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head><meta charset=\"utf-8\"><title>" + html_lib.escape(title)
        + "</title>\n"
        "<style>" + PAGE_STYLE + "</style>\n</head>\n<body>\n"
        "<div id=\"wbc-main\"><div id=\"meshcat-pane\"></div><div id=\"wbc-plots\"></div></div>\n"
        "<div id=\"wbc-bar\"></div>\n"
        "<script>\n" + viewer_script() + "\n</script>\n<script>\n"
        "var viewer = new MeshCat.Viewer(document.getElementById(\"meshcat-pane\"));\n"
        + DATA_START + _json(data) + ";\n"
        "var wbcCommands = [\n" + ",\n".join(f'"{c}"' for c in commands) + "\n];\n" + _APPLY + PAGE_SCRIPT
        + "</script>\n</body>\n</html>\n"
    )


def save_trial_page(path: str | Path, recording: Recording, runs: list[TrialSignals], *, title: str,
                    marks: list[Mark] | None = None, duration: float | None = None) -> Path:
    """Write `trial_page` to `path`.

    Raises:
        ViewerError: the file cannot be written.
    """
    path = Path(path)
    try:
        path.write_text(trial_page(recording, runs, title=title, marks=marks, duration=duration), encoding="utf-8")
    except OSError as exc:
        raise ViewerError(f"{path}: cannot write the recording ({exc.strerror})") from None
    return path


def _json(data: object) -> str:
    """`data` as JSON safe inside a script element (no ``</``)."""
    return json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")


def read_page_data(html: str) -> dict[str, object]:
    """The ``wbcData`` of a trial page (for tests and tools).

    Raises:
        ViewerError: the text is not a trial page.
    """
    start = html.find(DATA_START)
    if start < 0:
        raise ViewerError("not a trial page: no wbcData in it")
    line = html[start + len(DATA_START):].split("\n", 1)[0]
    return json.loads(line.rstrip(";"))
