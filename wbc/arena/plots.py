"""Plots of an arena run (matplotlib, Agg backend): success against push, push recovery, time to fall, tracking error.

`write_plots` draws them from the records and the summary (`wbc.arena.report.summarize`); the report
(`wbc.arena.report.write_report`) writes ``report.md`` around them. This is the only arena module that imports
matplotlib, and only when it draws.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wbc.arena.record import TrialRecord

__all__ = ["PLOTS", "write_plots"]

PLOTS = (
    ("success_vs_push.png", "Success rate against push magnitude"),
    ("push_recovery.png", "Push recovery: survival of each push against its impulse, Wilson 95 % intervals"),
    ("ttf.png", "Time to fall (fraction of the episode survived)"),
    ("tracking.png", "Velocity tracking error"),
)
"""File name and caption of every plot, in report order."""

_N_PUSH_BINS = 8


def _cell_stat(summary: Mapping[str, Any], controller: str, band: str, metric: str, field: str) -> float:
    cell = summary["controllers"][controller]["bands"].get(band)
    value = None if cell is None else cell[metric][field]
    return math.nan if value is None else float(value)


def _plot_success_vs_push(plt: Any, path: Path, records: Sequence[TrialRecord], controllers: Sequence[str]) -> bool:
    """Success rate against push magnitude, one line per controller; False (nothing written) without pushes."""
    pushes = np.array([r.push_force_n for r in records], dtype=float)
    if not np.any(pushes > 0.0):
        return False
    success = np.array([r.success for r in records], dtype=float)
    names = np.array([r.controller for r in records])
    finite = np.isfinite(pushes)
    levels = np.unique(pushes[finite])
    if levels.size <= _N_PUSH_BINS:  # few distinct magnitudes (a push band): one point per magnitude
        centers = levels
        bin_of = np.searchsorted(levels, pushes)
    else:
        edges = np.linspace(0.0, float(levels[-1]), _N_PUSH_BINS + 1)
        centers = 0.5 * (edges[:-1] + edges[1:])
        bin_of = np.clip(np.searchsorted(edges, pushes, side="right") - 1, 0, _N_PUSH_BINS - 1)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    try:
        for controller in controllers:
            mine = (names == controller) & finite & ~np.isnan(success)
            rates = [
                100.0 * float(success[mine & (bin_of == i)].mean()) if np.any(mine & (bin_of == i)) else math.nan
                for i in range(centers.size)
            ]
            ax.plot(centers, rates, marker="o", label=_short(controller))
        ax.set_xlabel("largest push in the trial [N]")
        ax.set_ylabel("success [%]")
        ax.set_ylim(-5.0, 105.0)
        ax.grid(True, alpha=0.3)
        ax.legend()
        ax.set_title("Success rate against push magnitude (all bands)")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)
    return True


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
            ax.errorbar(x, rate, yerr=np.vstack([rate - lo, hi - rate]), marker="o", capsize=3,
                        label=_short(controller))
        for edge in edges:
            ax.axvline(edge, color="0.9", linewidth=0.8, zorder=0)
        ax.set_xlabel("push impulse |F| T [N s]")
        ax.set_ylabel("pushes survived [%]")
        ax.set_ylim(-5.0, 105.0)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), fontsize=8, ncol=3, frameon=False)
        ax.set_title("Push recovery (all bands; a push is survived when no fall precedes the next)", fontsize=9)
        fig.tight_layout()
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)
    return True


def _plot_ttf(plt: Any, path: Path, records: Sequence[TrialRecord], controllers: Sequence[str]) -> None:
    """Box plot of TTF per controller, all bands pooled."""
    names = [r.controller for r in records]
    ttf = [r.ttf for r in records]
    data = []
    for controller in controllers:
        values = np.array([t for n, t in zip(names, ttf, strict=True) if n == controller], dtype=float)
        values = values[~np.isnan(values)]
        data.append(values if values.size else np.array([math.nan]))
    fig, ax = plt.subplots(figsize=(max(4.0, 1.2 * len(controllers) + 2.0), 4.0))
    try:
        ax.boxplot(data, tick_labels=[_short(c) for c in controllers])
        ax.set_ylabel("TTF (fraction of the episode survived)")
        ax.set_ylim(-0.05, 1.05)
        ax.grid(True, axis="y", alpha=0.3)
        ax.set_title("Time to fall, all bands")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)


def _plot_tracking(plt: Any, path: Path, summary: Mapping[str, Any], bands: Sequence[str],
                   labels: Mapping[str, str]) -> None:
    """Grouped bars of V_lin and V_ang tracking error, mean with std across seeds as error bars."""
    controllers = list(summary["controllers"])
    x = np.arange(len(bands), dtype=float)
    width = 0.8 / max(1, len(controllers))
    fig, axes = plt.subplots(1, 2, figsize=(max(6.4, 1.5 * len(bands) * 2 + 2.0), 4.0))
    try:
        for ax, metric in zip(axes, ("vlin_err", "vang_err"), strict=True):
            for i, controller in enumerate(controllers):
                means = [_cell_stat(summary, controller, b, metric, "mean") for b in bands]
                stds = [_cell_stat(summary, controller, b, metric, "std") for b in bands]
                offset = (i - (len(controllers) - 1) / 2.0) * width
                ax.bar(x + offset, np.nan_to_num(means), width, yerr=np.nan_to_num(stds), capsize=3,
                       label=_short(controller))
            ax.set_xticks(x, list(bands))
            ax.set_ylabel(labels[metric])
            ax.set_title(labels[metric].split(" [")[0])
            ax.grid(True, axis="y", alpha=0.3)
        axes[0].legend()
        fig.tight_layout()
        fig.savefig(path, dpi=100)
    finally:
        plt.close(fig)


def write_plots(out_dir: Path, summary: Mapping[str, Any], records: Sequence[TrialRecord], *,
                controllers: Sequence[str], bands: Sequence[str], labels: Mapping[str, str],
                curve: Mapping[str, Any] | None = None) -> list[Path]:
    """Draw the plots of `PLOTS` into `out_dir` (which must exist); figures are closed after saving.

    - ``success_vs_push.png``: success rate against the trial's largest push magnitude (``push_force_n``), binned,
      one line per controller; only written when some record has a push.
    - ``push_recovery.png``: survival of each push against its impulse, binned, one line per controller with Wilson
      95 % error bars (`curve`, from `wbc.arena.breakdown.recovery_curve`); only written when the curve has pushes.
    - ``ttf.png``: box plot of TTF per controller, all bands pooled.
    - ``tracking.png``: V_lin and V_ang tracking error per band and controller, bars of the mean across seeds with
      the std as error bars.

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
    if _plot_success_vs_push(plt, out / "success_vs_push.png", records, controllers):
        plots.append(out / "success_vs_push.png")
    if curve is not None and _plot_push_recovery(plt, out / "push_recovery.png", curve, controllers):
        plots.append(out / "push_recovery.png")
    _plot_ttf(plt, out / "ttf.png", records, controllers)
    plots.append(out / "ttf.png")
    _plot_tracking(plt, out / "tracking.png", summary, bands, labels)
    plots.append(out / "tracking.png")
    return plots
