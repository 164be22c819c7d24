"""Plots of an arena run (matplotlib, Agg backend): push survival, time to fall per band, tracking error.

`write_plots` draws them from the records, the summary (`wbc.arena.report.summarize`) and the push-recovery curve
(`wbc.arena.breakdown.recovery_curve`); the report (`wbc.arena.report.write_report`) writes ``report.md`` around
them. Every error bar and band says what it is, in its axis label or title, and every point carries the number of
trials or pushes behind it. This is the only arena module that imports matplotlib, and only when it draws.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

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

def _stat(summary: Summary, controller: str, band: str, metric: str) -> MetricSummary | None:
    cell = summary.cell(controller, band)
    return None if cell is None or metric not in cell else cell[metric]


def _short(controller: str) -> str:
    """A legend label: a policy file's name without its directories (``policy:a/b/x-ppo`` -> ``x-ppo``)."""
    kind, sep, path = controller.partition(":")
    return Path(path).name if sep and kind in ("policy", "onnx") else controller


def _plot_push_recovery(plt: Any, path: Path, curve: Mapping[str, Any], controllers: Sequence[str]) -> bool:
    """Survival of each push against its impulse, one line per controller with Wilson 95 % error bars."""
    edges = np.asarray(curve.get("edges", ()), dtype=float)
    if edges.size < 2:
        return False
    centers = 0.5 * (edges[:-1] + edges[1:])
    width = float(edges[1] - edges[0])
    n_lines = max(1, len(controllers))
    fig, ax = plt.subplots(figsize=(7.0, 4.8))
    try:
        for i, controller in enumerate(controllers):
            cells = curve["controllers"].get(controller, [])
            if not cells:
                continue
            # a small sideways shift per controller keeps overlapping error bars apart
            x = centers + (i - (n_lines - 1) / 2.0) * 0.08 * width
            rate = np.array([np.nan if c["rate"] is None else 100.0 * c["rate"] for c in cells])
            lo = np.array([np.nan if c["ci95"][0] is None else 100.0 * c["ci95"][0] for c in cells])
            hi = np.array([np.nan if c["ci95"][1] is None else 100.0 * c["ci95"][1] for c in cells])
            line = ax.errorbar(x, rate, yerr=np.vstack([rate - lo, hi - rate]), marker="o", capsize=3,
                               label=_short(controller))
            for xi, yi, cell in zip(x, rate, cells, strict=True):
                if cell["n"] and math.isfinite(yi):
                    # alternate controllers above and below their points, so that equal rates stay legible
                    ax.annotate(f"n={cell['n']}", (xi, yi), textcoords="offset points",
                                xytext=(3, 4 if i % 2 == 0 else -10), fontsize=6, color=line[0].get_color())
        for edge in edges:
            ax.axvline(edge, color="0.9", linewidth=0.8, zorder=0)
        ax.set_xlabel("push impulse |F| T [N s]")
        ax.set_ylabel("pushes survived [%] (bars: Wilson 95 % interval)")
        ax.set_ylim(-5.0, 105.0)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), fontsize=8, ncol=3, frameon=False)
        ax.set_title("Push recovery (all bands; a push is survived when no fall precedes the next)", fontsize=9)
        fig.tight_layout()
        with replacing(path) as f:  # whole or not at all
            fig.savefig(f, format="png", dpi=100)
    finally:
        plt.close(fig)
    return True


def _plot_ttf(plt: Any, path: Path, records: Sequence[TrialRecord], controllers: Sequence[str],
              bands: Sequence[str]) -> None:
    """Per band, the share of each controller's trials still standing against the fraction of the episode played.

    A step curve per controller (an empirical survival curve: a trial leaves it when it falls, trips, is stopped or
    its controller fails), the number of trials in the legend.
    """
    fig, axes = plt.subplots(1, max(1, len(bands)), figsize=(max(5.0, 3.6 * len(bands)), 3.8), squeeze=False,
                             sharey=True)
    try:
        for ax, band in zip(axes[0], bands, strict=False):
            for controller in controllers:
                ttf = np.sort(np.array([r.ttf for r in records if r.controller == controller and r.band == band],
                                       dtype=float))
                ttf = ttf[~np.isnan(ttf)]
                if not ttf.size:
                    continue
                ended = ttf[ttf < 1.0]
                x = np.concatenate(([0.0], ended, [1.0]))
                standing = 100.0 * np.concatenate(([1.0], 1.0 - np.arange(1, ended.size + 1) / ttf.size,
                                                   [1.0 - ended.size / ttf.size]))
                ax.step(x, standing, where="post", label=f"{_short(controller)} (n={ttf.size})")
            ax.set_title(f"band {band}", fontsize=9)
            ax.set_xlabel("fraction of the episode played")
            ax.set_xlim(0.0, 1.0)
            ax.set_ylim(-5.0, 105.0)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7, loc="lower left")
        axes[0][0].set_ylabel("trials still standing [%]")
        fig.suptitle("Time to fall, per band", fontsize=10)
        fig.tight_layout()
        with replacing(path) as f:  # whole or not at all
            fig.savefig(f, format="png", dpi=100)
    finally:
        plt.close(fig)


def _plot_tracking(plt: Any, path: Path, summary: Summary, bands: Sequence[str],
                   labels: Mapping[str, str]) -> None:
    """Grouped bars of the V_lin and V_ang tracking errors over the common window, per band and controller.

    Each bar is the mean over trials, its error bar the 95 % bootstrap interval over trials, and the number of trials
    with a window is written on it.
    """
    controllers = summary.controllers
    metrics = ("vlin_err_common", "vang_err_common")
    x = np.arange(len(bands), dtype=float)
    width = 0.8 / max(1, len(controllers))
    fig, axes = plt.subplots(1, 2, figsize=(max(6.4, 1.5 * len(bands) * 2 + 2.0), 4.2))
    try:
        for ax, metric in zip(axes, metrics, strict=True):
            for i, controller in enumerate(controllers):
                stats = [_stat(summary, controller, b, metric) for b in bands]
                means = np.array([math.nan if st is None or st.mean is None else st.mean for st in stats])
                lo = np.array([math.nan if st is None or st.ci95[0] is None else st.ci95[0] for st in stats])
                hi = np.array([math.nan if st is None or st.ci95[1] is None else st.ci95[1] for st in stats])
                offset = (i - (len(controllers) - 1) / 2.0) * width
                yerr = np.nan_to_num(np.vstack([means - lo, hi - means]))
                bars = ax.bar(x + offset, np.nan_to_num(means), width, label=_short(controller))
                # drawn apart from the bars: bar(yerr=) of one band warns in NumPy 1.25+
                ax.errorbar(x + offset, np.nan_to_num(means), yerr=np.clip(yerr, 0.0, None), fmt="none", capsize=3,
                            ecolor="black")
                for bar, band, st in zip(bars, bands, stats, strict=True):
                    cell = summary.cell(controller, band)
                    n = 0 if cell is None else st.trials if st is not None and st.trials is not None else cell.trials
                    ax.annotate(f"n={n}", (bar.get_x() + bar.get_width() / 2.0, 0.0), textcoords="offset points",
                                xytext=(0, 2), ha="center", fontsize=6)
            ax.set_xticks(x, list(bands))
            ax.set_xlabel("band")
            ax.set_ylabel(labels[metric] + " (bars: 95 % interval over trials)", fontsize=8)
            ax.set_title(labels[metric].split(" [")[0], fontsize=9)
            ax.grid(True, axis="y", alpha=0.3)
        axes[0].legend(fontsize=7)
        fig.suptitle("Tracking error over the seconds every controller survived", fontsize=10)
        fig.tight_layout()
        with replacing(path) as f:  # whole or not at all
            fig.savefig(f, format="png", dpi=100)
    finally:
        plt.close(fig)


def write_plots(out_dir: Path, summary: Summary, records: Sequence[TrialRecord], *,
                controllers: Sequence[str], bands: Sequence[str], labels: Mapping[str, str],
                curve: Mapping[str, Any] | None = None) -> list[Path]:
    """Draw the plots of `PLOTS` into `out_dir` (which must exist); figures are closed after saving.

    - ``push_recovery.png``: survival of each push against its impulse, binned, one line per controller with Wilson
      95 % error bars and the pushes per point (`curve`, from `wbc.arena.breakdown.recovery_curve`); only written
      when the curve has pushes.
    - ``ttf.png``: per band, the share of trials still standing against the fraction of the episode played.
    - ``tracking.png``: V_lin and V_ang tracking error over the common window per band and controller, the mean over
      trials with its 95 % bootstrap interval and the trials behind it.

    Args:
        out_dir: output folder.
        summary: the output of `wbc.arena.report.summarize` for `records`.
        records: the records of `controllers` and `bands`, in canonical order (`wbc.arena.stats.in_canonical_order`).
        controllers: the controllers, in legend order.
        bands: the bands, in axis order.
        labels: summary metric name -> axis label with its unit (`wbc.arena.report.LABELS`).
        curve: the push-recovery curve (None: not drawn).

    Returns:
        The plots written, in `PLOTS` order.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    plots: list[Path] = []
    if curve is not None and _plot_push_recovery(plt, out / "push_recovery.png", curve, controllers):
        plots.append(out / "push_recovery.png")
    _plot_ttf(plt, out / "ttf.png", records, controllers, bands)
    plots.append(out / "ttf.png")
    _plot_tracking(plt, out / "tracking.png", summary, bands, labels)
    plots.append(out / "tracking.png")
    return plots
