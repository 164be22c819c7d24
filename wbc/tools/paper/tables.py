"""The paper's three tables as protocols: which contenders play which scenario, what is compared, the paper's rows.

- Table I (push recovery, a1-wx200, ``scenarios/push.toml``): the arm actuated, locked and absent, for both
  families: the learned policies (pi3, pi2, pi1: ``learned``, ``learned-locked``, ``learned-noarm``) and the
  model-based controller (``mpc``, ``mpc-tail``, ``mpc-locked``, ``mpc-noarm``).
- Table II (fast turns, go1-arm, ``scenarios/turn.toml``): the same seven names, which play the go1-arm weights and
  the MPC on the Go1.
- Table III (the staged method against its baselines, ``scenarios/push.toml``): pi3 (``learned``, "Ours") and the
  stage-3 baselines of `wbc.learned.train.stages.BASELINES` whose exported policy ships in
  ``wbc/learned/weights/a1-wx200-actuated-<baseline>.npz``, played as ``policy:PATH``; a baseline without shipped
  weights is listed as missing with the command that trains it, or given with ``--contender NAME=CONTROLLER``.
  Two rows the paper does not have follow: ``mpc-distilled`` (the MPC distilled into a policy of our form by DAgger)
  and its expert ``mpc``, compared with Ours and with each other.

The learned rows play the shipped stages, trained to hold the robot's nominal trunk height. With ``--crouched``
every learned row plays its posture variant instead (the same stage as first trained, without the posture term:
``learned-crouched`` ..., ``a1-wx200-actuated-<baseline>-crouched.npz``; `wbc.learned.policy.shipped.POSTURES`),
under the same keys, so the comparisons are the same pairs.

Every contender has a key (the controller name it plays by default, or the baseline's name); ``--contender
KEY=CONTROLLER`` plays another controller in its row (a policy retrained on another scenario version, say). The
comparisons each table prints are pairs of keys, B - A on the same trials.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from wbc.errors import ConfigError, UnknownNameError
from wbc.learned.policy.shipped import WEIGHTS_DIR
from wbc.learned.train.stages import BASELINES
from wbc.scenario import Scenario
from wbc.tools.paper.paper_numbers import (
    PROTOCOL_I,
    PROTOCOL_II,
    PROTOCOL_III,
    TABLE_I,
    TABLE_II,
    TABLE_III,
    PaperProtocol,
    PaperValue,
)

__all__ = ["PAIRED_TRACKING", "Contender", "Contrast", "PaperTableSpec", "TABLES", "paper_column", "resolve_contenders"]

PAIRED_TRACKING: Mapping[str, str] = {"vlin_err": "vlin_err_common", "vang_err": "vang_err_common"}
"""A table's tracking metric -> the one its paired comparisons test: over the seconds both controllers survived."""


@dataclass(frozen=True, kw_only=True)
class Contender:
    """One row of ours.

    Attributes:
        key: the name ``--contender`` refers to it by.
        row: the paper's row it stands beside (``Actuated``, ``Ours``, ``PPO`` ...).
        family: ``learned`` or ``model-based``.
        controller: the arena controller name it plays; None when it is missing.
        note: what it is (``pi3``), or why it is missing and how to get it.
        arm_mode: the arm mode its row stands for (``actuated``, ``locked``, ``none``): a controller given for it by
            ``--contender`` must play with that one.
    """

    key: str
    row: str
    family: str
    controller: str | None
    note: str
    arm_mode: str = "actuated"


@dataclass(frozen=True, kw_only=True)
class Contrast:
    """A paired comparison a table prints: B - A on the same trials.

    Attributes:
        a: the key of A.
        b: the key of B.
        question: what it answers, in words (``actuated vs locked arm, learned``).
    """

    a: str
    b: str
    question: str


@dataclass(frozen=True, kw_only=True)
class PaperTableSpec:
    """A paper table as a protocol.

    Attributes:
        name: ``table1``, ``table2`` or ``table3``.
        title: what the table shows.
        scenario: the default scenario file.
        robot: the robot the table's contenders drive.
        metrics: the summary metrics of its columns, in order (`wbc.arena.report.METRICS` names).
        paper_columns: the paper's column labels.
        paper_bands: what each of the paper's columns commands, as a scenario band's settings
            (`wbc.scenario.Scenario.band_settings`): ``{"vx": 1.25}``, ``{"push_force_n": (200.0, 300.0)}``. A band
            of the scenario played stands in a column when its settings are exactly those (`paper_column`).
        paper: paper row -> metric -> a `PaperValue` per column.
        contenders: our rows, in the order they are played (printed grouped by the paper's rows).
        crouched_contenders: the same rows with the learned ones' crouched posture variants (``--crouched``: as first
            trained, without the posture term).
        contrasts: the paired comparisons printed under the table, on `paired_metrics`.
        paper_protocol: how the paper evaluated it (seeds, trials, episode length): the n behind `paper`.
        protocol_scenario: the name of our scenario whose published versions play the paper's task (``push``,
            ``turn``); the paper's figures stand beside no band of another scenario (`paper_columns_of`).
    """

    name: str
    title: str
    scenario: str
    robot: str
    metrics: tuple[str, ...]
    paper_columns: tuple[str, ...]
    paper_bands: tuple[Mapping[str, Any], ...]
    paper: Mapping[str, Mapping[str, tuple[PaperValue, ...]]]
    contenders: tuple[Contender, ...]
    crouched_contenders: tuple[Contender, ...]
    contrasts: tuple[Contrast, ...]
    paper_protocol: PaperProtocol
    protocol_scenario: str

    @property
    def paired_metrics(self) -> tuple[str, ...]:
        """The metrics the paired comparisons test: `metrics` with each tracking error over the common window.

        A cell's tracking error is over each trial's own survived time, as the paper reports it; two controllers'
        own times on a trial differ, so the paired test compares them over the seconds both survived
        (`PAIRED_TRACKING`), as the arena does.
        """
        return tuple(PAIRED_TRACKING.get(m, m) for m in self.metrics)


def _arm_rows(crouched: bool = False) -> tuple[Contender, ...]:
    # played in this order (the arena's, and its report's); the printed table groups them by the paper's rows
    suffix, note = ("-crouched", " crouched") if crouched else ("", "")
    return (
        Contender(key="learned", row="Actuated", family="learned", controller="learned" + suffix, note="pi3" + note),
        Contender(key="learned-locked", row="Locked", family="learned", controller="learned-locked" + suffix,
                  note="pi2" + note, arm_mode="locked"),
        Contender(key="learned-noarm", row="No arm", family="learned", controller="learned-noarm" + suffix,
                  note="pi1" + note, arm_mode="none"),
        Contender(key="mpc", row="Actuated", family="model-based", controller="mpc", note="MPC"),
        Contender(key="mpc-tail", row="Actuated", family="model-based", controller="mpc-tail",
                  note="MPC, arm as a tail"),
        Contender(key="mpc-locked", row="Locked", family="model-based", controller="mpc-locked", note="MPC",
                  arm_mode="locked"),
        Contender(key="mpc-noarm", row="No arm", family="model-based", controller="mpc-noarm", note="MPC",
                  arm_mode="none"),
    )


_ARM_CONTRASTS = (
    Contrast(a="learned-locked", b="learned", question="actuated vs locked arm, learned (pi3 - pi2)"),
    Contrast(a="learned-noarm", b="learned", question="actuated arm vs no arm, learned (pi3 - pi1)"),
    Contrast(a="mpc-locked", b="mpc", question="actuated vs locked arm, model-based"),
    Contrast(a="mpc-noarm", b="mpc", question="actuated arm vs no arm, model-based"),
    Contrast(a="mpc-locked", b="mpc-tail", question="arm as a tail vs locked arm, model-based"),
    Contrast(a="mpc", b="learned", question="learned vs model-based, arm actuated"),
)

_BASELINE_ROWS = {"ppo": "PPO", "curriculum": "PPO cur", "finetune-pi2": "Fine-tuned pi2", "decoupled": "Decoupled",
                  "one-stage-demo": "One stage demonstration"}
"""`BASELINES` name -> its row in the paper's Table III."""


def _policy_name(path: Path) -> str:
    """``policy:PATH``, PATH relative to the working directory when inside it (shorter in tables and run.json)."""
    rel = os.path.relpath(path)
    return f"policy:{path if rel.startswith('..') else rel}"


def _baseline_rows(crouched: bool = False) -> tuple[Contender, ...]:
    suffix = "-crouched" if crouched else ""
    rows = [Contender(key="ours", row="Ours", family="learned", controller="learned" + suffix,
                      note="pi3 (staged: PPO + BC)" + (" crouched" if crouched else ""))]
    for baseline, row in _BASELINE_ROWS.items():
        weights = WEIGHTS_DIR / f"a1-wx200-actuated-{baseline}{suffix}.npz"
        if weights.is_file():
            rows.append(Contender(key=baseline, row=row, family="learned", controller=_policy_name(
                weights.with_suffix("")), note=BASELINES[baseline]))
        else:
            rows.append(Contender(key=baseline, row=row, family="learned", controller=None,
                                  note=f"no shipped weights (train: wbc train --task push --stage 3 --baseline "
                                  f"{baseline}; play: --contender {baseline}=policy:PATH; they would ship as "
                                  f"{weights.name})"))
    # beside the paper's baselines: the MPC distilled into a policy of the same form, and its expert
    distilled = WEIGHTS_DIR / "a1-wx200-actuated-mpc-distilled.npz"
    rows.append(Contender(key="mpc-distilled", row="MPC distilled (not in the paper)", family="learned",
                          controller="mpc-distilled" if distilled.is_file() else None,
                          note="DAgger student of mpc" if distilled.is_file() else
                          f"no shipped weights (train: wbc train --task push --teacher mpc; play: --contender "
                          f"mpc-distilled=policy:PATH; they would ship as {distilled.name})"))
    rows.append(Contender(key="mpc", row="MPC (not in the paper)", family="model-based", controller="mpc",
                          note="MPC, the distilled policy's expert"))
    return tuple(rows)


_PUSH_BANDS: tuple[Mapping[str, Any], ...] = ({"push_force_n": (200.0, 300.0)}, {"push_force_n": (300.0, 400.0)})
"""The push tables' columns: the paper's push forces in and out of distribution [N]."""


def paper_columns_of(spec: PaperTableSpec, scenario: Scenario, *, published: bool) -> tuple[tuple[int | None, ...],
                                                                                               str | None]:
    """The paper's column each band of `scenario` stands in (`paper_column`), and why none does, or None.

    The paper's figures stand beside a band only of a published version of the table's own scenario
    (`PaperTableSpec.protocol_scenario`), whose trials play the paper's task: a band of another scenario may set the
    same speed or forces and still play another task (right turns, straight runs, longer pushes, slippery ground),
    and an edited copy of the table's scenario plays whatever it was edited to.

    Returns:
        One column index or None per band, in the scenario's order; and, when no band stands in a column for that
        reason, a sentence saying why (None otherwise).
    """
    none = (None,) * len(scenario.bands)
    if scenario.name != spec.protocol_scenario:
        return none, (f"no paper figures beside our bands: the paper's task is that of scenario "
                      f"{spec.protocol_scenario!r} (its published versions), and {scenario.name!r} plays another")
    if not published:
        return none, (f"no paper figures beside our bands: this copy of scenario {scenario.name!r} is not published, "
                      "so its trials need not play the paper's task")
    return tuple(paper_column(spec, scenario.band_settings(band)) for band in scenario.bands), None


def paper_column(spec: PaperTableSpec, settings: Mapping[str, Any]) -> int | None:
    """The paper's column (an index into `spec.paper_columns`) that a band of these settings stands in, or None.

    A band stands in a column when it sets exactly what the column commands (``vx = 1.25`` for Table II's "1.25",
    ``push_force_n = [200, 300]`` for Table I's "200-300") and nothing else; any other band (a speed or a force the
    paper did not play, a band that also fixes the yaw rate) has no paper figure beside it. This reads the band
    alone: `paper_columns_of` also requires the scenario to play the paper's task.

    Args:
        spec: the table.
        settings: the band's settings (`wbc.scenario.Scenario.band_settings`).
    """
    given = {key: tuple(value) if isinstance(value, list | tuple) else value for key, value in settings.items()}
    return next((i for i, column in enumerate(spec.paper_bands) if given == dict(column)), None)


TABLES: dict[str, PaperTableSpec] = {
    "table1": PaperTableSpec(
        name="table1", title="Table I: locomotion under pushes, arm actuated / locked / absent",
        scenario="scenarios/push.toml", robot="a1-wx200", metrics=("success_rate", "ttf", "vlin_err"),
        paper_columns=("200-300", "300-400"), paper_bands=_PUSH_BANDS, paper=TABLE_I, contenders=_arm_rows(),
        crouched_contenders=_arm_rows(crouched=True),
        contrasts=_ARM_CONTRASTS,
        paper_protocol=PROTOCOL_I, protocol_scenario="push"),
    "table2": PaperTableSpec(
        name="table2", title="Table II: high-speed turns, arm actuated / locked / absent",
        scenario="scenarios/turn.toml", robot="go1-arm", metrics=("success_rate", "vang_err", "vlin_err"),
        paper_columns=("1", "1.25", "1.5"), paper_bands=({"vx": 1.0}, {"vx": 1.25}, {"vx": 1.5}),
        paper=TABLE_II, contenders=_arm_rows(),
        crouched_contenders=_arm_rows(crouched=True),
        contrasts=_ARM_CONTRASTS,
        paper_protocol=PROTOCOL_II, protocol_scenario="turn"),
    "table3": PaperTableSpec(
        name="table3", title="Table III: the staged method against its baselines, under pushes",
        scenario="scenarios/push.toml", robot="a1-wx200", metrics=("success_rate", "ttf", "vlin_err"),
        paper_columns=("200-300", "300-400"), paper_bands=_PUSH_BANDS, paper=TABLE_III, contenders=_baseline_rows(),
        crouched_contenders=_baseline_rows(crouched=True),
        contrasts=(*(Contrast(a=key, b="ours", question=f"Ours vs {row}") for key, row in _BASELINE_ROWS.items()),
                   Contrast(a="mpc-distilled", b="ours", question="Ours vs MPC distilled"),
                   Contrast(a="mpc", b="mpc-distilled", question="MPC distilled vs its expert, mpc")),
        paper_protocol=PROTOCOL_III, protocol_scenario="push"),
}
"""The three tables, by the name ``wbc paper`` takes."""


def resolve_contenders(spec: PaperTableSpec, overrides: Mapping[str, str], *,
                       crouched: bool = False) -> tuple[Contender, ...]:
    """The table's contenders (their crouched posture variants with `crouched`) with ``--contender KEY=CONTROLLER``.

    Raises:
        UnknownNameError: a key that is not one of the table's (the message lists them).
        ConfigError: two rows would play the same controller.
    """
    contenders = spec.crouched_contenders if crouched else spec.contenders
    keys = [c.key for c in contenders]
    for key in overrides:
        if key not in keys:
            raise UnknownNameError(f"{spec.name} contender", key, keys)
    rows = tuple(replace(c, controller=overrides[c.key], note=f"given by --contender {c.key}=...")
                 if c.key in overrides else c for c in contenders)
    played = [c.controller for c in rows if c.controller is not None]
    if len(set(played)) != len(played):
        raise ConfigError(f"{spec.name}: two rows play the same controller ({', '.join(played)}); give each row its "
                          "own")
    return rows
