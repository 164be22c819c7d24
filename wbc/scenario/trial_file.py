"""A trial written out as a scenario file whose every trial is that trial (`write_trial_scenario`).

A scenario draws its trials at random, seeded by its own content hash, so a trial cannot be kept by copying its
scenario's ranges: the copy hashes differently and draws other trials. The file written here fixes every drawn value
instead: each ``[domain]`` interval is one value (``[x, x]`` draws exactly x), ``[terrain] seed`` is the trial's
terrain seed, one command option holds the trial's command (its ``[[commands.changes]]`` too), and each push is a
``[[fixed_pushes]]`` table. Floats are written as Python's shortest round-trip text, which TOML reads back to the
same bits, so trial (band, any seed, any index) of the file equals the trial given, push for push and bit for bit;
`write_trial_scenario` loads what it wrote and checks it.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from wbc.errors import ConfigError, ScenarioError
from wbc.output_files import temporary_name
from wbc.scenario.scenario import Scenario, load_scenario
from wbc.scenario.trial import Trial

__all__ = ["trial_scenario_text", "write_trial_scenario"]


def _num(x: float) -> str:
    """A float as TOML reads it back to the same bits."""
    value = float(x)
    if not math.isfinite(value):
        raise ConfigError(f"a scenario file holds finite numbers only, got {value}")
    return repr(value)


def _vec(v: np.ndarray) -> str:
    return "[" + ", ".join(_num(x) for x in np.asarray(v, dtype=np.float64)) + "]"


def _str(text: str) -> str:
    """A TOML basic string (JSON's escapes are TOML's)."""
    return json.dumps(text)


def trial_scenario_text(trial: Trial, *, name: str, description: str, notes: str = "", header: str = "") -> str:
    """The TOML text of a scenario whose every trial is `trial` (see the module docstring).

    Args:
        trial: the trial, as played (its pushes and command changes included).
        name: the scenario's name (``^[a-z0-9][a-z0-9_-]*$``).
        description: its one-paragraph summary.
        notes: where it comes from.
        header: comment lines put first (each without its ``#``).

    Raises:
        ConfigError: the trial holds what a scenario file cannot say (a payload off the trunk's origin, one motor
            strength per joint).
    """
    d = trial.domain
    if np.any(np.asarray(d.payload_com) != 0.0):
        raise ConfigError("a scenario puts its payload at the trunk's origin; this trial's sits elsewhere "
                          f"({d.payload_com}), so no scenario file replays it")
    if np.ndim(d.motor_strength) != 0:
        raise ConfigError("a scenario has one motor strength for every motor; this trial has one per joint, so no "
                          "scenario file replays it")
    ter, cmd = trial.terrain, trial.command
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    lines += ["", "[scenario]", f"name = {_str(name)}", "version = 1", f"description = {_str(description)}"]
    if notes:
        lines.append(f"notes = {_str(notes)}")
    lines += [f"robot = {_str(trial.robot)}", f"duration_s = {_num(trial.duration_s)}", "",
              "[terrain]", f"kind = {_str(ter.kind)}", f"amplitude_m = {_num(ter.amplitude)}",
              f"base_wavelength_m = {_num(ter.base_cell)}", f"octaves = {int(ter.octaves)}",
              f"half_extent_m = {_num(ter.half_extent)}", f"seed = {int(trial.terrain_seed)}", "",
              "[domain]  # each interval one value: the trial's",
              f"friction = [{_num(d.friction)}, {_num(d.friction)}]",
              f"payload_kg = [{_num(d.payload_mass)}, {_num(d.payload_mass)}]",
              f"motor_strength = [{_num(d.motor_strength)}, {_num(d.motor_strength)}]"]
    for key, value in (("actuation_delay_s", d.actuation_delay), ("sensing_delay_s", d.sensing_delay)):
        if value != 0.0:
            lines.append(f"{key} = [{_num(value)}, {_num(value)}]")
    lines += ["", "[commands]", f"ramp_s = {_num(cmd.ramp_s)}", "", "[[commands.options]]  # the trial's command",
              f"vx = {_num(cmd.vx)}", f"vy = {_num(cmd.vy)}", f"yaw_rate = {_num(cmd.yaw_rate)}"]
    for change in cmd.changes:
        c = change.command
        lines += ["", "[[commands.changes]]", f"at_s = {_num(change.at_s)}", f"vx = {_num(c.vx)}",
                  f"vy = {_num(c.vy)}", f"yaw_rate = {_num(c.yaw_rate)}"]
    for push in trial.pushes:
        lines += ["", f"[[fixed_pushes]]  # {float(np.linalg.norm(push.force_in_world)):.0f} N",
                  f"start_s = {_num(push.start)}", f"duration_s = {_num(push.duration)}",
                  f"force_n = {_vec(push.force_in_world)}", f"offset_m = {_vec(push.offset_in_base)}"]
    lines += ["", "[[bands]]", f"name = {_str(trial.band)}", ""]
    return "\n".join(lines)


def _same_trial(a: Trial, b: Trial) -> bool:
    """Every value the simulation uses, compared exactly."""
    if (a.robot, a.duration_s, a.terrain, a.terrain_seed, a.domain.friction, a.domain.payload_mass,
            a.domain.actuation_delay, a.domain.sensing_delay) != (
            b.robot, b.duration_s, b.terrain, b.terrain_seed, b.domain.friction, b.domain.payload_mass,
            b.domain.actuation_delay, b.domain.sensing_delay):
        return False
    if not np.array_equal(a.domain.motor_strength, b.domain.motor_strength) or a.command != b.command:
        return False
    return len(a.pushes) == len(b.pushes) and all(
        p.start == q.start and p.duration == q.duration and np.array_equal(p.force_in_world, q.force_in_world)
        and np.array_equal(p.offset_in_base, q.offset_in_base) for p, q in zip(a.pushes, b.pushes, strict=True))


def write_trial_scenario(path: str | Path, trial: Trial, *, name: str, description: str, notes: str = "",
                         header: str = "") -> Scenario:
    """Write `trial_scenario_text` to `path`, its content hash in its first comment lines, and check it replays.

    The file is written under a temporary name beside `path` and renamed to `path` once it loads and replays the
    trial: a trial the schema refuses, or a write that fails, leaves `path` as it was.

    Args:
        path: the ``.toml`` file to write.
        trial: the trial, as played.
        name: the scenario's name.
        description: its summary.
        notes: where it comes from.
        header: comment lines put before the hash's.

    Returns:
        The scenario as loaded from the file: unpublished (no lock lists it), its hash the one in the file.

    Raises:
        ConfigError: the trial holds what a scenario file cannot say, or the file cannot be written.
        ScenarioError: the trial breaks the schema (a value out of its range), named with the file and the line;
            nothing is written.
    """
    path = Path(path)
    tmp = temporary_name(path)  # checked under this name, renamed over `path` only once it loads and replays
    body = trial_scenario_text(trial, name=name, description=description, notes=notes)
    try:
        try:
            tmp.write_text(body, encoding="utf-8")
            content_hash = load_scenario(tmp).hash  # comments do not enter it: the header may name it
            lines = [header] if header else []
            lines += ["Unpublished. Content hash (sha256 of the parsed file, what results record; comments and "
                      "layout do not change it):", f"  {content_hash}"]
            tmp.write_text(trial_scenario_text(trial, name=name, description=description, notes=notes,
                                               header="\n".join(lines)), encoding="utf-8")
            written = load_scenario(tmp)
        except ScenarioError as exc:  # named by the file asked for, which is left as it was
            raise ScenarioError(str(path), f"{exc.reason} (the trial's file was not written)", line=exc.line,
                                field=exc.field) from None
        if written.hash != content_hash or not _same_trial(written.trial(trial.band, 0, 0), trial):
            raise ScenarioError(str(path), "the written file does not replay the trial exactly (a bug in "
                                "wbc.scenario.trial_file); please report it with the trial; nothing was written")
        os.replace(tmp, path)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot write the scenario ({exc.strerror})") from None
    finally:
        tmp.unlink(missing_ok=True)
    return load_scenario(path)
