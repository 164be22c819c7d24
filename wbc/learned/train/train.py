"""`train`: one stage (or baseline) trained with rsl-rl-lib's `OnPolicyRunner` on the batched env.

A run directory holds: ``config.json`` (the resolved `TrainConfig` as the newest session set it, seed, the command,
the scenario file and its sha256, the sha256 of each file it reads, package versions, git revision, and the run's
sessions, ``segments``: `_run_config`),
TensorBoard event files and ``model_<it>.pt`` checkpoints (rsl-rl's), ``policy.npz``/``policy.json`` (the
torch-free export, refreshed at every checkpoint; a checkpoint's export without the adaptation module its stage needs
goes to ``policy_ppo.npz``/``policy_ppo.json`` where ``policy`` holds one, `_Runner.export`) and ``progress.json``
(iterations, environment steps and wall time so far, summed over resumed sessions). Each of these files is replaced
whole (`wbc.output_files`): a run killed while it writes one keeps the one before. ``resume`` continues from the
newest checkpoint up to `max_iterations`; Ctrl-C stops a run at the end of the iteration in progress, whose
checkpoint it saves first (`_learn`); in the adaptation phase (RMA phase 2) it stops at once, and the run keeps the
export it had before the phase (`_adapt`).
When the run ends, ``policy.replay.npz`` records a short rollout of the exported policy (robot states, commands,
observation frames and actions, `wbc.learned.policy.replay_recorder`): ``wbc check-controller NAME --replay
policy.replay.npz`` then checks that a controller built from these weights (an ONNX export, an I/O file written by
hand) observes and acts as the trainer's policy did.

With `TrainConfig.frozen_legs` (the decoupled baseline) the env is wrapped in `FrozenLegsVecEnv`, the actor drives
the arm only, and ``policy.npz``/``policy.json`` is a composite file holding the frozen leg policy and the arm actor.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import shlex
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from wbc.errors import ConfigError
from wbc.interrupts import DeferredInterrupts
from wbc.learned.env.env import BatchedEnv
from wbc.learned.policy.composite_policy import save_composite
from wbc.learned.policy.policy_file import load_policy, save_policy
from wbc.learned.policy.replay_file import replay_path_for
from wbc.learned.policy.replay_recorder import record_replay
from wbc.learned.train.distill import student_policy_file
from wbc.learned.train.export import decoupled_policy, policy_file_from_actor
from wbc.learned.train.frozen_legs_vec_env import FrozenLegsVecEnv
from wbc.learned.train.history_actor import HistoryActor
from wbc.learned.train.preflight import (
    CHECKPOINT_KEY,
    PPO_EXPORT,
    RESUMABLE,
    ResumePoint,
    check_run,
    checkpoint_identity,
    checkpoint_iteration,
    config_diff,
    input_files,
    lacks_module,
    latest_checkpoint,
    load_input_policy,
    locked_run_dir,
    make_run_dir,
    playable_export,
    scenario_record,
    student_layout,
    unreadable_fix,
)
from wbc.learned.train.rma import train_adaptation
from wbc.learned.train.train_config import TrainConfig
from wbc.learned.train.vec_env import RslVecEnv
from wbc.learned.train.warm_start import warm_start_actor
from wbc.optional import require
from wbc.output_files import replacing, temporary_name
from wbc.provenance import provenance

torch = require("torch")
_runners = require("rsl_rl.runners")

__all__ = ["latest_checkpoint", "rsl_rl_config", "train"]

_RESUMABLE = RESUMABLE
"""TrainConfig fields a resumed run may change; any other difference is refused."""


def rsl_rl_config(cfg: TrainConfig) -> dict[str, Any]:
    """The rsl-rl-lib 5.x runner configuration of a `TrainConfig`."""
    ppo = dataclasses.asdict(cfg.ppo)
    dist = {"class_name": "GaussianDistribution", "init_std": cfg.init_std, "std_type": "scalar"}
    actor: dict[str, Any] = {"class_name": "MLPModel", "hidden_dims": list(cfg.actor_hidden_dims),
                             "activation": cfg.activation, "obs_normalization": True, "distribution_cfg": dist}
    actor_groups = ["policy"]
    if cfg.student is not None:
        actor.update(class_name="wbc.learned.train.history_actor:HistoryActor", student_path=cfg.student)
        actor_groups = ["policy", "history"]
    elif cfg.extrinsics_dim > 0:
        actor.update(class_name="wbc.learned.train.extrinsics_actor:ExtrinsicsActor", extrinsics_dim=cfg.extrinsics_dim,
                     encoder_dims=list(cfg.encoder_dims))
        actor_groups = ["policy", "privileged"]
    algorithm: dict[str, Any] = {"class_name": "PPO", **ppo}
    if cfg.bc is not None:
        algorithm.update(class_name="wbc.learned.train.ppo_bc:PPOWithBC", teacher_path=cfg.teacher,
                         bc_schedule=dataclasses.asdict(cfg.bc),
                         action_mask=None if cfg.action_mask is None else list(cfg.action_mask),
                         actor_frozen_iterations=cfg.actor_frozen_iterations)
        if cfg.expert_data is not None:
            algorithm.update(expert_data=cfg.expert_data, expert_seed=cfg.seed)
        if cfg.student is not None:
            algorithm["teacher_group"] = "policy"  # the student as it was: same arm, same observation
    return {
        "num_steps_per_env": cfg.num_steps_per_env,
        "save_interval": cfg.save_interval,
        "obs_groups": {"actor": actor_groups, "critic": ["policy", "privileged"]},
        "algorithm": algorithm,
        "actor": actor,
        "critic": {"class_name": "MLPModel", "hidden_dims": list(cfg.critic_hidden_dims),
                   "activation": cfg.activation, "obs_normalization": True},
        "logger": "tensorboard",
        "check_for_nan": True,
    }


class _Runner(_runners.OnPolicyRunner):
    """rsl-rl's runner, also exporting the policy file and progress at every checkpoint."""

    def __init__(self, vec: RslVecEnv, train_cfg: dict, cfg: TrainConfig, before: dict[str, Any]) -> None:
        super().__init__(vec, train_cfg, log_dir=cfg.run_dir, device=cfg.device)
        self.wbc_cfg = cfg
        self._wall_before = float(before["wall_s"])
        self._steps_before = int(before["env_steps"])
        self._t0 = time.perf_counter()
        self._student_meta = {}
        if cfg.student is not None:  # what the student was: its file and its own training
            student = load_policy(cfg.student)
            self._student_meta = {"method": "ppo-bc fine-tune of a distilled student", "student": str(cfg.student),
                                  "bc_towards": "the expert's samples" if cfg.expert_data else "the student",
                                  **({"expert_data": str(cfg.expert_data)} if cfg.expert_data else {}),
                                  "student_training": student.meta.get("training", {})}

    def save(self, path: str, infos: dict | None = None) -> None:
        """rsl-rl's checkpoint ``model_<it>.pt``, written whole or not at all, then the export (`export`).

        rsl-rl writes the checkpoint in place (``torch.save(path)``), so a run killed while writing it left a torn
        file that ``--resume`` refuses. It is written here to ``model_<it>.pt.tmp`` beside it (a name
        `wbc.learned.train.preflight.latest_checkpoint` never takes for a checkpoint) and renamed over its name once
        complete (`wbc.output_files`): a kill leaves the previous checkpoints whole and at most that temporary file,
        which the next save of the iteration replaces. (rsl-rl also hands the path to its logger, to upload the
        file; the TensorBoard logger a run uses uploads nothing.)

        Its ``infos`` record what run it is (`wbc.learned.train.preflight.checkpoint_identity`: task, stage, baseline,
        variant, robot, arm mode and iteration), which ``--resume`` compares with the run's (`check_checkpoint`).
        """
        identity = checkpoint_identity(self.wbc_cfg, int(self.current_learning_iteration))
        tmp = temporary_name(path)
        try:
            super().save(str(tmp), {**(infos or {}), CHECKPOINT_KEY: identity})
            os.replace(tmp, path)
        except BaseException:  # KeyboardInterrupt too: no half-written file stays behind
            tmp.unlink(missing_ok=True)
            raise
        self.export()

    def policy_file(self) -> tuple[Any, dict[str, Any]]:
        """The export of the runner's networks as they are (a policy file, or a composite one), and its progress.

        Its ``training`` block holds the run's provenance as ``config.json`` records it (`_provenance`): the inputs
        and their sha256, the seed, the scenario file and its hash, the command and the package versions and git
        revision, so that a shipped copy of the file says how it was made.
        """
        cfg = self.wbc_cfg
        wall = self._wall_before + time.perf_counter() - self._t0
        progress = {"iteration": int(self.current_learning_iteration),
                    "env_steps": self._steps_before + int(self.env.env.total_steps), "wall_s": wall}
        actor = self.alg.get_policy()
        extra = {"baseline": cfg.baseline, **({"variant": cfg.variant} if cfg.variant else {}), **progress,
                 **_provenance(Path(cfg.run_dir))}
        if isinstance(actor, HistoryActor):
            pf = student_policy_file(actor, cfg.env, task=cfg.task, extra={**self._student_meta, **extra})
            pf.meta["extrinsics"]["note"] = (
                "z is a latent learned from the observation history by the adaptation module, fitted with the actor "
                "on an expert's actions, then fine-tuned with it by PPO + BC; it observes nothing privileged")
            return pf, progress
        if isinstance(self.env, FrozenLegsVecEnv):
            extra["frozen_legs"] = cfg.frozen_legs
            return decoupled_policy(actor, self.env.legs.file, cfg.env, task=cfg.task, stage=cfg.stage,
                                    extra=extra), progress
        return policy_file_from_actor(actor, cfg.env, task=cfg.task, stage=cfg.stage, extra=extra), progress

    def export(self) -> Path:
        """Write ``policy.npz``/``policy.json`` of the runner's networks, then ``progress.json``; returns the ``.npz``.

        A stage whose policy observes RMA's extrinsics has no adaptation module before its phase 2 (`_adapt`): where
        the run's ``policy`` is playable (a module fitted on an earlier checkpoint), this export is written beside
        it, as ``policy_ppo.npz``/``policy_ppo.json`` (`PPO_EXPORT`), and the playable one is kept until phase 2
        replaces it.
        """
        pf, progress = self.policy_file()
        run_dir = Path(self.wbc_cfg.run_dir)
        path = run_dir / "policy"
        if isinstance(self.env, FrozenLegsVecEnv):
            save_composite(path, pf)
        else:
            if lacks_module(pf.meta) and playable_export(run_dir) is not None:
                path = run_dir / PPO_EXPORT
            save_policy(path, pf)
        # after the policy files: a kill in between leaves a progress of the checkpoint before, which --resume
        # reconciles (`wbc.learned.train.preflight.check_run_dir`)
        _write_json(run_dir / "progress.json", progress)
        return path.with_suffix(".npz")


_PROVENANCE_KEYS = ("seed", "command", "scenario", "inputs", "provenance", "started", "segments")
"""What the ``training`` block of an export copies from the run's ``config.json``."""


def _provenance(run_dir: Path) -> dict[str, Any]:
    """The `_PROVENANCE_KEYS` of the run's ``config.json`` (those it has: a run begun before they were recorded)."""
    try:
        data = json.loads((run_dir / "config.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return {}
    return {k: data[k] for k in _PROVENANCE_KEYS if isinstance(data, dict) and k in data}


def _write_json(path: Path, data: dict[str, Any]) -> None:
    """Write a JSON file of the run directory whole (`wbc.output_files`): ``--resume`` refuses a torn one."""
    with replacing(path) as f:
        f.write((json.dumps(data, indent=2) + "\n").encode())


class _StopAfterIteration(KeyboardInterrupt):
    """A Ctrl-C deferred to the end of an iteration (`_learn`), raised there."""


def _learn(runner: _Runner, iterations: int, *, init_at_random_ep_len: bool) -> None:
    """`runner.learn`, which Ctrl-C (or SIGTERM) stops at the end of an iteration, keeping that iteration's checkpoint.

    rsl-rl's loop may be interrupted anywhere: in a rollout, whose steps have already moved the observation
    normalisers, or in the PPO update, some of its minibatches applied. The model in memory then is no iteration's,
    and is not saved. So Ctrl-C and the requests to end (`wbc.interrupts.ASKS_TO_END`: SIGTERM, SIGHUP) are deferred
    while the loop runs: the first is noted (and said on stderr), and the
    interruption is raised at the end of the iteration in progress, once it is updated and logged (in rsl-rl's
    ``logger.log``, the loop's last step before its periodic save). The runner then holds that iteration's networks,
    normalisers and optimiser, and ``current_learning_iteration`` is its number: its checkpoint is saved, with its
    export and progress (unless a checkpoint as new is already there), and KeyboardInterrupt is raised, so that
    ``wbc train`` names the newest checkpoint, this one, and ``--resume`` continues after it.

    A second Ctrl-C or SIGTERM stops at once (the handlers before are back), and the run keeps the checkpoints saved
    until then, as does a KeyboardInterrupt raised otherwise. A Ctrl-C after the last iteration's log lets the loop
    end (its final checkpoint saved) and is raised once it has. Outside the main thread, where Python handles no
    signal, nothing is deferred (`DeferredInterrupts` installs nothing there) and the loop runs as rsl-rl's.

    Raises:
        KeyboardInterrupt: Ctrl-C.
    """
    interrupt = DeferredInterrupts(lambda what: f"wbc: {what}: the run stops at the end of the iteration in progress "
                                   "and saves its checkpoint (Ctrl-C or SIGTERM again stops at once, keeping the "
                                   "checkpoints saved so far)")
    log = runner.logger.log

    def log_then_stop(*args: Any, **kwargs: Any) -> None:
        weight = getattr(runner.alg, "bc_weight", None)
        if weight is not None:
            # the BC weight as what it is, TensorBoard tag Train/bc_weight, printed beside the episode figures:
            # rsl-rl logs the update's values as losses (Loss/<name>, "Mean <name> loss")
            runner.logger.ep_extras.append({"Train/bc_weight": torch.tensor(float(weight))})
        log(*args, **kwargs)
        if interrupt.requested:
            raise _StopAfterIteration

    runner.logger.log = log_then_stop
    try:
        with interrupt:
            runner.learn(iterations, init_at_random_ep_len=init_at_random_ep_len)
    except _StopAfterIteration:
        it = runner.current_learning_iteration
        run_dir = Path(runner.wbc_cfg.run_dir)
        # the session's end first, so that the export of its checkpoint carries it
        _end_segment(run_dir, {"to_iteration": it, "adaptation": "none", "interrupted": True})
        newest = latest_checkpoint(run_dir)
        if newest is None or checkpoint_iteration(newest) < it:
            runner.save(str(run_dir / f"model_{it}.pt"))
        else:  # saved at its periodic checkpoint already: its export again, with the session's end
            runner.export()
        if hasattr(runner.logger.writer, "flush"):  # the curves up to the checkpoint
            runner.logger.writer.flush()
        raise KeyboardInterrupt from None
    finally:
        del runner.logger.log  # rsl-rl's own again
    if interrupt.requested:
        raise KeyboardInterrupt


def train(cfg: TrainConfig, *, resume: bool = False, options: Mapping[str, str] | None = None,
          checked: Callable[[], object] | None = None, command: Sequence[str] | None = None) -> dict[str, Any]:
    """Train (or resume) one run.

    Args:
        cfg: the run.
        resume: continue from the newest checkpoint in ``cfg.run_dir``; its saved config must match `cfg` except in
            `_RESUMABLE` fields (train longer with a larger max_iterations).
        options: the options of ``wbc train`` that set its input files (``{"teacher": "--teacher"}``), named when
            one is refused (`wbc.learned.train.preflight.check_inputs`).
        checked: called once the run's checks have passed, before anything is built or trained (the command's
            resume note).
        command: the command line the run records (``["wbc", "train", ...]``, as ``wbc train`` gives it), quoted
            with `shlex.join`; default: the process's ``sys.argv``.

    Returns:
        ``{"run_dir", "iterations", "env_steps", "wall_s", "policy", "trained"}`` (``iterations``: trained in all,
        ``trained``: in this call, 0 when a resumed run had already reached `max_iterations`: its newest checkpoint is
        then exported as it is, and the adaptation phase runs), ``"adaptation"`` (``"fitted"``; ``"kept"`` where the
        export already held the module this phase 2 fits on that checkpoint, `_adapted`; ``"none"``), and
        ``"replay"`` (the replay file of the exported policy) unless the policy observes RMA extrinsics without an
        adaptation module to estimate them.

    The run holds its directory's lock (`wbc.learned.train.preflight.locked_run_dir`) from before it reads it to its
    end: a second run on the directory (a training, a DAgger run, a fine-tune) is refused while this one lives.

    Raises:
        ConfigError: another run holds the run directory (naming it and that run's pid); a new run in a directory
            that holds a run; no checkpoint to resume from, a damaged run directory (config.json, progress.json, the
            newest checkpoint, or one of another run or whose networks do not fit) or a resumed config that differs; or
            the teacher is missing/mismatched.
        KeyboardInterrupt: Ctrl-C; during PPO, once the iteration in progress has ended and its checkpoint is saved
            (`_learn`); during the adaptation phase at once, the export before it kept (`_adapt`).
    """
    def check() -> ResumePoint | None:  # the checks `wbc train --dry-run` makes, under the lock
        point = check_run(cfg, resume=resume, options=options)
        if checked is not None:
            checked()
        return point

    with locked_run_dir(cfg.run_dir, check) as point:
        return _train(cfg, point, shlex.join(sys.argv if command is None else command))


def _train(cfg: TrainConfig, point: ResumePoint | None, command: str) -> dict[str, Any]:
    """`train` once its run directory is checked and locked; `point`: where a resumed run continues from, or None."""
    run_dir = Path(cfg.run_dir)
    resolved = json.loads(json.dumps(dataclasses.asdict(cfg), default=list))
    progress = point.progress if point is not None else {"iteration": 0, "env_steps": 0, "wall_s": 0.0}
    make_run_dir(run_dir)
    torch.manual_seed(cfg.seed)
    torch.set_num_threads(cfg.torch_threads)
    env = BatchedEnv(cfg.env)
    if cfg.frozen_legs is not None:
        vec: RslVecEnv = FrozenLegsVecEnv(env, load_policy(cfg.frozen_legs), device=cfg.device)
    else:
        history = student_layout(load_policy(cfg.student))[1] if cfg.student is not None else 0
        vec = RslVecEnv(env, device=cfg.device, history=history)
    done = 0
    adapts = cfg.extrinsics_dim > 0 and cfg.rma.iterations > 0
    kept = False
    exported = run_dir / "policy.npz"
    try:
        # rsl-rl prints its networks as it builds them: held back until a resumed run's checkpoint fits them, so that
        # a refusal is the one line that says why
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):
            runner = _Runner(vec, rsl_rl_config(cfg), cfg, progress)
            if point is not None:
                _load_checkpoint(runner, point.checkpoint, cfg.device)
        sys.stdout.write(printed.getvalue())
        if point is None and cfg.init_from is not None:
            start = load_input_policy(cfg.init_from, "the policy this run starts from")
            mask = None if cfg.action_mask is None else list(cfg.action_mask)
            warm_start_actor(runner.alg.get_policy(), start, mask=mask)
        if point is not None:
            done = runner.current_learning_iteration + 1
            runner.current_learning_iteration = done  # rsl-rl would repeat the checkpoint's iteration number
        _write_json(run_dir / "config.json", _run_config(cfg, resolved, point, command))
        remaining = cfg.max_iterations - done
        if remaining > 0:
            _learn(runner, remaining, init_at_random_ep_len=point is None)
        else:
            # nothing left to train: the newest checkpoint is exported as it is (how an interrupted run is finished,
            # phase 2 included), under its own iteration, not the next one
            runner.current_learning_iteration = done - 1
            kept = adapts and _adapted(run_dir, cfg, done - 1)
        # the session's end is recorded before its final export, which carries it in its training block
        reached = {"to_iteration": int(runner.current_learning_iteration),
                   "adaptation": "kept" if kept else "fitted" if adapts else "none"}
        if kept:  # its export already holds this checkpoint's module of this phase 2: neither redone nor replaced
            _end_segment(run_dir, reached)
            phase1, final = None, json.loads((run_dir / "progress.json").read_text())
        elif adapts:
            # the export is replaced once phase 2 has fitted its module (`_adapt`): an interruption before leaves
            # the export as it was, a module included, never this checkpoint's without one
            phase1, final = runner.policy_file()
        else:
            _end_segment(run_dir, reached)
            exported = runner.export()
            phase1, final = None, json.loads((run_dir / "progress.json").read_text())
    finally:
        vec.close()
    result = {"run_dir": str(run_dir), "iterations": final["iteration"] + 1, "env_steps": final["env_steps"],
              "wall_s": final["wall_s"], "policy": str(exported), "trained": max(remaining, 0)}
    if phase1 is not None:
        try:
            result["rma_wall_s"] = _adapt(run_dir, cfg, phase1, final, reached)
        except KeyboardInterrupt:
            _end_segment(run_dir, {**reached, "adaptation": "interrupted", "interrupted": True})
            raise
    result["adaptation"] = reached["adaptation"]
    if cfg.extrinsics_dim == 0 or cfg.rma.iterations > 0:  # else it observes extrinsics a robot cannot give it
        result["replay"] = str(record_replay(run_dir / "policy", replay_path_for(run_dir / "policy")))
    return result


def _load_checkpoint(runner: _Runner, checkpoint: Path, device: str) -> None:
    """Load a resumed run's checkpoint into `runner`, or refuse it in one line naming the first part that differs.

    Raises:
        ConfigError: the checkpoint's networks are not the run's (another stage's, other layers), naming the file,
            the state that does not fit and the checkpoint a resume takes once it is moved away.
    """
    try:
        runner.load(str(checkpoint), map_location=device)  # a run may resume on another device
    except (RuntimeError, KeyError, ValueError) as exc:
        # torch's message: a header, then one line per parameter that differs ("size mismatch for mlp.0.weight: ...")
        lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
        detail = lines[1] if len(lines) > 1 else lines[0] if lines else type(exc).__name__
        raise ConfigError(f"--resume: {checkpoint}: does not fit this run's networks ({detail[:160]}): "
                          f"{unreadable_fix(checkpoint)}, or start a new run under another --run-root") from None


def _adapt(run_dir: Path, cfg: TrainConfig, phase1: Any, progress: dict[str, Any], reached: dict[str, Any]) -> float:
    """RMA phase 2 on `phase1` (the newest checkpoint's export, in memory), then its export written; returns its wall.

    Once the module is fitted, the session's end (`reached`) is recorded in ``config.json`` (`_end_segment`) and the
    export's ``training`` block takes the run's segments from it.

    Ctrl-C (or SIGTERM) during the fit stops it at once, and nothing of it is written: the run directory keeps the
    export, ``rma.json`` and ``progress.json`` it had before phase 2 (a previous module included), and ``--resume``
    fits the module again from the newest checkpoint. The files are then written with Ctrl-C deferred to their end,
    the policy first: an interruption never leaves a pair torn between two exports.
    """
    policy, summary = train_adaptation(phase1, cfg.env, cfg.rma)
    _end_segment(run_dir, reached)
    training = policy.meta.get("training")
    if isinstance(training, dict):
        training.update({k: v for k, v in _provenance(run_dir).items() if k == "segments"})
    # what `_adapted` compares: a plain --resume of the finished run keeps this module instead of fitting it again
    summary = {**summary, "iteration": progress["iteration"],
               "config": json.loads(json.dumps(dataclasses.asdict(cfg.rma), default=list))}
    interrupt = DeferredInterrupts(lambda what: f"wbc: {what}: the run stops once its export is written")
    with interrupt:
        save_policy(run_dir / "policy", policy)
        for stale in (run_dir / f"{PPO_EXPORT}.npz", run_dir / f"{PPO_EXPORT}.json"):  # this export supersedes it
            stale.unlink(missing_ok=True)
        _write_json(run_dir / "rma.json", summary)
        _write_json(run_dir / "progress.json", progress)
    if interrupt.requested:
        raise KeyboardInterrupt
    return summary["wall_s"]


def _adapted(run_dir: Path, cfg: TrainConfig, iteration: int) -> bool:
    """Whether the run's export already holds the module that phase 2 with `cfg.rma` fits on checkpoint `iteration`.

    Its ``rma.json`` records that config and iteration (a run begun before they were recorded: the export's
    ``adaptation`` block its rounds, window and layers), and its ``policy.json`` is that iteration's, with a module.
    """
    try:
        meta = json.loads((run_dir / "policy.json").read_text())
        summary = json.loads((run_dir / "rma.json").read_text())
        module, training = meta["adaptation"], meta["training"]
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
        return False
    if not isinstance(module, dict) or not isinstance(training, dict) or training.get("iteration") != iteration:
        return False
    rma = json.loads(json.dumps(dataclasses.asdict(cfg.rma), default=list))
    if isinstance(summary, dict) and "config" in summary:
        return summary["config"] == rma and summary.get("iteration") == iteration
    return {k: module.get(k) for k in ("history", "hidden_dims", "iterations")} == {
        k: rma[k] for k in ("history", "hidden_dims", "iterations")}


def _scenario(cfg: TrainConfig) -> dict[str, Any]:
    """The scenario the run trains on (`wbc.learned.train.preflight.scenario_record`)."""
    return scenario_record(cfg.env.scenario)


def _run_config(cfg: TrainConfig, resolved: dict[str, Any], point: ResumePoint | None, command: str
                ) -> dict[str, Any]:
    """The run's ``config.json``: its current settings, what it began with, and a history of its segments.

    A new run records its settings, inputs, provenance and its first segment. A resumed one keeps what the run began
    with (seed, inputs, provenance, start) and takes this segment's settings as the current ones: a later plain
    ``--resume`` takes the options left out from them (``--iterations``, ``--rma-iterations``, ``--threads``).
    Each segment says where it began and which settings it changed (``{field: [before, now]}``), and the command,
    package versions and git revision it ran under; its end (`_end_segment`) the iteration it reached.
    """
    segment = {"started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "command": command,
               "from_iteration": 0 if point is None else point.done, "max_iterations": cfg.max_iterations,
               "provenance": provenance()}
    if point is None:
        return {"train_config": resolved, "rsl_rl_config": rsl_rl_config(cfg), "seed": cfg.seed,
                "command": segment["command"], "scenario": _scenario(cfg), "inputs": input_files(cfg),
                "provenance": segment["provenance"], "started": segment["started"],
                "segments": [{**segment, "resumed": False, "changed": {}}]}
    data = json.loads((Path(cfg.run_dir) / "config.json").read_text())  # checked by check_run_dir
    changed = {field: [_at(point.saved, field), _at(resolved, field)] for field in config_diff(point.saved, resolved)}
    # a run begun before segments were recorded: its earlier segments are not known
    segments = data.get("segments") if isinstance(data.get("segments"), list) else []
    return {**data, "train_config": resolved, "rsl_rl_config": rsl_rl_config(cfg),
            "segments": [*segments, {**segment, "resumed": True, "changed": changed}]}


def _at(config: dict[str, Any], field: str) -> Any:
    """The value of a dotted field (`config_diff`'s ``env.nthread``) of a resolved config, or None."""
    for key in field.split("."):
        config = config.get(key) if isinstance(config, dict) else None
    return config


def _end_segment(run_dir: Path, fields: dict[str, Any]) -> None:
    """Record in ``config.json`` how this segment ended (the iteration it reached, its adaptation phase)."""
    path = run_dir / "config.json"
    data = json.loads(path.read_text())
    if isinstance(data.get("segments"), list) and data["segments"]:
        data["segments"][-1].update(fields)
        _write_json(path, data)
