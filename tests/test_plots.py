"""Tests of `wbc.arena.plots` and `wbc.arena.plot_style`: the arena's plots read without colour, hide no data and say
what was played.

The figures are inspected as drawn (Agg backend): `write_plots` closes each after saving, so the `drawn` fixture
keeps them open for the test and closes them after it.
"""

from __future__ import annotations

import dataclasses
import itertools
import warnings
from pathlib import Path

import numpy as np
import pytest
from test_report import BANDS, HASH, N_TRIALS, SCENARIO, SEEDS, arena_records, make_record, summary_of

from wbc.arena.plots import write_plots
from wbc.arena.report import LABELS, summarize, write_report
from wbc.arena.summary import MetricSummary, Summary

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402

MANY = ("stand", "stand-locked", "stand-noarm", "mpc", "policy:runs/a/ppo-push", "wbc", "learned", "mpc-noarm")
"""Eight controllers: every colour of the palette."""

# Machado, Oliveira & Fernandes (2009), severity 1, on linear RGB
_CVD = {
    "deuteranopia": np.array([[0.367322, 0.860646, -0.227968], [0.280085, 0.672501, 0.047413],
                              [-0.011820, 0.042940, 0.968881]]),
    "protanopia": np.array([[0.152286, 1.052583, -0.204868], [0.114503, 0.786281, 0.099216],
                            [-0.003882, -0.048116, 1.051998]]),
}


def _lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB (D65) of linear sRGB."""
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]) @ np.clip(rgb, 0, 1)
    t = xyz / np.array([0.95047, 1.0, 1.08883])
    f = np.where(t > (6 / 29) ** 3, np.cbrt(t), t / (3 * (6 / 29) ** 2) + 4 / 29)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def _seen_apart(a: str | tuple, b: str | tuple, deficiency: str) -> float:
    """ΔE (CIE76) between two colours as a dichromat sees them."""
    def linear(c):
        c = np.asarray(to_rgb(c))
        return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return float(np.linalg.norm(_lab(_CVD[deficiency] @ linear(a)) - _lab(_CVD[deficiency] @ linear(b))))


@pytest.fixture
def drawn(monkeypatch):
    """Keep the figures `write_plots` draws open: a function of the written paths -> {file name: figure}."""
    close = plt.close
    close("all")
    monkeypatch.setattr(plt, "close", lambda *args, **kwargs: None)

    seen: set[int] = set()

    def figures(paths):
        figs = [plt.figure(n) for n in plt.get_fignums() if n not in seen]
        seen.update(plt.get_fignums())
        assert len(figs) == len(paths)
        for fig in figs:
            fig.canvas.draw()
        return {Path(p).name: fig for p, fig in zip(paths, figs, strict=True)}

    yield figures
    close("all")


def _records(controllers, *, standing=()):
    """3 seeds x 10 trials per controller and band; `standing` controllers never fall, the others fall half the time."""
    rng = np.random.default_rng(7)
    return [make_record(c, b, s, t, success=(ok := c in standing or bool(rng.random() < 0.5)),
                        ttf=1.0 if ok else float(rng.uniform(0.1, 0.9)))
            for c in controllers for b in BANDS for s in SEEDS for t in range(N_TRIALS)]


def _curve(controllers, n_bins=10):
    """A push-recovery curve where every controller survives the same share: points and their counts side by side."""
    edges = np.linspace(10.0, 40.0, n_bins + 1)
    return {"edges": [float(e) for e in edges],
            "controllers": {c: [{"k": 6, "n": 12, "rate": 0.5, "ci95": [0.25, 0.75]} for _ in range(n_bins)]
                            for c in controllers}}


def _with_tracking(summary: Summary, missing=()) -> Summary:
    """`summary` with common-window tracking errors in every cell but the (controller, band) pairs of `missing`."""
    cells = {}
    for i, (controller, per_band) in enumerate(summary.cells.items()):
        cells[controller] = {}
        for band, cell in per_band.items():
            metrics = dict(cell.metrics)
            for metric in ("vlin_err_common", "vang_err_common"):
                v = 0.1 + 0.02 * i
                metrics[metric] = (MetricSummary(None, None, (None, None), 0) if (controller, band) in missing else
                                   MetricSummary(v, 0.01, (v - 0.02, v + 0.02), cell.trials))
            cells[controller][band] = dataclasses.replace(cell, metrics=metrics)
    return dataclasses.replace(summary, cells=cells)


def _draw(drawn, tmp_path, controllers, records, *, summary=None, curve=True, **kwargs):
    summary = summary or summarize(records, scenario_name=SCENARIO, scenario_hash=HASH, controllers=list(controllers),
                                   bands=list(BANDS))
    paths = write_plots(tmp_path, summary, records, controllers=list(controllers), bands=list(BANDS), labels=LABELS,
                        curve=_curve(controllers) if curve else None, **kwargs)
    return drawn(paths)


def _legend_entries(fig):
    """{controller label: its line or bar in the legend} over every legend of `fig` (an error bar: its data line)."""
    containers = {c.get_label(): c.lines[0] for ax in fig.axes for c in ax.containers
                  if isinstance(c, matplotlib.container.ErrorbarContainer)
                  and not (c.get_label() or "_").startswith("_")}
    if containers:
        return containers
    legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend() is not None)]
    return {text.get_text().split(" (")[0]: handle for legend in legends
            for text, handle in zip(legend.get_texts(), legend.legend_handles, strict=True)}


def _texts(fig):
    return [t for t in fig.findobj(matplotlib.text.Text) if t.get_visible() and t.get_text()]


def test_palette_is_told_apart_under_red_green_colour_blindness():
    from wbc.arena.plot_style import controller_styles

    styles = list(controller_styles(MANY).values())
    for deficiency in _CVD:
        closest = min(_seen_apart(a.color, b.color, deficiency) for a, b in itertools.combinations(styles, 2))
        assert closest > 15.0, deficiency  # matplotlib's tab10 default: 7.3 (deuteranopia), 4.6 (protanopia)


def test_each_controller_keeps_one_style_told_apart_without_colour(drawn, tmp_path):
    figs = _draw(drawn, tmp_path, MANY, _records(MANY))
    shorts = [c.rpartition("/")[2] for c in MANY]
    colours = {}
    for name, fig in figs.items():
        entries = _legend_entries(fig)
        assert sorted(entries) == sorted(shorts), name
        for label, handle in entries.items():
            colour = handle.get_facecolor() if name == "tracking.png" else handle.get_color()
            colours.setdefault(label, set()).add(to_rgb(colour))
        for (a, ha), (b, hb) in itertools.combinations(entries.items(), 2):
            if name == "tracking.png":
                assert ha.get_hatch() != hb.get_hatch(), (name, a, b)
            else:
                assert ha.get_marker() != hb.get_marker(), (name, a, b)
                assert ha._unscaled_dash_pattern != hb._unscaled_dash_pattern, (name, a, b)
    # the same controller in the same colour in every plot, and no two controllers in one colour
    assert all(len(c) == 1 for c in colours.values()), colours
    palette = [next(iter(c)) for c in colours.values()]
    assert len(set(palette)) == len(palette)
    for deficiency in _CVD:
        assert min(_seen_apart(a, b, deficiency) for a, b in itertools.combinations(palette, 2)) > 15.0


def test_legends_sit_outside_the_axes(drawn, tmp_path):
    figs = _draw(drawn, tmp_path, MANY[:5], _records(MANY[:5]))
    for name, fig in figs.items():
        renderer = fig.canvas.get_renderer()
        legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend() is not None)]
        assert legends, name
        for legend, ax in itertools.product(legends, fig.axes):
            box, area = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
            assert not box.overlaps(area), (name, ax.get_title())


def test_coinciding_ttf_curves_stay_visible_and_are_named(drawn, tmp_path):
    controllers = ("stand", "stand-locked", "mpc")
    figs = _draw(drawn, tmp_path, controllers, _records(controllers, standing=("stand", "stand-locked")), curve=False)
    fig = figs["ttf.png"]
    labels = [t.get_text() for ax in fig.axes for t in ax.get_legend().get_texts()]
    # the later of two coinciding curves names the first: one short entry per controller however many coincide
    assert labels.count("stand (n=30)") == len(BANDS)
    assert labels.count("stand-locked (n=30), same curve as stand") == len(BANDS)
    assert labels.count("mpc (n=30)") == len(BANDS)
    # the two 100 % curves are drawn at 100 % (no offset), each with markers where the other has none
    for ax in fig.axes:
        marked = {}
        for line in ax.get_lines():
            if line.get_marker() not in ("None", "", None):
                marked.setdefault(to_rgb(line.get_color()), set()).update(
                    (round(float(x), 6), float(y)) for x, y in zip(line.get_xdata(), line.get_ydata(), strict=True))
        full = [points for points in marked.values() if all(y == 100.0 for _, y in points)]
        assert len(full) >= 2 and not set.intersection(*full)


def test_eight_long_named_controllers_that_all_stand_keep_their_ttf_legend_off_the_data(drawn, tmp_path):
    """Eight policy files of long names, every trial standing (a paper table of baselines): each entry names the
    first curve it coincides with, long ones wrap, and the bands' axes keep their size beside the legends."""
    controllers = tuple(f"policy:wbc/learned/weights/a1-wx200-actuated-{name}" for name in (
        "ppo", "curriculum", "finetune-pi2", "decoupled", "one-stage-demo", "mpc-distilled", "pi3", "pi2"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib warns when the layout collapses the axes to make room
        fig = _draw(drawn, tmp_path, controllers, _records(controllers, standing=controllers), curve=False)["ttf.png"]
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        assert labels[0] == "a1-wx200-actuated-ppo (n=30)" and len(labels) == len(controllers)
        assert all(label.endswith("same curve as\n  a1-wx200-actuated-ppo") or
                   label.endswith("same curve as a1-wx200-actuated-ppo") or "\n" in label for label in labels[1:])
        assert all(len(line) <= 42 for label in labels for line in label.split("\n"))
        area = ax.get_window_extent(renderer)
        assert area.height > 150 and area.width > 150
        assert not ax.get_legend().get_window_extent(renderer).overlaps(area)


def test_push_counts_never_overprint(drawn, tmp_path):
    controllers = MANY[:5]
    fig = _draw(drawn, tmp_path, controllers, _records(controllers))["push_recovery.png"]
    renderer = fig.canvas.get_renderer()
    counts = [t for ax in fig.axes for t in ax.texts if "12" in t.get_text()]
    assert len(counts) == len(controllers) * 10  # one count per controller and bin
    boxes = [t.get_window_extent(renderer) for t in counts]
    for (i, a), (j, b) in itertools.combinations(enumerate(boxes), 2):
        assert not a.overlaps(b), (counts[i].get_text(), counts[j].get_text())


def test_titles_name_what_was_played(drawn, tmp_path):
    records = arena_records()
    paths = write_report(tmp_path, summary_of(records), records, {}, curve=_curve(("mpc", "rl", "wbc")))[1:]
    for name, fig in drawn(paths).items():
        text = " ".join(t.get_text() for t in _texts(fig)).replace("\n", " ")
        for part in (f"scenario {SCENARIO}", "bands nominal, push", "seeds 0-2", "10 trials per band and seed"):
            assert part in text, (name, part)
    figs = _draw(drawn, tmp_path, ("mpc", "rl"), [r for r in records if r.controller in ("mpc", "rl")],
                 scenario=f"{SCENARIO} v3")
    for name, fig in figs.items():
        assert f"scenario {SCENARIO} v3;" in fig.get_suptitle().replace("\n", " "), name


def test_tracking_draws_no_bar_for_an_empty_common_window(drawn, tmp_path):
    controllers = ("mpc", "rl", "wbc")
    records = arena_records()
    summary = _with_tracking(summary_of(records), missing={("rl", "push")})
    fig = _draw(drawn, tmp_path, controllers, records, summary=summary, curve=False)["tracking.png"]
    for ax in fig.axes:
        bars = [p for p in ax.patches if isinstance(p, matplotlib.patches.Rectangle)]
        assert len(bars) == len(controllers) * len(BANDS) - 1  # no bar, not even one of height 0, for (rl, push)
        assert all(b.get_height() > 0.0 for b in bars)
        na = [t for t in ax.texts if t.get_text().startswith("n/a")]
        assert [t.get_text() for t in na] == ["n/a: no common window"]
        # where rl's bar in the push band would stand
        bar_width = bars[0].get_width()
        assert na[0].xy[0] == pytest.approx(1.0 + (1 - 1) * bar_width)


def test_the_push_tables_names_and_counts_read_on_white_in_every_controllers_colour(drawn, tmp_path):
    """Okabe-Ito's yellow is a line's colour but no text's: each name and count keeps a contrast of 3:1 or more."""
    def contrast(colour):
        rgb = np.asarray(to_rgb(colour))
        linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
        return 1.05 / (float(linear @ np.array([0.2126, 0.7152, 0.0722])) + 0.05)

    fig = _draw(drawn, tmp_path, MANY, _records(MANY))["push_recovery.png"]
    table = fig.axes[1]
    texts = [*table.get_yticklabels(), *(t for t in table.texts if t.get_text() != "0")]
    assert len(texts) > len(MANY)
    assert min(contrast(t.get_color()) for t in texts) >= 2.99
