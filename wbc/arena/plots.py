"""Plots of an arena run (matplotlib, Agg backend): push survival, time to fall per band, tracking error.

`write_plots` draws them from the records, the summary (`wbc.arena.report.summarize`) and the push-recovery curve
(`wbc.arena.breakdown.recovery_curve`); the report (`wbc.arena.report.write_report`) writes ``report.md`` around
them. Every error bar and band says what it is, in its axis label or title, and every point carries the number of
trials or pushes behind it. Every plot's title names what was played (scenario and version, bands, seeds, trials),
and each controller keeps one `wbc.arena.plot_style.ControllerStyle` in all of them: a colour-blind-safe colour and a
marker, line style and hatch that tell it apart without colour. Legends sit outside the axes, where they hide no
data. This is the only arena module that imports matplotlib, and only when it draws.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wbc.arena.plot_style import ControllerStyle, controller_styles
from wbc.arena.summary import MetricSummary, Summary
from wbc.arena.trial_record import TrialRecord
from wbc.output_files import replacing

__all__ = ["PLOTS", "write_plots"]

PLOTS = (
    ("push_recovery.png", "Push survival against push impulse: share of pushes survived per impulse bin, with its "
     "Wilson 95 % interval and the pushes (n) behind it"),
    ("ttf.png", "Time to fall per band: share of trials still standing against time, with the trials (n) per "
     "controller"),
    ("tracking.png", "Velocity tracking error over the common window (the seconds every controller survived): mean "
     "over trials with its 95 % bootstrap interval"),
)
"""File name and caption of every plot, in report order."""

_TTF_MARKS = 4
"""Markers per time-to-fall curve, staggered between controllers so that coinciding curves each show theirs."""


def _stat(summary: Summary, controller: str, band: str, metric: str) -> MetricSummary | None:
    cell = summary.cell(controller, band)
    return None if cell is None or metric not in cell else cell[metric]


def _short(controller: str) -> str:
    """A legend label: a policy file's name without its directories (``policy:a/b/x-ppo`` -> ``x-ppo``)."""
    kind, sep, path = controller.partition(":")
    return Path(path).name if sep and kind in ("policy", "onnx") else controller


def _ranges(values: Sequence[int]) -> str:
    """Sorted integers as runs: ``0-4, 7, 9-10``."""
    runs: list[list[int]] = []
    for v in sorted(set(values)):
        if runs and v == runs[-1][1] + 1:
            runs[-1][1] = v
        else:
            runs.append([v, v])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


def _played(scenario: str, records: Sequence[TrialRecord], bands: Sequence[str]) -> str:
    """What the plots show: the scenario, bands, seeds and trials, as counted from the records drawn."""
    seeds = sorted({r.seed for r in records})
    per_seed = {(r.band, r.seed): set() for r in records}
    for r in records:
        per_seed[(r.band, r.seed)].add(r.trial)
    counts = {len(trials) for trials in per_seed.values()}
    if len(counts) == 1:
        n = counts.pop()
        trials = f"{n} trial{'s' if n != 1 else ''} per band and seed"
    else:
        per_band = {b: len({(r.seed, r.trial) for r in records if r.band == b}) for b in bands}
        trials = "trials per band: " + ", ".join(f"{b} {n}" for b, n in per_band.items())
    return (f"scenario {scenario}; band{'s' if len(bands) != 1 else ''} {', '.join(bands)}; "
            f"seed{'s' if len(seeds) != 1 else ''} {_ranges(seeds) if seeds else 'none'}; {trials}")


def _title(fig: Any, what: str, played: str, width_in: float) -> None:
    """The figure's title: what it plots, then what was played (wrapped to the figure's width)."""
    fig.suptitle(what + "\n" + textwrap.fill(played, width=max(40, int(width_in * 15))), fontsize=9)


def _save(fig: Any, path: Path) -> None:
    with replacing(path) as f:  # whole or not at all
        fig.savefig(f, format="png", dpi=100)


def _plot_push_recovery(plt: Any, path: Path, curve: Mapping[str, Any], controllers: Sequence[str],
                        styles: Mapping[str, ControllerStyle], played: str) -> bool:
    """Survival of each push against its impulse, one line per controller with Wilson 95 % error bars.

    The pushes behind each point are a table under the axes, one row per controller and one column per bin, so
    that no two counts are drawn over each other.
    """
    edges = np.asarray(curve.get("edges", ()), dtype=float)
    if edges.size < 2:
        return False
    centers = 0.5 * (edges[:-1] + edges[1:])
    width = float(edges[1] - edges[0])
    n_lines = max(1, len(controllers))
    fig_w = 8.0
    fig, (ax, table) = plt.subplots(2, 1, figsize=(fig_w, 5.0 + 0.2 * n_lines), sharex=True, layout="constrained",
                                    gridspec_kw={"height_ratios": [4.0, 0.35 + 0.22 * n_lines]})
    try:
        for i, controller in enumerate(controllers):
            row = n_lines - 1 - i
            cells = curve["controllers"].get(controller, [])
            style = styles[controller]
            if not cells:
                continue
            # a small sideways shift per controller keeps overlapping error bars apart
            x = centers + (i - (n_lines - 1) / 2.0) * 0.08 * width
            rate = np.array([np.nan if c["rate"] is None else 100.0 * c["rate"] for c in cells])
            lo = np.array([np.nan if c["ci95"][0] is None else 100.0 * c["ci95"][0] for c in cells])
            hi = np.array([np.nan if c["ci95"][1] is None else 100.0 * c["ci95"][1] for c in cells])
            ax.errorbar(x, rate, yerr=np.vstack([rate - lo, hi - rate]), color=style.color, marker=style.marker,
                        linestyle=style.linestyle, markersize=5, capsize=3, label=_short(controller))
            for xc, cell in zip(centers, cells, strict=True):
                table.text(xc, row, str(cell["n"]), ha="center", va="center", fontsize=7,
                           color=_text_colour(style.color) if cell["n"] else "0.55")
        for edge in edges:
            ax.axvline(edge, color="0.9", linewidth=0.8, zorder=0)
            table.axvline(edge, color="0.9", linewidth=0.8, zorder=0)
        ax.set_ylabel("pushes survived [%] (bars: Wilson 95 % interval)")
        ax.set_ylim(-5.0, 105.0)
        ax.grid(True, axis="y", alpha=0.3)
        ax.tick_params(labelbottom=True)
        ax.set_xlabel("push impulse |F| T [N s]")
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
        table.set_ylim(-0.5, n_lines - 0.5)
        table.set_yticks(range(n_lines), [_short(c) for c in reversed(controllers)], fontsize=7)
        for label, controller in zip(table.get_yticklabels(), reversed(controllers), strict=True):
            label.set_color(_text_colour(styles[controller].color))
        table.tick_params(axis="x", which="both", bottom=False, labelbottom=False)
        table.tick_params(axis="y", length=0)
        for spine in table.spines.values():
            spine.set_visible(False)
        table.set_title("pushes (n) per impulse bin", fontsize=7, loc="left")
        _title(fig, "Push recovery (all bands; a push is survived when no fall precedes the next)", played, fig_w)
        _save(fig, path)
    finally:
        plt.close(fig)
    return True


def _text_colour(colour: str) -> tuple[float, float, float]:
    """`colour` as text on white: a light one darkened until it reads, the others as they are.

    Okabe-Ito's yellow and sky blue are scaled down in linear light to WCAG's relative luminance 0.3 (a contrast of
    3:1 and more against white), their hue kept.
    """
    from matplotlib.colors import to_rgb

    rgb = np.asarray(to_rgb(colour))
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    luminance = float(linear @ np.array([0.2126, 0.7152, 0.0722]))
    if luminance <= 0.3:
        return tuple(float(c) for c in rgb)
    # scale the linear light down to 0.3 and back to sRGB: the hue kept, only darker
    scaled = linear * (0.3 / luminance)
    srgb = np.where(scaled <= 0.0031308, 12.92 * scaled, 1.055 * scaled ** (1 / 2.4) - 0.055)
    return tuple(float(c) for c in srgb)


_TTF_LABEL_WIDTH = 40
"""Characters of a TTF legend entry's line (a band's axes' width at its font): a longer one wraps."""


def _ttf_curve(ttf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The empirical survival curve of the times to fall `ttf` (fractions of the episode; 1: stood to the end)."""
    ended = ttf[ttf < 1.0]
    x = np.concatenate(([0.0], ended, [1.0]))
    standing = 100.0 * np.concatenate(([1.0], 1.0 - np.arange(1, ended.size + 1) / ttf.size,
                                       [1.0 - ended.size / ttf.size]))
    return x, standing


def _plot_ttf(plt: Any, path: Path, records: Sequence[TrialRecord], controllers: Sequence[str],
              bands: Sequence[str], styles: Mapping[str, ControllerStyle], played: str) -> None:
    """Per band, the share of each controller's trials still standing against the fraction of the episode played.

    A step curve per controller (an empirical survival curve: a trial leaves it when it falls, trips, is stopped or
    its controller fails) in its line style, with its markers at a few staggered points, so that curves that
    coincide (all trials standing, say) each stay visible; the legend under each band gives the trials (n) and
    names the controllers whose curves are the same.
    """
    from matplotlib.lines import Line2D

    n = max(1, len(controllers))
    fig_w = max(5.0, 3.6 * len(bands))
    by_band: dict[str, dict[str, tuple[np.ndarray, np.ndarray, int]]] = {}
    labels: dict[str, dict[str, str]] = {}
    for band in bands:
        curves = by_band.setdefault(band, {})
        for controller in controllers:
            ttf = np.sort(np.array([r.ttf for r in records if r.controller == controller and r.band == band],
                                   dtype=float))
            ttf = ttf[~np.isnan(ttf)]
            if ttf.size:
                curves[controller] = (*_ttf_curve(ttf), ttf.size)
        named = labels.setdefault(band, {})
        for controller, (x, standing, size) in curves.items():
            # a curve the same as an earlier controller's names that one (the first of them): the legend stays one
            # short entry per controller however many coincide
            first = next((c for c, (x2, s2, _) in curves.items() if c != controller and np.array_equal(x, x2)
                          and np.array_equal(standing, s2)), None)
            same = f", same curve as {_short(first)}" if first is not None and \
                controllers.index(first) < controllers.index(controller) else ""
            named[controller] = textwrap.fill(f"{_short(controller)} (n={size}){same}", width=_TTF_LABEL_WIDTH,
                                              subsequent_indent="  ")
    legend_lines = max((sum(label.count("\n") + 1 for label in named.values()) for named in labels.values()),
                       default=1)
    fig, axes = plt.subplots(1, max(1, len(bands)), figsize=(fig_w, 4.2 + 0.17 * max(n, legend_lines)),
                             squeeze=False, sharey=True, layout="constrained")
    try:
        for ax, band in zip(axes[0], bands, strict=False):
            curves = by_band[band]
            handles = []
            for controller, (x, standing, _) in curves.items():
                i, style = controllers.index(controller), styles[controller]
                ax.step(x, standing, where="post", color=style.color, linestyle=style.linestyle, linewidth=1.6)
                marks = (np.arange(_TTF_MARKS) + (i + 0.5) / n) / _TTF_MARKS
                ax.plot(marks, standing[np.searchsorted(x, marks, side="right") - 1], linestyle="none",
                        marker=style.marker, color=style.color, markersize=5)
                handles.append(Line2D([], [], color=style.color, linestyle=style.linestyle, marker=style.marker,
                                      markersize=5, linewidth=1.6, label=labels[band][controller]))
            ax.set_title(f"band {band}", fontsize=9)
            ax.set_xlabel("fraction of the episode played")
            ax.set_xlim(0.0, 1.0)
            ax.set_ylim(-5.0, 105.0)
            ax.grid(True, alpha=0.3)
            if handles:
                ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16),
                          frameon=False)
        axes[0][0].set_ylabel("trials still standing [%]")
        _title(fig, "Time to fall, per band", played, fig_w)
        _save(fig, path)
    finally:
        plt.close(fig)


def _missing(summary: Summary, controller: str, band: str, stat: MetricSummary | None) -> str:
    """Why a tracking error has no value: the controller did not play the band, or no trial had a common window."""
    if summary.cell(controller, band) is None:
        return "not played"
    return "no common window" if stat is None or not stat.trials else "no value"


def _edge(style: ControllerStyle) -> str:
    """A bar's edge and hatch colour: dark, but light on a dark bar, whose hatch it would hide."""
    r, g, b = (int(style.color[k:k + 2], 16) for k in (1, 3, 5))
    return "0.85" if 0.299 * r + 0.587 * g + 0.114 * b < 60 else "0.15"


def _plot_tracking(plt: Any, path: Path, summary: Summary, bands: Sequence[str], labels: Mapping[str, str],
                   styles: Mapping[str, ControllerStyle], played: str) -> None:
    """Grouped bars of the V_lin and V_ang tracking errors over the common window, per band and controller.

    Each bar is the mean over trials, its error bar the 95 % bootstrap interval over trials, and the number of trials
    with a window is written above it. A cell without a value (no trial had a common window) draws no bar: "n/a"
    and the reason stand in its place.
    """
    from matplotlib.patches import Patch

    controllers = summary.controllers
    metrics = ("vlin_err_common", "vang_err_common")
    x = np.arange(len(bands), dtype=float)
    width = 0.8 / max(1, len(controllers))
    fig_w = max(6.4, 2.0 * len(bands) * (0.3 * len(controllers) + 0.6) + 1.0)
    fig, axes = plt.subplots(1, 2, figsize=(fig_w, 4.6), layout="constrained")
    try:
        for ax, metric in zip(axes, metrics, strict=True):
            top = 0.0
            for i, controller in enumerate(controllers):
                style = styles[controller]
                offset = (i - (len(controllers) - 1) / 2.0) * width
                for xb, band in zip(x + offset, bands, strict=True):
                    st = _stat(summary, controller, band, metric)
                    if st is None or st.mean is None:
                        ax.annotate(f"n/a: {_missing(summary, controller, band, st)}", (xb, 0.0),
                                    textcoords="offset points", xytext=(0, 3), ha="center", va="bottom",
                                    rotation=90, fontsize=6, color="0.3")
                        continue
                    ax.bar(xb, st.mean, width, color=style.color, hatch=style.hatch, edgecolor=_edge(style),
                           linewidth=0.6)
                    hi = st.mean if st.ci95[1] is None else max(st.mean, st.ci95[1])
                    lo = st.mean if st.ci95[0] is None else min(st.mean, st.ci95[0])
                    ax.errorbar(xb, st.mean, yerr=[[st.mean - lo], [hi - st.mean]], fmt="none", capsize=3,
                                ecolor="black")
                    cell = summary.cell(controller, band)
                    n = st.trials if st.trials is not None else cell.trials if cell is not None else 0
                    ax.annotate(f"n={n}", (xb, hi), textcoords="offset points", xytext=(0, 3), ha="center",
                                va="bottom", rotation=90, fontsize=6)
                    top = max(top, hi)
            ax.set_ylim(0.0, 1.3 * top if top > 0.0 else 1.0)
            ax.set_xticks(x, list(bands))
            ax.set_xlabel("band")
            ax.set_ylabel(labels[metric] + " (bars: 95 % interval over trials)", fontsize=8)
            ax.set_title(labels[metric].split(" [")[0], fontsize=9)
            ax.grid(True, axis="y", alpha=0.3)
        fig.legend(handles=[Patch(facecolor=styles[c].color, hatch=styles[c].hatch, edgecolor=_edge(styles[c]),
                                  label=_short(c)) for c in controllers],
                   loc="outside lower center", ncol=min(4, max(1, len(controllers))), fontsize=7, frameon=False)
        _title(fig, "Tracking error over the seconds every controller survived", played, fig_w)
        _save(fig, path)
    finally:
        plt.close(fig)


def write_plots(out_dir: Path, summary: Summary, records: Sequence[TrialRecord], *,
                controllers: Sequence[str], bands: Sequence[str], labels: Mapping[str, str],
                curve: Mapping[str, Any] | None = None, scenario: str | None = None) -> list[Path]:
    """Draw the plots of `PLOTS` into `out_dir` (which must exist); figures are closed after saving.

    - ``push_recovery.png``: survival of each push against its impulse, binned, one line per controller with Wilson
      95 % error bars, and under it the pushes per point, one row per controller (`curve`, from
      `wbc.arena.breakdown.recovery_curve`); only written when the curve has pushes.
    - ``ttf.png``: per band, the share of trials still standing against the fraction of the episode played.
    - ``tracking.png``: V_lin and V_ang tracking error over the common window per band and controller, the mean over
      trials with its 95 % bootstrap interval and the trials behind it ("n/a" where no trial had a window).

    Each title names the scenario, the bands, the seeds and the trials (counted from `records`); each controller
    keeps its `wbc.arena.plot_style.controller_styles` style, by its position in `controllers`, in every plot.

    Args:
        out_dir: output folder.
        summary: the output of `wbc.arena.report.summarize` for `records`.
        records: the records of `controllers` and `bands`, in canonical order (`wbc.arena.stats.in_canonical_order`).
        controllers: the controllers, in legend order.
        bands: the bands, in axis order.
        labels: summary metric name -> axis label with its unit (`wbc.arena.report.LABELS`).
        curve: the push-recovery curve (None: not drawn).
        scenario: the scenario as the titles name it, with its version (``push v2``); None: the summary's scenario
            name.

    Returns:
        The plots written, in `PLOTS` order.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    styles = controller_styles([*controllers, *(c for c in summary.controllers if c not in controllers)])
    played = _played(scenario or summary.scenario_name, records, bands)
    plots: list[Path] = []
    if curve is not None and _plot_push_recovery(plt, out / "push_recovery.png", curve, controllers, styles, played):
        plots.append(out / "push_recovery.png")
    _plot_ttf(plt, out / "ttf.png", records, controllers, bands, styles, played)
    plots.append(out / "ttf.png")
    _plot_tracking(plt, out / "tracking.png", summary, bands, labels, styles, played)
    plots.append(out / "tracking.png")
    return plots
