"""DAgger: a policy of our observation and action form distilled from a controller of the arena (``mpc`` by default).

Each round plays episodes of the task's scenario (its training bands, on the training seed stream, apart from
evaluation's) in the arena's own simulation (`wbc.arena.sim_trial.run_trial`). The expert runs at its own rate in
every episode, whoever drives, so its internal state (estimator, gait clock, plan) follows the robot. At each policy
tick (50 Hz) the student's observation is recorded with the expert's command turned into a policy action
(`wbc.learned.train.distill.expert_action`). Round 0 is driven by the expert; in round k an episode is driven by the
expert with probability beta^k and otherwise by the current student, whose mistakes then show the expert states it
never visits under the expert (Ross et al., 2011). After each round the student is fitted to everything collected so far
(`fit_student`) and exported (``<run_dir>/policy.npz/.json``), with the data (``data.npz``) and the round's figures
(``progress.json``): a run that stops loses at most the round in progress, and ``resume`` continues after the last
finished round, from that round's student. Each round's student also stays, as ``<run_dir>/rounds/policy-<k>`` and
``rounds/student-<k>.pt``: the episodes the student drives in round k + 1 measure the student fitted in round k, on
training seeds, and a resumed run starts from the student of its last finished round even where the round after it
had already replaced the run's ``policy`` and ``student.pt`` when it stopped.

While the expert drives, the student's previous-action input is the expert's action as a policy would have sent it,
so the observation means the same thing under both drivers. The samples of each episode are kept in time order with
the episode's id (``episode`` in ``data.npz``), so a student with memory (`FitConfig.history`) is fitted on the very
window of observations it would have read had it driven: the observations it sees and the previous actions in them
are built the same way whoever drives.

DART (Laskey et al., 2017): with ``expert_noise`` > 0 the robot, while the expert drives, gets the expert's command
plus the torque of a Gaussian action offset (standard deviation ``expert_noise`` action units, drawn each policy tick
and held over it, as a policy's action is), and the labels stay the expert's clean actions: the expert then shows how
it recovers from the small errors a student makes, from round 0 on.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shlex
import sys
import time
import zipfile
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wbc.arena.sim_trial import run_trial
from wbc.control.protocol import Controller, TruthSwitch
from wbc.control.registry import get_controller
from wbc.control.spec import ControllerSpec
from wbc.errors import ConfigError
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.policy.controller import LearnedController
from wbc.learned.policy.observations import policy_observation
from wbc.learned.policy.policy_file import load_policy, save_policy
from wbc.learned.train.distill import (
    FitConfig,
    StudentNet,
    expert_action,
    fit_student,
    load_student,
    save_student,
    student_policy_file,
)
from wbc.learned.train.preflight import (
    check_run_root,
    config_diff,
    locked_run_dir,
    make_run_dir,
    read_run_json,
    scenario_record,
)
from wbc.learned.train.stages import TASKS
from wbc.mpc.controller import MpcController, MpcControllerConfig
from wbc.output_files import replacing as _replacing  # a name of this module: the tests interrupt its writes
from wbc.provenance import provenance
from wbc.robots.description import RobotDescription
from wbc.robots.registry import get_robot
from wbc.scenario import load_scenario
from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["DaggerConfig", "DaggerController", "DaggerStart", "check_dagger_run", "run_dagger"]

TRAIN_SEED_OFFSET = 100_000
"""Training episodes use seeds from here on, as the training env's (`EnvConfig.train_seed_offset`): never an
evaluation trial."""


@dataclass(frozen=True, kw_only=True)
class DaggerConfig:
    """A DAgger run.

    Attributes:
        task: a key of `wbc.learned.train.stages.TASKS` (its robot, scenario and training bands).
        expert: the expert, a controller name of the arena (``mpc``).
        rounds: rounds, the expert-driven round 0 included.
        episodes: episodes per round.
        episode_s: play only the first seconds of each episode (None: the scenario's whole duration).
        beta: in round k an episode is driven by the expert with probability beta^k.
        seed: training seed (episodes use scenario seed `TRAIN_SEED_OFFSET` + seed).
        expert_noise: DART's action noise while the expert drives [action units, standard deviation]; 0: none.
        average_labels: label a sample with the mean of the expert's actions over its policy period, the constant
            action that best matches the expert's torques while a policy holds it, instead of the action at the
            period's first tick.
        expert_follows: the expert's CoM and yaw targets follow the robot (`MpcControllerConfig` leashes 0): the
            MPC then tracks the commanded velocity and yaw rate and forgets where the command would have put the
            robot, which no policy observation holds. With the arena's leashes (0.15 m, 0.3 rad) a student that
            drifts draws labels that pull it back by up to the leash, a correction it cannot see the reason for.
            Only an expert built by `MpcController` (``mpc``, ``mpc-locked``, ``mpc-noarm``).
        takeover: in the episodes the student drives, the expert takes over once the student's actions differ from
            its labels by more than this (rms over the joints, action units, smoothed over about 0.2 s), and drives to
            the end: the rest of the episode shows the expert recovering from where the student led, and labels that
            drift away from anything the student can act on are not collected under the student. None: never.
        expert_truth: the expert reads the simulator's base position and velocity instead of estimating them (its
            ground-truth switch); the student's observation is unchanged. A test of whether the expert's estimator,
            which trusts the feet its own schedule puts down, makes its labels drift from a student that stands:
            the drift stayed with it.
        fit: the student's supervised fit.
        run_dir: where the data, the policy and the progress go.
    """

    task: str = "push"
    expert: str = "mpc"
    rounds: int = 8
    episodes: int = 20
    episode_s: float | None = None
    beta: float = 0.5
    seed: int = 0
    expert_noise: float = 0.0
    average_labels: bool = False
    expert_follows: bool = False
    takeover: float | None = None
    expert_truth: bool = False
    fit: FitConfig = field(default_factory=FitConfig)
    run_dir: str = "runs/train/push-dagger-mpc"

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ConfigError(f"DaggerConfig: task must be one of {', '.join(TASKS)}, got {self.task!r}")
        if min(self.rounds, self.episodes) < 1:
            raise ConfigError("DaggerConfig: rounds and episodes must be >= 1")
        if self.episode_s is not None and not (math.isfinite(self.episode_s) and self.episode_s > 0.0):
            raise ConfigError(f"DaggerConfig: episode_s must be a positive number of seconds, got {self.episode_s}")
        if not 0.0 <= self.beta <= 1.0:
            raise ConfigError(f"DaggerConfig: beta must be in [0, 1], got {self.beta}")
        if self.takeover is not None and not (math.isfinite(self.takeover) and self.takeover > 0.0):
            raise ConfigError(f"DaggerConfig: takeover must be > 0 or None, got {self.takeover}")
        if not (math.isfinite(self.expert_noise) and self.expert_noise >= 0.0):
            raise ConfigError(f"DaggerConfig: expert_noise must be >= 0, got {self.expert_noise}")

    def expert_drives(self, round_index: int, episode: int) -> bool:
        """Whether the expert drives `episode` of round `round_index` (a pure function of the seed)."""
        if round_index == 0:
            return True
        draw = np.random.default_rng([self.seed, round_index, episode]).random()
        return bool(draw < self.beta**round_index)


class DaggerController:
    """The expert and the student in one controller: the expert acts every tick, one of them drives.

    The student's observation is recorded with the expert's label at every policy tick.

    Args:
        expert: the expert controller, built for the robot.
        desc: the robot.
        env: the student's env configuration (observation scales, action scale, gains, policy rate).
        student: the student's controller (its policy file), or None while there is none (the expert must drive).
        expert_drives: who drives this episode.
        noise: DART's action noise while the expert drives (standard deviation, action units); 0: none.
        rng: draws the noise (with `noise` > 0).
        average: label each sample with the mean of the expert's actions over its policy period (the constant
            action closest, in least squares, to the expert's torques over the period) instead of the action at its
            first tick.
        takeover: hand the episode to the expert once the student's actions differ from the labels by more than
            this (root mean square over the joints, action units, smoothed over about 0.2 s: an exponential mean
            with weight 0.2 per policy tick); None: the student drives to the end.

    Raises:
        ConfigError: the student must drive but there is none, or the expert's period does not divide the
            student's.
    """

    def __init__(self, expert: Controller, desc: RobotDescription, env: EnvConfig, student: LearnedController | None,
                 *, expert_drives: bool, noise: float = 0.0, rng: np.random.Generator | None = None,
                 average: bool = False, takeover: float | None = None) -> None:
        if student is None and not expert_drives:
            raise ConfigError("DaggerController: no student yet; the expert must drive")
        ratio = expert.rate_hz * env.policy_dt
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ConfigError(f"DaggerController: the expert's rate {expert.rate_hz} Hz is not a whole multiple of "
                              f"the student's {1.0 / env.policy_dt:g} Hz")
        self.expert, self.student, self.expert_drives = expert, student, expert_drives
        self.rate_hz = expert.rate_hz
        self.every = int(round(ratio))
        self.default_q = desc.nominal_q.copy()
        self.kp, self.kd = env.gains(desc.num_joints)
        self.scale, self.clip, self.scales = env.action_scale, env.clip_actions, env.obs_scales
        self.noise, self.rng = noise, rng if rng is not None else np.random.default_rng(0)
        self.average, self.takeover = average, takeover
        self.student_drove = not expert_drives
        self.offset = np.zeros(self.default_q.size)
        self.offset_tau = np.zeros(self.default_q.size)
        self._sum, self._count = np.zeros(self.default_q.size), 0
        self.obs: list[np.ndarray] = []
        self.labels: list[np.ndarray] = []
        self.reset()

    def reset(self) -> None:
        """Reset the expert and the student's inputs; the collected samples stay."""
        self.expert.reset()
        if self.student is not None:
            self.student.reset()
        self.tick = 0
        self._count = 0
        self.expert_drives = not self.student_drove
        self.taken_over_at: int | None = None
        self.disagreement = 0.0
        self.offset = np.zeros(self.default_q.size)
        self.last_action = np.zeros(self.default_q.size)
        self.held: MotorCommand | None = None

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """One expert tick; on policy ticks also a labelled sample and, when it drives, the student's command."""
        expert_cmd = self.expert.act(state, command)
        policy_tick = self.tick % self.every == 0
        instant = None
        if policy_tick or self.average:
            instant = expert_action(expert_cmd, state.q, state.dq, default_q=self.default_q, action_scale=self.scale,
                                    kp=self.kp, kd=self.kd)
        if policy_tick:
            self.finish()
            obs = policy_observation(
                gyro_in_body=state.gyro_in_body[None], imu_quat=state.imu_quat[None],
                command=command.as_array()[None], q=state.q[None], dq=state.dq[None],
                last_action=self.last_action[None], default_q=self.default_q, scales=self.scales)[0]
            self.obs.append(obs)
            self.labels.append(np.clip(instant, -self.clip, self.clip))
            self._sum, self._count = instant.copy(), 1
            if self.expert_drives:
                if self.noise > 0.0:
                    self.offset = self.noise * self.rng.standard_normal(instant.size)
                    self.offset_tau = self.kp * self.scale * self.offset
            else:
                assert self.student is not None
                # the student's own history: the same observations, in order, as recorded
                action = self.student.step(obs)
                self.last_action = action
                self.held = MotorCommand(q=self.default_q + self.scale * action, dq=np.zeros_like(action),
                                         kp=self.kp, kd=self.kd, tau=np.zeros_like(action))
        elif self.average and self._count:
            self._sum += instant
            self._count += 1
        self.tick += 1
        if self.expert_drives:
            if self.noise > 0.0:
                return dataclasses.replace(expert_cmd, tau=expert_cmd.tau + self.offset_tau)
            return expert_cmd
        assert self.held is not None
        return self.held

    def finish(self) -> None:
        """Close the last sample's policy period.

        Its label becomes final (averaged over the period with `average`) and, while the expert drives, so does the
        previous action the next observation reads (the label, plus DART's offset). Called at each policy tick and
        once after the episode.
        """
        if not self._count:
            return
        if self.average:
            self.labels[-1] = np.clip(self._sum / self._count, -self.clip, self.clip)
        if self.expert_drives:
            self.last_action = np.clip(self.labels[-1] + self.offset, -self.clip, self.clip)
        elif self.takeover is not None:
            # the student's action over the period against its label; the next observation still reads the
            # student's action, which is what the robot got
            error = float(np.sqrt(np.mean((self.last_action - self.labels[-1]) ** 2)))
            self.disagreement = 0.8 * self.disagreement + 0.2 * error
            if self.disagreement > self.takeover:
                self.expert_drives = True
                self.taken_over_at = len(self.labels)
        self._count = 0

    def use_ground_truth(self, truth: Any) -> None:
        """Pass the simulator's base state to the expert (`DaggerConfig.expert_truth`); the student never reads it."""
        switch = getattr(self.expert, "use_ground_truth", None)
        if switch is None:
            raise ConfigError(f"DaggerController: the expert {type(self.expert).__name__} has no ground-truth switch; "
                              "run without expert_truth")
        switch(truth)

    def counters(self) -> dict[str, int]:
        """The expert's event counters."""
        return self.expert.counters()


def _student_env(cfg: DaggerConfig, arm_mode: str) -> EnvConfig:
    spec = TASKS[cfg.task]
    return EnvConfig(robot=spec.robot, arm_mode=arm_mode, scenario=spec.scenario, bands=spec.bands)


def dagger_expert(cfg: DaggerConfig) -> tuple[ControllerSpec, Callable[[RobotDescription], Controller]]:
    """The expert's registry entry and what builds it for the run.

    With ``expert_follows`` the builder makes the MPC with its leashes at 0. `check_dagger_run` calls it, for the run
    and for ``wbc train --dry-run``.

    Raises:
        ConfigError: the expert is not a controller of the arena, or ``expert_follows`` with an expert that is not
            built by `MpcController`.
    """
    expert_spec = get_controller(cfg.expert)
    if not cfg.expert_follows:
        return expert_spec, expert_spec.make
    if expert_spec.make is not MpcController:
        raise ConfigError(f"DaggerConfig.expert_follows: {cfg.expert!r} is not built by MpcController; its "
                          "targets cannot be made to follow the robot")

    def make_expert(desc: RobotDescription) -> Controller:
        return MpcController(desc, MpcControllerConfig(xy_leash=0.0, yaw_leash=0.0))

    return expert_spec, make_expert


_DAMAGED = "the run directory is damaged: start a new run under another --run-root"


def _made(run_dir: Path) -> dict[str, Any]:
    """How the run was made, from its ``config.json``, for its exports' ``training`` block: a shipped copy says it.

    The command it began with, the scenario file and its sha256, the package versions and git revision, when it
    began, and its sessions (``segments``, each with its own command; those it records: a run begun before some were
    recorded has fewer).
    """
    try:
        data = json.loads((run_dir / "config.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return {}
    keys = ("command", "scenario", "provenance", "started", "segments")
    return {k: data[k] for k in keys if isinstance(data, dict) and k in data}


def _round_student(run_dir: Path, k: int) -> Path:
    """Where round `k` keeps its fitted student (``rounds/student-<k>.pt``)."""
    return run_dir / "rounds" / f"student-{k}.pt"


def _current_from_round(run_dir: Path, k: int) -> None:
    """Make round `k`'s student the run's current one: ``student.pt`` and ``policy.npz/.json`` copied from its own.

    A file already equal to the round's is left as it is; so is one the round did not keep (a run that kept no
    student per round has ``student.pt`` only).
    """
    rounds = run_dir / "rounds"
    pairs = [(_round_student(run_dir, k), run_dir / "student.pt")]
    pairs += [(rounds / f"policy-{k}{ext}", run_dir / f"policy{ext}") for ext in (".npz", ".json")]
    for kept, current in pairs:
        if not kept.is_file():
            continue
        data = kept.read_bytes()
        if current.is_file() and current.read_bytes() == data:
            continue
        with _replacing(current) as f:
            f.write(data)


def _resumed(run_dir: Path, resolved: dict[str, Any]) -> tuple[dict[str, Any], list, list, list]:
    """What a resumed run continues from: its progress and the samples of its finished rounds.

    Raises:
        ConfigError: no finished round, another config, or a missing or damaged ``config.json``, ``progress.json``
            or ``data.npz`` (the message names the file).
    """
    if not (run_dir / "progress.json").exists():
        raise ConfigError(f"--resume: no finished DAgger round in {run_dir}; start the run without --resume")
    config = run_dir / "config.json"
    data = read_run_json(config, _DAMAGED)
    saved = data.get("dagger_config") if isinstance(data, dict) else None
    if not isinstance(saved, dict):
        raise ConfigError(f"--resume: {config}: dagger_config: missing or not an object; {_DAMAGED}")
    # where the run lies is not part of its config: a run directory may move, or be named another way
    diff = [name for key in sorted(resolved) if key not in ("rounds", "run_dir")
            for name in config_diff(saved.get(key), resolved[key], key)]
    if diff:
        raise ConfigError(f"--resume: {config} differs from this run's config in {diff}")
    path = run_dir / "progress.json"
    progress = read_run_json(path, _DAMAGED)
    rounds = progress.get("rounds") if isinstance(progress, dict) else None
    if not isinstance(rounds, list) or not all(
            isinstance(r, dict) and isinstance(r.get("samples_total"), int) and r["samples_total"] >= 0
            and isinstance(r.get("wall_s"), (int, float)) and math.isfinite(r["wall_s"]) for r in rounds):
        raise ConfigError(f"--resume: {path}: rounds: missing, or a round without its samples_total or wall_s; "
                          f"{_DAMAGED}")
    try:
        with np.load(run_dir / "data.npz") as npz:
            if "episode" not in npz.files:
                raise ConfigError(f"--resume: {run_dir}/data.npz predates the samples' episode ids; start a new run")
            obs, actions, episode = npz["obs"], npz["actions"], npz["episode"]
    except FileNotFoundError:
        raise ConfigError(f"--resume: {run_dir / 'data.npz'}: no such file; {_DAMAGED}") from None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise ConfigError(f"--resume: {run_dir / 'data.npz'}: not readable ({type(exc).__name__}: {exc}); "
                          f"{_DAMAGED}") from None
    # the samples of the finished rounds only: a run stopped after saving a round's data and before its progress
    # plays that round again
    recorded = rounds[-1]["samples_total"] if rounds else 0
    if obs.shape[0] < recorded or actions.shape[0] != obs.shape[0] or episode.shape[0] != obs.shape[0]:
        raise ConfigError(f"--resume: {run_dir}/data.npz holds {obs.shape[0]} samples, progress.json records "
                          f"{recorded}: {_DAMAGED}")
    return progress, [obs[:recorded]], [actions[:recorded]], [episode[:recorded]]


@dataclass
class DaggerStart:
    """What a DAgger run starts from, once `check_dagger_run` has checked it.

    Attributes:
        expert_spec: the expert's registry entry.
        make_expert: builds the expert for the robot (`dagger_expert`).
        progress: ``progress.json`` of the finished rounds (``{"rounds": []}`` for a new run).
        obs: the finished rounds' observations, in one array (or none).
        actions: their labels.
        episode: their episode ids.
        net: the student of the last finished round, or None.
    """

    expert_spec: ControllerSpec
    make_expert: Callable[[RobotDescription], Controller]
    progress: dict[str, Any]
    obs: list[np.ndarray]
    actions: list[np.ndarray]
    episode: list[np.ndarray]
    net: StudentNet | None


def _check_truth_switch(cfg: DaggerConfig, expert_spec: ControllerSpec,
                        make_expert: Callable[[RobotDescription], Controller]) -> None:
    """With ``expert_truth``, the expert must have a ground-truth switch (`TruthSwitch`): built once to see."""
    expert = make_expert(get_robot(TASKS[cfg.task].robot, expert_spec.arm_mode))
    if not isinstance(expert, TruthSwitch):
        raise ConfigError(f"--expert-truth: the expert {cfg.expert!r} ({type(expert).__name__}) has no ground-truth "
                          "switch (wbc.control.protocol.TruthSwitch) to read the simulator's base state: leave "
                          "--expert-truth out, or distil a controller that estimates its base state (mpc)")


def check_dagger_run(cfg: DaggerConfig, *, resume: bool) -> DaggerStart:
    """Every check a DAgger run makes before its first round, and what it starts from.

    `run_dagger` calls it before it writes anything, ``wbc train --teacher CONTROLLER --dry-run`` instead of running:
    a dry run refuses what the run would.

    Raises:
        ConfigError: the expert is not a controller of the arena, cannot follow (``expert_follows``) or has no
            ground-truth switch (``expert_truth``); a run directory that cannot be made; ``resume`` without a
            finished round, with another configuration or over a damaged run directory (`_resumed`, ``student.pt``);
            or a run directory that already holds a run (without ``resume``).
    """
    expert_spec, make_expert = dagger_expert(cfg)
    if cfg.expert_truth:
        _check_truth_switch(cfg, expert_spec, make_expert)
    run_dir = Path(cfg.run_dir)
    check_run_root(run_dir)
    progress: dict[str, Any] = {"rounds": []}
    obs: list[np.ndarray] = []
    actions: list[np.ndarray] = []
    episode: list[np.ndarray] = []
    if resume:
        resolved = json.loads(json.dumps(dataclasses.asdict(cfg), default=list))
        progress, obs, actions, episode = _resumed(run_dir, resolved)
    elif (run_dir / "progress.json").exists():
        raise ConfigError(f"{run_dir} already holds a DAgger run; pass --resume to continue it or choose another "
                          "--run-root")
    net: StudentNet | None = None
    if progress["rounds"]:
        kept = _round_student(run_dir, len(progress["rounds"]) - 1)
        source = kept if kept.is_file() else run_dir / "student.pt"  # a run that kept no student per round
        try:
            net = load_student(source)
        except Exception as exc:  # noqa: BLE001 - torch raises anything from a damaged pickle
            raise ConfigError(f"--resume: {source}: not a readable student ({type(exc).__name__}); "
                              f"{_DAMAGED}") from None
    return DaggerStart(expert_spec=expert_spec, make_expert=make_expert, progress=progress, obs=obs, actions=actions,
                       episode=episode, net=net)


def run_dagger(cfg: DaggerConfig, *, resume: bool = False, log: Any = None,
               checked: Callable[[], object] | None = None, command: Sequence[str] | None = None) -> dict[str, Any]:
    """Run DAgger rounds and export the student after each.

    Args:
        cfg: the run.
        resume: continue after the last finished round in ``cfg.run_dir`` (its config must be the same but for
            ``rounds``).
        log: called with one line of progress per round (e.g. `print`), or None.
        checked: called once the run's checks have passed, before its first round (the command's resume note).
        command: the command line the run records (``["wbc", "train", ...]``), quoted with `shlex.join`; default:
            the process's ``sys.argv``.

    Returns:
        The run's summary: ``rounds`` (finished in all), ``trained`` (in this call: 0 when a resumed run already held
        ``cfg.rounds``), ``samples``, ``policy`` (the file), ``wall_s``.

    The run holds its directory's lock (`wbc.learned.train.preflight.locked_run_dir`) from before it reads it to its
    end: a second run on the directory is refused while this one lives.

    Raises:
        ConfigError: another run holds the run directory (naming it and that run's pid); what `check_dagger_run`
            refuses.
    """
    # the checks `wbc train --dry-run` makes, under the lock
    with locked_run_dir(cfg.run_dir, lambda: check_dagger_run(cfg, resume=resume)) as start:
        if checked is not None:
            checked()
        return _run_rounds(cfg, start, resume=resume, log=log,
                           command=shlex.join(sys.argv if command is None else command))


def _session(cfg: DaggerConfig, run_dir: Path, *, resume: bool, done: int, command: str) -> dict[str, Any]:
    """The run's ``config.json`` with this session added to its ``segments``.

    A new run records its settings, command, scenario, provenance and start, and its first segment. A resumed one
    keeps what the run began with and takes this session's settings as the current ones (``dagger_config``, so
    that a later plain ``--resume`` takes its ``rounds``); its segment says when it began, its command, the settings
    it changed (``{field: [before, now]}``), the round it began at (``from_round``, rounds finished before it) and
    the package versions and git revision it ran under. Each round records the rounds reached (``to_round``).
    """
    resolved = json.loads(json.dumps(dataclasses.asdict(cfg), default=list))
    segment = {"started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "command": command, "from_round": done,
               "rounds": cfg.rounds, "provenance": provenance()}
    if not resume:
        spec = TASKS[cfg.task]
        return {"dagger_config": resolved, "command": command, "scenario": scenario_record(spec.scenario),
                "provenance": segment["provenance"], "started": segment["started"],
                "segments": [{**segment, "resumed": False, "changed": {}}]}
    data = json.loads((run_dir / "config.json").read_text())  # checked by `_resumed`
    saved = data.get("dagger_config", {})
    changed = {key: [saved.get(key), resolved[key]] for key in sorted(resolved)
               if key != "run_dir" and saved.get(key) != resolved[key]}
    # a run begun before segments were recorded: its earlier sessions are not known
    segments = data.get("segments") if isinstance(data.get("segments"), list) else []
    return {**data, "dagger_config": resolved, "segments": [*segments, {**segment, "resumed": True,
                                                                        "changed": changed}]}


def _end_segment(run_dir: Path, fields: dict[str, Any]) -> None:
    """Record in ``config.json`` how far this session went (the rounds finished)."""
    path = run_dir / "config.json"
    data = json.loads(path.read_text())
    if isinstance(data.get("segments"), list) and data["segments"]:
        data["segments"][-1].update(fields)
        with _replacing(path) as f:
            f.write((json.dumps(data, indent=2) + "\n").encode())


def _run_rounds(cfg: DaggerConfig, start: DaggerStart, *, resume: bool, log: Any, command: str) -> dict[str, Any]:
    """`run_dagger` once its run directory is checked and locked, from `start`."""
    expert_spec, make_expert = start.expert_spec, start.make_expert
    progress, obs_all, act_all, ep_all, net = start.progress, start.obs, start.actions, start.episode, start.net
    spec = TASKS[cfg.task]
    scenario = load_scenario(spec.scenario)
    env = _student_env(cfg, expert_spec.arm_mode)
    run_dir = Path(cfg.run_dir)
    if not resume:
        make_run_dir(run_dir)
    start_round = len(progress["rounds"])
    if start_round < cfg.rounds or not resume:  # a resume with no round to play leaves the run as it was
        config = _session(cfg, run_dir, resume=resume, done=start_round, command=command)
        with _replacing(run_dir / "config.json") as f:
            f.write((json.dumps(config, indent=2) + "\n").encode())
    student_path = run_dir / "policy"
    if start_round:  # a run stopped after a round wrote its student and before its progress: that round plays again
        _current_from_round(run_dir, start_round - 1)
    wall_before = sum(r["wall_s"] for r in progress["rounds"])
    for k in range(start_round, cfg.rounds):
        t0 = time.perf_counter()
        built: dict[str, DaggerController] = {}
        episodes = []
        for e in range(cfg.episodes):
            index = k * cfg.episodes + e
            band = spec.bands[index % len(spec.bands)]
            trial = scenario.trial(band, TRAIN_SEED_OFFSET + cfg.seed, index)
            if cfg.episode_s is not None and cfg.episode_s < trial.duration_s:
                trial = dataclasses.replace(trial, duration_s=cfg.episode_s,
                                            pushes=tuple(p for p in trial.pushes if p.start < cfg.episode_s))
            drives = cfg.expert_drives(k, e) or net is None

            def make(desc: RobotDescription, drives: bool = drives, index: int = index,
                     built: dict[str, DaggerController] = built) -> DaggerController:
                student = LearnedController(desc, student_path) if not drives else None
                ctrl = DaggerController(make_expert(desc), desc, env, student, expert_drives=drives,
                                        noise=cfg.expert_noise, rng=np.random.default_rng([cfg.seed, index, 7]),
                                        average=cfg.average_labels, takeover=cfg.takeover)
                built["ctrl"] = ctrl
                return ctrl

            dagger_spec = ControllerSpec(name=f"dagger:{cfg.expert}", arm_mode=expert_spec.arm_mode, make=make,
                                         summary="DAgger collection")
            # a controller failure costs this episode's remaining ticks only: the samples before it are kept
            record, _ = run_trial(trial, dagger_spec, debug_truth=cfg.expert_truth)
            ctrl = built.pop("ctrl", None)
            if ctrl is not None:
                ctrl.finish()
            if ctrl is not None and ctrl.obs:
                obs_all.append(np.asarray(ctrl.obs))
                act_all.append(np.asarray(ctrl.labels))
                ep_all.append(np.full(len(ctrl.obs), index))
            fell = bool(math.isfinite(record.fall_time_s))
            taken = None if ctrl is None or ctrl.taken_over_at is None else ctrl.taken_over_at * env.policy_dt
            episodes.append({"index": index, "band": band, "expert_drives": drives, "takeover_s": taken,
                             "samples": 0 if ctrl is None else len(ctrl.obs), "fell": fell,
                             "fall_time_s": record.fall_time_s if fell else None, "error": record.error or None})
        obs, actions, episode_ids = np.concatenate(obs_all), np.concatenate(act_all), np.concatenate(ep_all)
        obs_all, act_all, ep_all = [obs], [actions], [episode_ids]
        net, losses = fit_student(obs, actions, dataclasses.replace(cfg.fit, seed=cfg.fit.seed + k), start=net,
                                  episode=episode_ids)
        wall = time.perf_counter() - t0
        student_rounds = [ep for ep in episodes if not ep["expert_drives"]]
        summary = {"round": k, "episodes": episodes, "samples_total": int(obs.shape[0]),
                   "student_episodes": len(student_rounds),
                   "student_falls": sum(ep["fell"] and ep["takeover_s"] is None for ep in student_rounds),
                   "student_takeovers": sum(ep["takeover_s"] is not None for ep in student_rounds),
                   "errors": sum(ep["error"] is not None for ep in episodes),
                   "fit_loss_first": losses[0] if losses else math.nan, "fit_loss_last": losses[-1] if losses
                   else math.nan, "wall_s": wall}
        progress["rounds"].append(summary)
        _end_segment(run_dir, {"to_round": k + 1})  # before the round's export, whose training block carries it
        made = _made(run_dir)
        extra = {"baseline": None, "method": "dagger", "expert": cfg.expert, "rounds": k + 1,
                 "episodes": cfg.episodes, "episode_s": cfg.episode_s, "history": cfg.fit.history,
                 "expert_noise": cfg.expert_noise,
                 "average_labels": cfg.average_labels, "expert_truth": cfg.expert_truth,
                 "expert_follows": cfg.expert_follows, "takeover": cfg.takeover, "beta": cfg.beta,
                 "seed": cfg.seed,
                 "samples": int(obs.shape[0]), "wall_s": wall_before + sum(r["wall_s"] for r in progress["rounds"][
                     start_round:]), **made}
        # each file replaced whole: a run stopped while writing keeps the previous round's. The round's own files
        # first, then its progress (the round is finished once that is written), then the run's current student:
        # a resumed run starts from the student of its last finished round, whatever the next round wrote
        with _replacing(run_dir / "data.npz") as f:
            np.savez(f, obs=obs, actions=actions, episode=episode_ids)
        # each round's student stays: the next round's figures measure it, and the newest is not always the best
        _round_student(run_dir, k).parent.mkdir(parents=True, exist_ok=True)
        with _replacing(_round_student(run_dir, k)) as f:
            save_student(net, f)
        exported = student_policy_file(net, env, task=cfg.task, extra=extra)
        save_policy(run_dir / "rounds" / f"policy-{k}", exported)
        with _replacing(run_dir / "progress.json") as f:
            f.write((json.dumps(progress, indent=2, default=float) + "\n").encode())
        _current_from_round(run_dir, k)
        if log is not None:
            log(f"round {k}: {len(episodes)} episodes ({len(student_rounds)} driven by the student, "
                f"{summary['student_falls']} of them fell, {summary['student_takeovers']} taken over), "
                f"{obs.shape[0]} samples, fit loss "
                f"{summary['fit_loss_first']:.4f} -> {summary['fit_loss_last']:.4f}, {wall:.1f} s")
    load_policy(student_path)  # the export reads back
    return {"run_dir": str(run_dir), "rounds": len(progress["rounds"]), "trained": max(cfg.rounds - start_round, 0),
            "samples": int(sum(len(a) for a in act_all)), "policy": str(student_path.with_suffix(".npz")),
            "wall_s": sum(r["wall_s"] for r in progress["rounds"])}
