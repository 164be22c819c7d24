"""A trial played in the viewer, exported as a scenario that plays it again, pushes from the browser included.

``wbc view CTRL --scenario FILE --trial I --export-scenario OUT.toml``: after the trial, `export_trial` writes OUT.toml
(`wbc.scenario.trial_file`), a scenario whose every trial is the one just played: its terrain, domain and command,
every push it had (the scenario's and those sent from the live page, each exactly the `wbc.scenario.push.Push` the
robot met) and the commands set from the page (as ``[[commands.changes]]``, each from the control tick that first
played it). Any controller then meets exactly those pushes: ``wbc run CTRL --scenario OUT.toml --trials 1``. Pushes
and commands sent from the page that the trial never reached (after a fall) are left out; the scenario's own pushes
all stay, as the trial had them, but for those after its end (a trial cut short with ``--duration``).
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbc.scenario.push import Push
from wbc.scenario.scenario import Scenario
from wbc.scenario.trial import CommandChange, Trial
from wbc.scenario.trial_file import write_trial_scenario

__all__ = ["ExportedScenario", "export_trial", "exported_name"]


@dataclass(frozen=True)
class ExportedScenario:
    """A scenario written from a played trial.

    Attributes:
        path: the file.
        scenario: the scenario as loaded from it (unpublished).
        pushes: every push its trials meet.
        browser_pushes: how many of them were sent from the live page.
        command_changes: the command changes its trials play (those set from the page).
    """

    path: Path
    scenario: Scenario
    pushes: int
    browser_pushes: int
    command_changes: int

    def line(self, controller: str) -> str:
        """What was written and how to play it, for a person."""
        return (f"exported scenario {self.scenario.name!r} (unpublished, hash {self.scenario.hash[:12]}) to "
                f"{self.path}: this trial with its {self.pushes} push(es), {self.browser_pushes} from the page, and "
                f"{self.command_changes} command change(s) from the page; every controller meets them: wbc run "
                f"{controller} --scenario {self.path} --trials 1")


def exported_name(trial: Trial) -> str:
    """The exported scenario's name: the trial's scenario, band, seed and index, and ``live``."""
    raw = f"{trial.scenario}-{trial.band}-s{trial.seed}-t{trial.index}-live".lower()
    name = re.sub(r"[^a-z0-9_-]+", "-", raw).strip("-_")
    return name if name else "live-trial"


def export_trial(path: str | Path, trial: Trial, *, controller: str, played_s: float,
                 browser_pushes: Sequence[Push] = (), browser_commands: Sequence[CommandChange] = ()
                 ) -> ExportedScenario:
    """Write a scenario whose every trial is `trial` as it was played, with the page's pushes and commands.

    Args:
        path: the ``.toml`` file to write.
        trial: the trial as the scenario drew it.
        controller: who played it (named in the file's notes).
        played_s: how long it was played [s] (a fall ends it early); pushes and changes from then on are left out.
        browser_pushes: the pushes sent from the page, as applied.
        browser_commands: the commands set from the page, each from the tick that first played it, in time order;
            from the first on they replace the trial's own later changes (`wbc.viz.live_page.SteeredCommand`).

    Raises:
        ConfigError: the file cannot be written, or the trial holds what a scenario cannot say.
        ScenarioError: a push or command breaks the scenario schema's bounds.
    """
    sent = [p for p in browser_pushes if p.start < played_s]
    own = [p for p in trial.pushes if p.start < trial.duration_s]  # a trial cut short (--duration) ends before some
    pushes = sorted(own + sent, key=lambda p: p.start)
    steered = [c for c in browser_commands if c.at_s < played_s]
    first = browser_commands[0].at_s if browser_commands else math.inf
    kept = [c for c in trial.command.changes if c.at_s < min(first, trial.duration_s)]
    schedule = dataclasses.replace(trial.command, changes=tuple(kept + steered))
    played = dataclasses.replace(trial, pushes=tuple(pushes), command=schedule)

    def push_line(p: Push) -> str:
        f = p.force_in_world
        return (f"  {p.start:.4f} s for {p.duration:g} s: {np.linalg.norm(f):.0f} N ({f[0]:.1f}, {f[1]:.1f}, "
                f"{f[2]:.1f}) at ({', '.join(f'{x:g}' for x in p.offset_in_base)}) in the base")

    notes = [f"Trial {trial.index} of scenario {trial.scenario!r} (hash {trial.scenario_hash}), band {trial.band!r}, "
             f"seed {trial.seed}, {trial.duration_s:g} s, as {controller} played it in the viewer "
             f"({played_s:g} s played). Every drawn value is fixed to the trial's."]
    if sent:
        notes.append("Pushes sent from the page:")
        notes += [push_line(p) for p in sent]
    if steered:
        notes.append("Commands set from the page (vx, vy, yaw rate, held from then on):")
        notes += [f"  from {c.at_s:.4f} s: {c.command.vx:g} m/s, {c.command.vy:g} m/s, {c.command.yaw_rate:g} rad/s"
                  for c in steered]
    description = (f"One trial of {trial.scenario!r} (band {trial.band}, seed {trial.seed}, trial {trial.index}) "
                   f"frozen as played in the viewer, with {len(sent)} push(es) and {len(steered)} "
                   "command change(s) sent from the page; every trial of this file is that trial.")
    header = (f"A scenario that replays one trial exactly, for every controller: written by `wbc view "
              f"--export-scenario` from {trial.scenario!r} band {trial.band} seed {trial.seed} trial {trial.index}.")
    scenario = write_trial_scenario(path, played, name=exported_name(trial), description=description,
                                    notes="\n".join(notes), header=header)
    return ExportedScenario(path=Path(path), scenario=scenario, pushes=len(pushes), browser_pushes=len(sent),
                            command_changes=len(steered))
