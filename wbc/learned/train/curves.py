"""Training curves of one or more runs, read from their TensorBoard logs and drawn with matplotlib.

``python -m wbc.learned.train.curves RUN_DIR [RUN_DIR ...] -o docs/training-push.png`` draws, against environment steps,
the mean episode reward, the fall rate, the velocity-tracking reward, (for BC stages) the BC loss and the value loss,
one line per run, labelled with the run directory's name.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from wbc.errors import ConfigError
from wbc.optional import require

__all__ = ["PANELS", "plot_training_curves", "read_scalars"]

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
    for d in run_dirs:
        scalars = read_scalars(d)
        config = json.loads((Path(d) / "config.json").read_text())["train_config"]
        steps_per_it = config["num_steps_per_env"] * config["env"]["num_envs"]
        runs.append((Path(d).name, scalars, steps_per_it))
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
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    """Command line: run directories in, one PNG out."""
    p = argparse.ArgumentParser(prog="python -m wbc.learned.train.curves", description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="run directories (runs/train/<task>-stage<k>...)")
    p.add_argument("-o", "--out", required=True, help="PNG to write (e.g. docs/training-push.png)")
    args = p.parse_args(argv)
    print(plot_training_curves(args.runs, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
