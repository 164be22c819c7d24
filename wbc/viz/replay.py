"""Replays of stored episodes: find a trial's episode log in a results directory and turn it into viewer frames.

A results directory written with ``--save-episodes`` holds ``run.json`` (its `wbc.arena.identity.RunIdentity`:
controllers, scenario path and hash, bands, seeds, trials per band and seed) and
``episodes/<controller>/<band>-s<seed>-t<index>.npz``. The episode gives the configuration and command of every
control tick and the pushes it met (as arrays, `PushLog`); the scenario file gives the robot and the ground. A
hardware trial's directory (``wbc hw run``) names its one trial and the robot it was played on, drawn on flat ground.
Every problem names the file and the field at fault.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wbc.arena.episode import Episode
from wbc.arena.identity import HardwareRunIdentity, RunIdentity
from wbc.arena.results import episode_path
from wbc.arena.trial_record import TrialRecord
from wbc.control.registry import get_controller
from wbc.errors import EpisodeFileError, InputFileError, RecordError, WbcError
from wbc.input_files import read_json
from wbc.robots.conventions import quat_to_matrix
from wbc.robots.description import ARM_MODES
from wbc.robots.registry import get_robot
from wbc.scenario.scenario import Scenario, load_scenario
from wbc.scenario.terrain import TerrainConfig
from wbc.scenario.trial import Trial
from wbc.viz.content import SceneContent
from wbc.viz.errors import ViewerError
from wbc.viz.frame import VizFrame

__all__ = ["StoredEpisode", "frames_of", "load_stored_episode"]


def frames_of(episode: Episode) -> Iterator[VizFrame]:
    """One frame per control tick of `episode` but its last, each drawing the trunk and joints of one instant.

    A row of an episode holds the trunk's pose at the end of its tick (after the physics step) but the joints the
    controller read at its start: the joints of the instant row ``k`` ends are those row ``k + 1`` read. Frame ``k``
    pairs them, as the viewer draws a trial it plays (both read after the step), so a replay draws what the trial
    drew played afresh. The joints at the end of the last tick were never read, so the last row has no frame: a replay
    ends one control tick before its episode. The joints are what the controller read: with sensor noise or latency
    in the scenario, its measurement rather than the simulator's truth.

    A push is drawn in the frame of every tick whose control period overlaps it, at its application point on the
    trunk (the last acting push's point when several act together, their forces summed).

    Raises:
        EpisodeError: the episode holds a value no episode can (`Episode.validate`), checked before any frame.
    """
    episode.validate()
    dt = episode.control_dt
    pushes = episode.pushes
    for i in range(len(episode.t) - 1):
        t = float(episode.t[i])
        qpos = np.concatenate([episode.qpos[i][:7], episode.qpos[i + 1][7:]])
        force, point = np.zeros(3), np.zeros(3)
        for j in range(len(pushes)):
            start = pushes.start[j]
            if start < t and t - dt < start + pushes.duration[j]:
                force = force + pushes.force_in_world[j]
                point = qpos[:3] + quat_to_matrix(qpos[3:7]) @ pushes.offset_in_base[j]
        yield VizFrame(t=t, qpos=qpos, command=episode.command[i], push_force_in_world=force,
                       push_point_in_world=point)


@dataclass(frozen=True)
class StoredEpisode:
    """A stored trial, ready to replay.

    Attributes:
        path: the episode file.
        controller: who played it.
        arm_mode: its arm mode, as the run recorded it (``run.json``'s ``controllers``): the controller is not built
            to replay it, so a policy file moved or deleted since, or an I/O file given by ``--io``, does not matter.
        trial: the trial (robot, ground, pushes as sampled).
        episode: the log.
        scenario: the scenario file the trial was drawn from, as loaded: the run's content (its hash is the one
            ``run.json`` records), which a command warns about when it is not the published one
            (`wbc.scenario.warn_if_unpublished`).
        record: the trial's row of ``trials.csv`` (its outcome and error), None where there is none to read.
        arm_faults: a hardware trial's arm faults (``hardware.json``), as (trial time [s], what), where the file
            stores them at trial time (its ``clocks`` names ``arm_faults``; an older file's are on another clock and
            are not drawn).
    """

    path: Path
    controller: str
    arm_mode: str
    trial: Trial
    episode: Episode
    scenario: Scenario
    record: TrialRecord | None = None
    arm_faults: tuple[tuple[float, str], ...] = ()

    def content(self) -> SceneContent:
        """What to draw: the controller's robot (arm mode) on the trial's ground."""
        desc = get_robot(self.trial.robot, self.arm_mode)
        return SceneContent.for_trial(desc, self.trial.terrain, self.trial.terrain_seed)

    def frames(self) -> Iterator[VizFrame]:
        """The frames of the episode."""
        return frames_of(self.episode)


def _pick(run_json: Path, field: str, value: object, valid: list, option: str) -> object:
    if value is None:
        if len(valid) == 1 or field != "controllers":
            return valid[0]
        raise ViewerError(f"{run_json}: field {field}: the run has several ({', '.join(map(str, valid))}); "
                          f"choose one with {option}")
    if value not in valid:
        raise ViewerError(f"{run_json}: field {field}: {value!r} was not played; valid: "
                          f"{', '.join(map(str, valid))}")
    return value


def load_stored_episode(results_dir: str | Path, index: int, *, controller: str | None = None,
                        band: str | None = None, seed: int | None = None) -> StoredEpisode:
    """Find and load trial `index` of a results directory.

    Args:
        results_dir: the directory ``wbc run --save-episodes --out DIR`` wrote.
        index: trial index within (band, seed).
        controller: which controller's episode (default: the only one).
        band: which band (default: the first played).
        seed: which seed (default: the first played).

    Raises:
        ViewerError: missing directory, ``run.json``, scenario or episode file; a value out of range; an unreadable
            or mismatching file. The message names the file and the field.
    """
    root = Path(results_dir)
    run_json = root / "run.json"
    if root.is_file() and root.suffix.lower() == ".npz":
        raise ViewerError(f"{root}: an episode file alone (`wbc view --save-episode`) holds no trial to draw it on; "
                          "--episode takes a results directory (`wbc run --save-episodes --out DIR`). To see a trial "
                          "played live again, write it with --export-scenario FILE.toml and view that scenario")
    if root.is_file():
        raise ViewerError(f"{root}: a file, not a results directory: --episode takes the directory it is in "
                          f"({root.parent}), as `wbc run --save-episodes --out DIR` or `wbc hw run --out DIR` wrote "
                          "it")
    if not root.is_dir():
        raise ViewerError(f"{root}: no such results directory (give the --out of a `wbc run --save-episodes`)")
    if not run_json.exists():
        raise ViewerError(f"{run_json}: missing; {root} is not a results directory")
    try:
        identity = RunIdentity.load(run_json)
    except RecordError as exc:  # names the file and the field
        raise ViewerError(str(exc)) from None
    controllers, bands, seeds = list(identity.controllers), list(identity.bands), list(identity.seeds)
    played = list(identity.trials_played)  # a hardware trial (``wbc hw run``) stores its one trial
    played_on = identity.played_on  # and the robot it was played on
    scenario_path, scenario_hash = identity.scenario_path, identity.scenario_hash
    controller = _pick(run_json, "controllers", controller, controllers, "--controller")
    band = _pick(run_json, "bands", band, bands, "--band")
    seed = _pick(run_json, "seeds", seed, seeds, "--seed")
    if index not in played:
        raise ViewerError(f"{run_json}: field trials: --trial {index} is out of range; the run's trials are "
                          f"{played[0]}..{played[-1]} per band and seed{_so_far(root, controller, band, seed, played)}")
    path = episode_path(root, controller, band, seed, index)
    if not path.exists():
        raise ViewerError(_no_episode(root, path, controller, band, seed, index, hardware=played_on is not None))
    try:
        episode = Episode.load(str(path))  # checked in depth: a malformed episode is refused, never drawn
    except EpisodeFileError as exc:  # names the file and the field
        raise ViewerError(str(exc)) from None
    if not scenario_path.is_file() and (root / scenario_path.name).is_file():
        scenario_path = root / scenario_path.name
    try:
        scenario = load_scenario(scenario_path)
    except WbcError as exc:
        raise ViewerError(f"{run_json}: field scenario.path: {exc} (run from the directory the run started in)"
                          ) from None
    if scenario.hash != scenario_hash:
        raise ViewerError(f"{run_json}: field scenario.hash: {scenario_path} has changed since the run "
                          f"(hash {scenario.hash[:12]} != {scenario_hash[:12]}); restore that version to replay")
    trial = scenario.trial(band, seed, index)
    arm_faults: tuple[tuple[float, str], ...] = ()
    if played_on is not None:  # on a robot: its own ground (unknown, drawn flat) and none of the scenario's pushes
        try:
            get_robot(played_on)
        except WbcError as exc:
            raise ViewerError(f"{run_json}: field robot: {exc}") from None
        trial = dataclasses.replace(trial, robot=played_on, terrain=TerrainConfig(kind="flat"), pushes=())
        episode = _on_trial_clock(root / "hardware.json", episode)
        arm_faults = _arm_faults(root / "hardware.json")
    if episode.duration_s != trial.duration_s:  # a trial played shorter (`wbc hw run --seconds`): the one played
        trial = dataclasses.replace(trial, duration_s=float(episode.duration_s))
    arm_mode = _recorded_arm_mode(run_json, identity, controller)
    nq = get_robot(trial.robot, arm_mode).num_joints + 7
    if episode.qpos.ndim != 2 or episode.qpos.shape[1] != nq:
        raise ViewerError(f"{path}: field qpos: shape {episode.qpos.shape}, expected (ticks, {nq}) for "
                          f"{trial.robot} driven by {controller}; the file belongs to another run: store it again "
                          "with `wbc run --save-episodes`")
    return StoredEpisode(path=path, controller=controller, arm_mode=arm_mode, trial=trial, episode=episode,
                         scenario=scenario, record=_record(root, controller, band, seed, index),
                         arm_faults=arm_faults)


def _on_trial_clock(hardware_json: Path, episode: Episode) -> Episode:
    """The hardware episode with its safety transitions at trial time, as `Episode.safety_events` documents.

    A ``wbc hw run`` that wrote ``hardware.json`` without its ``clocks`` key stored them on the safety layer's clock
    (counted from the connect, the stand-up included): they are moved back by its ``trial_started_s``.
    """
    try:
        info = read_json(hardware_json)
    except (InputFileError, ValueError):
        return episode  # nothing to move them by
    if not isinstance(info, dict) or "clocks" in info:
        return episode
    started = info.get("trial_started_s")
    if not isinstance(started, (int, float)) or isinstance(started, bool):
        return episode
    return dataclasses.replace(episode, safety_events=episode.safety_events.shifted(-float(started)))


def _arm_faults(hardware_json: Path) -> tuple[tuple[float, str], ...]:
    """The arm faults of a ``hardware.json`` that stores them at trial time, as (time [s], what); else none."""
    try:
        info = read_json(hardware_json)
    except (InputFileError, ValueError):
        return ()
    if not isinstance(info, dict) or "arm_faults" not in (info.get("clocks") or {}):
        return ()
    faults = []
    for fault in info.get("arm_faults") or ():
        t = fault.get("time") if isinstance(fault, dict) else None
        if isinstance(t, (int, float)) and not isinstance(t, bool) and math.isfinite(t):
            faults.append((float(t), f"arm fault: {fault.get('kind')} (IDs {fault.get('ids')})"))
    return tuple(faults)


def _record(root: Path, controller: str, band: str, seed: int, index: int) -> TrialRecord | None:
    """The trial's row of ``trials.csv`` (None: no file to trust, or no row)."""
    try:
        records = TrialRecord.read_csv(root / "trials.csv")
    except (WbcError, OSError):
        return None
    return next((r for r in records if (r.controller, r.band, r.seed, r.trial) == (controller, band, seed, index)),
                None)


def _played(root: Path, controller: str, band: str, seed: int) -> list[int] | None:
    """The trials of (controller, band, seed) that ``trials.csv`` records, in order (None: no file to trust)."""
    try:
        records = TrialRecord.read_csv(root / "trials.csv")
    except (WbcError, OSError):
        return None
    return sorted(r.trial for r in records if (r.controller, r.band, r.seed) == (controller, band, seed))


def _so_far(root: Path, controller: str, band: str, seed: int, planned: list[int]) -> str:
    """``; ...--resume...`` when the run has played fewer trials of (controller, band, seed) than it plans."""
    done = _played(root, controller, band, seed)
    if done is None or set(planned) <= set(done):
        return ""
    shown = "none" if not done else f"{len(done)} ({done[0]}..{done[-1]})" if done == list(
        range(done[0], done[-1] + 1)) else f"{len(done)}"
    return (f"; {controller} has played {shown} of them so far in band {band}, seed {seed}: the run was "
            "interrupted, and the `wbc run` or `wbc compare` command that wrote it, with --resume, plays the rest")


def _no_episode(root: Path, path: Path, controller: str, band: str, seed: int, index: int, *,
                hardware: bool = False) -> str:
    """Why `path` is missing, with the remedy: the trial was not played yet, or was played without its episode.

    A hardware trial's directory (`hardware`: ``wbc hw run``) always stores its episode: one without it was damaged
    or cut short, and only playing the trial again on the robot brings it back.
    """
    if hardware:
        return (f"{path}: missing; a `wbc hw run` stores its trial's episode there ({root} is such a results "
                "directory, so its episodes/ was moved, deleted or never finished): play the trial again with "
                f"`wbc hw run ... --out DIR`")
    done = _played(root, controller, band, seed)
    if done is not None and index not in done:
        return (f"{path}: trial {index} of controller {controller}, band {band}, seed {seed} was not played: the run "
                f"was interrupted ({root / 'trials.csv'} records {len(done)} of its trials there); the `wbc run` or "
                "`wbc compare` command that wrote it, with --resume, plays the rest and stores their episodes")
    return (f"{path}: no episode stored for controller {controller}, band {band}, seed {seed}, trial {index}; rerun "
            "`wbc run` with --save-episodes")


def _recorded_arm_mode(run_json: Path, identity: RunIdentity, controller: str) -> str:
    """The arm mode `controller` played the run with, as ``run.json`` records it (``controllers.NAME.arm_mode``).

    A run written before ``run.json`` recorded its controllers (or a hardware run's, which names its robot's arm
    mode) is read as it can be; only a run that records neither builds the controller to ask it.
    """
    try:
        entry = read_json(run_json).get("controllers", {}).get(controller)
    except (InputFileError, ValueError, AttributeError):  # the identity was read from it already: an old layout
        entry = None
    arm_mode = entry.get("arm_mode") if isinstance(entry, dict) else None
    if arm_mode in ARM_MODES:
        return arm_mode
    if isinstance(identity, HardwareRunIdentity):
        return identity.arm_mode
    try:
        return get_controller(controller).arm_mode
    except WbcError as exc:
        raise ViewerError(f"{run_json}: field controllers.{controller}.arm_mode: missing, and {controller} cannot be "
                          f"built here to ask it ({exc})") from None
