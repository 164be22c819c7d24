"""The viewer's screenshots in the README and the docs, taken from real runs in headless Chromium.

``python -m wbc.tools.screenshots [--out docs] [--which trial ab live]`` plays each trial, renders its page in headless
Chromium (WebGL in software: SwiftShader) and writes a small PNG (a palette of `COLORS` colours) into ``--out``, a
folder that must exist:

- ``viewer-trial-page.png``: the recorded trial page of ``mpc`` on ``scenarios/push.toml`` band ood seed 0 trial 0
  (4 s of it), opened during its first push (312 N, the red arrow), the plots beside the 3D view;
- ``viewer-ab-page.png``: ``wbc view mpc stand`` on the same trial at 3 s: ``stand`` (the translucent ghost) has
  fallen (at 2.8 s) where ``mpc`` stepped out of the push;
- ``viewer-live-page.png``: the live trial page of ``stand`` on the same trial, paused while a push sent to its
  ``/push`` endpoint acts, with the page's push and command controls.

Every page is served from this machine (a file, or the live page on 127.0.0.1); nothing is fetched. Chromium is
Debian's ``chromium`` (or ``chromium-browser``, ``google-chrome``) on the PATH. Pillow, which matplotlib brings,
writes the palette PNG.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

from PIL import Image

from wbc.errors import WbcError
from wbc.scenario import Trial, load_scenario
from wbc.viz.live_page import LivePage
from wbc.viz.player import PlayerConfig
from wbc.viz.view import ViewConfig, view_ab, view_trial

__all__ = ["COLORS", "SHOTS", "chromium", "out_problem", "screenshot", "shoot"]

COLORS = 128
"""Colours of the written PNGs' palette: a 1200 x 700 page stays near 100 KB."""

SIZE = (1200, 700)
"""Window size of every screenshot [px]."""

SHOTS = ("trial", "ab", "live")
"""What `shoot` can take, in the order it takes them."""

_SCENARIO = "scenarios/push.toml"
_PUSH_AT = 2.37  # [s] 40 ms into band ood trial 0's first push (2.334 s for 0.09 s)


def chromium() -> str | None:
    """The headless browser on the PATH, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def screenshot(url: str, png: Path, *, budget_ms: int = 8000, size: tuple[int, int] = SIZE,
               profile: Path | None = None) -> Path:
    """Render `url` in headless Chromium for `budget_ms` of its virtual time and write it to `png`, palettised.

    Raises:
        WbcError: no Chromium on the PATH, or it wrote no picture.
    """
    browser = chromium()
    if browser is None:
        raise WbcError("no chromium on the PATH (Debian: apt install chromium); it renders the pages")
    png = Path(png)
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "raw.png"
        cmd = [browser, "--headless", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
               "--enable-unsafe-swiftshader", "--hide-scrollbars", f"--window-size={size[0]},{size[1]}",
               f"--user-data-dir={profile or Path(tmp) / 'profile'}", f"--virtual-time-budget={budget_ms}",
               f"--screenshot={raw}", url]
        subprocess.run(cmd, capture_output=True, timeout=180, check=False)
        if not raw.exists():
            raise WbcError(f"chromium wrote no screenshot of {url}")
        with Image.open(raw) as image:
            image.convert("RGB").quantize(colors=COLORS, method=Image.Quantize.MEDIANCUT).save(png, optimize=True)
    return png


def _trial() -> Trial:
    return dataclasses.replace(load_scenario(_SCENARIO).trial("ood", 0, 0), duration_s=4.0)


def _trial_page(out: Path, work: Path) -> Path:
    page = work / "trial.html"
    view_trial(_trial(), "mpc", ViewConfig(live=False, record=page))
    return screenshot(f"{page.resolve().as_uri()}#t={_PUSH_AT}", out / "viewer-trial-page.png")


def _ab_page(out: Path, work: Path) -> Path:
    page = work / "ab.html"
    view_ab(_trial(), ("mpc", "stand"), ViewConfig(live=False), page)
    return screenshot(f"{page.resolve().as_uri()}#t=3", out / "viewer-ab-page.png")


def _post(url: str, body: dict) -> dict:
    req = urllib.request.Request(url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=30) as reply:
        return json.loads(reply.read())


def _state(url: str) -> dict:
    with urllib.request.urlopen(url + "state", timeout=30) as reply:
        return json.loads(reply.read())


def _live_page(out: Path, work: Path) -> Path:
    trial = dataclasses.replace(_trial(), duration_s=3.0)
    with LivePage() as page:
        # a push from the browser's endpoint at 1.2 s: 160 N towards world +y, at the trunk's front
        _post(page.url + "push", {"force_n": 160.0, "heading_deg": 90.0, "duration_s": 0.1,
                                  "point_in_base": [0.15, 0.0, 0.05], "t": 1.2})
        cfg = ViewConfig(live=True, player=PlayerConfig(speed=0.25), keep_open=False)
        thread = threading.Thread(target=view_trial, args=(trial, "stand", cfg, page), daemon=True)
        thread.start()
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and _state(page.url)["t"] < 1.24:
            time.sleep(0.02)
        _post(page.url + "control", {"pause": True})  # held while the push acts and the browser looks
        try:
            return screenshot(page.url, out / "viewer-live-page.png", budget_ms=4000, profile=work / "profile")
        finally:
            _post(page.url + "control", {"pause": False, "speed": 100.0})
            thread.join(timeout=300)


def out_problem(out: str | Path) -> str | None:
    """Why the PNGs cannot go into the folder `out`, or None.

    The folder must exist: it is not created, so that a misspelt ``--out`` (``doc`` for ``docs``) is refused rather
    than filled, as every path the viewer writes must be in an existing directory.
    """
    out = Path(out)
    if out.is_dir():
        return None
    if out.exists():
        return f"{out} is a file, not a folder; give the folder the PNGs go into (default docs)"
    return f"{out}: no such folder; create it first (mkdir -p {out}), or give an existing one (default docs)"


def shoot(out: str | Path, which: tuple[str, ...] = SHOTS) -> list[Path]:
    """Play the trials of `which` (of `SHOTS`), render their pages and write the PNGs into `out`.

    Raises:
        WbcError: `out` is not an existing folder (`out_problem`; checked before anything plays), or a page could not
            be rendered (`screenshot`).
    """
    problem = out_problem(out)
    if problem is not None:
        raise WbcError(problem)
    out = Path(out)
    takers = {"trial": _trial_page, "ab": _ab_page, "live": _live_page}
    written = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in which:
            written.append(takers[name](out, Path(tmp)))
    return written


def main(argv: list[str] | None = None) -> int:
    """``python -m wbc.tools.screenshots``."""
    parser = argparse.ArgumentParser(prog="python -m wbc.tools.screenshots",
                                     description="the viewer's screenshots, from real runs in headless Chromium")
    parser.add_argument("--out", default="docs", help="the existing folder the PNGs go into (default docs/)")
    parser.add_argument("--which", nargs="+", choices=SHOTS, default=list(SHOTS), help="which pages (default all)")
    args = parser.parse_args(argv)
    problem = out_problem(args.out)
    if problem is not None:  # before the trials play and the pages render, not when the first PNG is written
        parser.error(f"--out {problem}")
    for png in shoot(args.out, tuple(args.which)):
        print(f"{png}: {png.stat().st_size / 1000:.0f} KB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
