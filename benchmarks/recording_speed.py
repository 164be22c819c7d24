"""What recording a trial to a trial page costs beside the trial's simulation, on this machine.

Run: python benchmarks/recording_speed.py [--controller mpc] [--scenario scenarios/push.toml] [--band in]
                                          [--trial 0] [--repeats 3]
After a short warm-up of both (compiled kernels, the robot's meshes), plays the trial without a viewer, then again
recorded to a trial page as ``wbc view CTRL --record FILE.html`` does, `--repeats` times in this one process, and
prints for each pair the two wall times and their ratio, the recorded run's own split of its time
(`wbc.viz.view.RecordingTime`, what ``wbc view --record`` prints), the page's size and the load average (another
process on the cores moves every figure). A fresh ``wbc view --record`` also pays once what the warm-up took here.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

from wbc.arena.identity import MAX_TRIALS
from wbc.arena.sim_trial import run_trial
from wbc.cli.parser import bounded_int
from wbc.control.registry import get_controller
from wbc.errors import WbcError
from wbc.scenario import load_scenario
from wbc.tools.bench import machine_description
from wbc.viz.view import ViewConfig, view_trial


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--controller", default="mpc")
    parser.add_argument("--scenario", default="scenarios/push.toml")
    parser.add_argument("--band", default="in")
    parser.add_argument("--trial", type=bounded_int(0, MAX_TRIALS - 1), default=0)
    parser.add_argument("--repeats", type=bounded_int(1, 100), default=3)
    args = parser.parse_args()
    try:
        trial = load_scenario(args.scenario).trial(args.band, 0, args.trial)
        get_controller(args.controller)  # an unknown name, said before the warm-up
    except WbcError as exc:
        parser.exit(2, f"recording_speed: error: {exc}\n")
    print(machine_description())
    print(f"{args.controller} on {trial.scenario} band {trial.band} trial {trial.index}, {trial.duration_s:g} s")
    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "trial.html"
        os.chdir(tmp)  # MuJoCo may write its log here
        short = dataclasses.replace(trial, duration_s=min(0.5, trial.duration_s))
        run_trial(short, args.controller)
        view_trial(short, args.controller, ViewConfig(live=False, record=page))
        ratios = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            _, episode = run_trial(trial, args.controller)
            simulated = time.perf_counter() - start
            start = time.perf_counter()
            result = view_trial(trial, args.controller, ViewConfig(live=False, record=page))
            recorded = time.perf_counter() - start
            ratios.append(recorded / simulated)
            print(f"  simulation {simulated:.2f} s ({episode.survived_s:g} s played), recorded {recorded:.2f} s: "
                  f"{ratios[-1]:.2f}x; in the recorded run {result.timing.line()}; page "
                  f"{page.stat().st_size / 1e6:.1f} MB; load average {os.getloadavg()[0]:.2f}")
    ratios.sort()
    print(f"recording / simulation: median {ratios[len(ratios) // 2]:.2f}x over {len(ratios)} pairs")


if __name__ == "__main__":
    main()
