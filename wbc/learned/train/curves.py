"""Training curves of one or more runs, read from their TensorBoard logs and drawn with matplotlib.

``python -m wbc.learned.train.curves RUN_DIR [RUN_DIR ...] -o docs/training-push.png`` draws, against environment steps,
the mean episode reward, the fall rate, the velocity-tracking reward, (for BC stages) the BC loss and the value loss,
one line per run, labelled with the run directory's name (and the folders above it that tell apart runs of the same
name from different run roots, `run_labels`).

Given DAgger runs (``wbc train --teacher CONTROLLER``, whose rounds are in ``progress.json``; a PPO run's
``progress.json`` counts iterations instead), it draws per round the
fit's loss, how long the students drove their episodes before the expert took over (or they fell) and the share of
their episodes taken over or fallen (`plot_dagger_curves`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from wbc.errors import ConfigError
from wbc.optional import require

__all__ = ["PANELS", "dagger_rounds", "is_dagger_run", "plot_dagger_curves", "plot_training_curves", "read_scalars",
           "run_labels"]

PANELS = (("Train/mean_reward", "mean episode reward"), ("episode/fall_rate", "fall rate"),
          ("rew/tracking_lin_vel", "velocity tracking reward [1/s]"), ("Loss/bc", "BC loss"),
          ("Loss/value", "value loss"))
"""(TensorBoard tag, axis title) of each panel; a panel no run logs is left out."""


def read_scalars(run_dir: str | Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every scalar of a run: tag -> (iterations, values)."""
    accumulator = require("tensorboard.backend.event_processing.event_accumulator", "train")
    ea = accumulator.EventAccumulator(str(run_dir), size_guidance={accumulator.SCALARS: 0})
    ea.Reload()
    out = {}
    for tag in ea.Tags()["scalars"]:
        events = ea.Scalars(tag)
        out[tag] = (np.array([e.step for e in events]), np.array([e.value for e in events]))
    return out


def plot_training_curves(run_dirs: list[str | Path], out: str | Path) -> Path:
    """Draw the `PANELS` of the runs against environment steps into `out` (a PNG); returns its path.

    Raises:
        ConfigError: no run logs any of the panels' tags.
    """
    # imported here, not at the top: the Agg backend must be chosen before pyplot is first imported
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = []
    for d, label in zip(run_dirs, run_labels(run_dirs), strict=True):
        scalars = read_scalars(d)
        config = json.loads((Path(d) / "config.json").read_text())["train_config"]
        steps_per_it = config["num_steps_per_env"] * config["env"]["num_envs"]
        runs.append((label, scalars, steps_per_it))
    panels = [(tag, title) for tag, title in PANELS if any(tag in s for _, s, _ in runs)]
    if not panels:
        raise ConfigError(f"none of {[t for t, _ in PANELS]} is logged in {[str(d) for d in run_dirs]}; pass run "
                          "directories written by `wbc train` (their TensorBoard event files)")
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.4), squeeze=False)
    for ax, (tag, title) in zip(axes[0], panels, strict=True):
        for k, (name, scalars, steps_per_it) in enumerate(runs):
            if tag in scalars:  # one colour per run in every panel, also where an earlier run logs nothing
                it, value = scalars[tag]
                ax.plot((it + 1) * steps_per_it / 1e6, value, label=name, color=f"C{k % 10}")
        ax.set_title(title)
        ax.set_xlabel("environment steps [M]")
        ax.grid(alpha=0.3)
    return _save(fig, axes, out, plt)


LEGEND_ROW_IN = 0.2
"""Height of one row of the legend under the panels [in] (8-point type)."""


def _save(fig: Any, axes: Any, out: str | Path, plt: Any) -> Path:
    """Put the legend under the panels, write the figure to `out` (a PNG) and close it; returns the path.

    Under them, not in a panel, where it would hide the lines it names; the figure grows by its rows. Every run
    named in any panel is in it once.
    """
    named: dict[str, Any] = {}
    for ax in axes[0]:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            named.setdefault(label, handle)
    columns = max(1, min(len(named), 3))
    rows = -(-len(named) // columns)
    width, height = fig.get_size_inches()
    legend_in = LEGEND_ROW_IN * rows + 0.1
    fig.set_size_inches(width, height + legend_in)
    fig.legend(list(named.values()), list(named), loc="lower center", ncol=columns, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0.0, legend_in / (height + legend_in), 1.0, 1.0))
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def is_dagger_run(run_dir: str | Path) -> bool:
    """Whether `run_dir` holds a DAgger run: its ``progress.json`` lists ``rounds`` (a PPO run's counts iterations)."""
    try:
        progress = json.loads((Path(run_dir) / "progress.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(progress, dict) and "rounds" in progress


def run_labels(run_dirs: list[str | Path]) -> list[str]:
    """One legend label per run: its directory's name, with as many folders above it as tell the runs apart.

    Runs of one task and stage in different run roots share the directory's name (``push-stage1``): each is then
    labelled ``<root>/push-stage1``, going up until the labels differ (or the path ends).
    """
    paths = [Path(d).resolve() for d in run_dirs]
    depth = 1
    while True:
        labels = ["/".join(p.parts[-depth:]) for p in paths]
        if len(set(labels)) == len(labels) or all(depth >= len(p.parts) for p in paths):
            return labels
        depth += 1


def dagger_rounds(run_dir: str | Path) -> dict[str, np.ndarray]:
    """A DAgger run's figures per round, from its ``progress.json``.

    Returns:
        ``round``, ``samples`` (aggregated so far), ``fit_loss`` (the last epoch's), ``driven_s`` (median seconds a
        student drove an episode before the expert took it over or it fell, the whole episode when neither; NaN in a
        round the expert drove alone) and ``stopped`` (the share of the students' episodes taken over or fallen).

    Raises:
        ConfigError: the directory holds no DAgger progress.
    """
    path = Path(run_dir) / "progress.json"
    try:
        rounds = json.loads(path.read_text())["rounds"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ConfigError(f"{path}: not a DAgger run's progress ({exc})") from None
    policy_dt = 0.02
    out: dict[str, list[float]] = {k: [] for k in ("round", "samples", "fit_loss", "driven_s", "stopped")}
    for r in rounds:
        driven, stopped = [], 0
        for ep in r["episodes"]:
            if ep["expert_drives"]:
                continue
            if ep["takeover_s"] is not None:
                driven.append(ep["takeover_s"])
            elif ep["fell"]:
                driven.append(ep["fall_time_s"])
            else:
                driven.append(ep["samples"] * policy_dt)
            stopped += ep["takeover_s"] is not None or ep["fell"]
        out["round"].append(r["round"])
        out["samples"].append(r["samples_total"])
        out["fit_loss"].append(r["fit_loss_last"])
        out["driven_s"].append(float(np.median(driven)) if driven else np.nan)
        out["stopped"].append(stopped / len(driven) if driven else np.nan)
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def plot_dagger_curves(run_dirs: list[str | Path], out: str | Path) -> Path:
    """Draw DAgger runs' figures per round (`dagger_rounds`) into `out` (a PNG); returns its path.

    Raises:
        ConfigError: a directory that holds no DAgger progress.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # every DAgger run of a task has the same directory name (<task>-dagger-<expert>): the run root tells them apart
    runs = [(label, dagger_rounds(d)) for d, label in zip(run_dirs, run_labels(run_dirs), strict=True)]
    panels = (("fit_loss", "fit loss (mean squared error)"),
              ("driven_s", "median seconds a student drove"),
              ("stopped", "students' episodes taken over or fallen"))
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.4), squeeze=False)
    for ax, (key, title) in zip(axes[0], panels, strict=True):
        for k, (name, figures) in enumerate(runs):
            ax.plot(figures["round"], figures[key], marker="o", ms=3, label=name, color=f"C{k % 10}")
        ax.set_title(title)
        ax.set_xlabel("DAgger round")
        ax.grid(alpha=0.3)
    return _save(fig, axes, out, plt)


def main(argv: list[str] | None = None) -> int:
    """Command line: run directories in, one PNG out."""
    p = argparse.ArgumentParser(prog="python -m wbc.learned.train.curves", description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="run directories (runs/train/<task>-stage<k>..., or DAgger runs)")
    p.add_argument("-o", "--out", required=True, help="PNG to write (e.g. docs/training-push.png)")
    args = p.parse_args(argv)
    dagger = [is_dagger_run(d) for d in args.runs]
    if any(dagger) and not all(dagger):
        raise SystemExit("python -m wbc.learned.train.curves: pass DAgger runs or PPO runs, not both")
    print(plot_dagger_curves(args.runs, args.out) if all(dagger) else plot_training_curves(args.runs, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
