"""Torch-free checks of a training run before it builds its env: its input files and its run directory.

`check_inputs` loads the policy files a `TrainConfig` names (teacher, init_from, frozen_legs, student) and the expert
samples of a fine-tune; `check_run_dir` refuses to start a run over another one and reads what a resumed run
continues from (``config.json``, ``progress.json``, the newest ``model_<it>.pt``'s name); `check_checkpoint` loads
that checkpoint (with torch, the one check here that needs it). `check_run` makes them all, in the order a run does:
``wbc train --dry-run`` and `wbc.learned.train.train.train` call it, so a dry run refuses what the run would, naming
the file (and field). A run makes them holding its directory's lock (`locked_run_dir`, ``RUN_DIR/.lock``), which it
keeps to its end, so that two runs never share a directory; a dry run only checks that no run holds it
(`check_unlocked`).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import zipfile
import zlib
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from wbc.errors import ConfigError, NetworkMismatchError, WbcError
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.policy.policy_file import PolicyFile, PolicyFileError, load_policy
from wbc.learned.train.stages import TASKS
from wbc.learned.train.train_config import TrainConfig
from wbc.optional import require
from wbc.output_files import LOCK_FILE, DirectoryInUse, DirectoryLock, directory_holder, lock_directory
from wbc.robots.registry import get_robot
from wbc.scenario.scenario import load_scenario, resolve_scenario_path

__all__ = ["CHECKPOINT_KEY", "INPUTS", "LOCK_FILE", "RESUMABLE", "RESUMABLE_ENV", "ResumePoint", "check_checkpoint",
           "check_inputs", "check_run", "check_run_dir", "check_run_root", "check_unlocked", "checkpoint_identity",
           "checkpoint_iteration", "config_diff", "env_meta", "input_files", "input_path", "latest_checkpoint",
           "PPO_EXPORT", "load_input_policy", "lock_run_dir", "lacks_module", "playable_export",
           "locked_run_dir", "make_run_dir", "names_a_file", "read_expert_samples", "read_run_json",
           "saved_train_config", "scenario_record", "student_layout", "unreadable_fix", "unstarted_run"]

T = TypeVar("T")

RESUMABLE = ("max_iterations", "save_interval", "device", "torch_threads", "rma")
"""TrainConfig fields a resumed run may change; any other difference is refused."""

RESUMABLE_ENV = ("env.nthread",)
"""EnvConfig fields (dotted, as `config_diff` names them) a resumed run may change: the physics threads, which
split the robots between threads without changing any robot's result (a run on 1 or 2 threads saves the same
checkpoint, bit for bit)."""

INPUTS = ("teacher", "init_from", "frozen_legs", "student", "expert_data")
"""TrainConfig fields that name a file the run reads; a resumed run compares their content (sha256), not the path."""

_POLICY_INPUTS = ("teacher", "init_from", "frozen_legs", "student")
"""Of `INPUTS`, those that name a policy (either file of its ``.npz``/``.json`` pair, or their common stem)."""

_RUN_FILES = ("config.json", "progress.json", "policy.npz", "policy.json")
"""Files of a run directory that say it already holds a run (besides ``model_<it>.pt`` checkpoints)."""


PPO_EXPORT = "policy_ppo"
"""The stem of the export a run writes of a checkpoint before its adaptation phase, where its ``policy`` is playable.

A stage whose policy observes RMA's extrinsics is playable only with the adaptation module its phase 2 fits; a
checkpoint's export (periodic, or an interrupted run's) has none yet, and never replaces a ``policy`` that has one.
"""


def lacks_module(meta: Any) -> bool:
    """Whether a policy file's JSON (`meta`) observes RMA's extrinsics and has no adaptation module: not playable."""
    return (isinstance(meta, dict) and meta.get("extrinsics") is not None
            and not isinstance(meta.get("adaptation"), dict))


def playable_export(run_dir: str | Path) -> dict[str, Any] | None:
    """The JSON of a run's ``policy.json`` where it is playable (no extrinsics, or its adaptation module), else None."""
    try:
        meta = json.loads((Path(run_dir) / "policy.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return meta if isinstance(meta, dict) and not lacks_module(meta) else None


@dataclass(frozen=True)
class ResumePoint:
    """Where a resumed run continues from.

    Attributes:
        checkpoint: the newest ``model_<it>.pt``.
        done: iterations trained so far (the checkpoint's iteration + 1).
        saved: the ``train_config`` object of the run's ``config.json``.
        progress: ``progress.json`` (iteration, env_steps, wall_s), zeros when the file is absent; scaled to the
            checkpoint's iterations when the file counts another iteration (`note` then says so).
        note: what was reconciled, or None.
    """

    checkpoint: Path
    done: int
    saved: dict[str, Any]
    progress: dict[str, Any]
    note: str | None = None


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The ``model_<it>.pt`` with the highest iteration in `run_dir`, or None."""
    found = [(int(m.group(1)), p) for p in Path(run_dir).glob("model_*.pt")
             if (m := re.fullmatch(r"model_(\d+)\.pt", p.name))]
    return max(found)[1] if found else None


def checkpoint_iteration(checkpoint: Path) -> int:
    """The iteration a ``model_<it>.pt`` (as `latest_checkpoint` finds it) holds: ``<it>``."""
    return int(re.fullmatch(r"model_(\d+)\.pt", checkpoint.name).group(1))


def unstarted_run(run_dir: str | Path) -> bool:
    """Whether `run_dir` holds a training run interrupted before its first checkpoint.

    Such a run wrote its ``config.json`` (with a ``train_config``) and nothing it could continue from: no
    ``model_<it>.pt``, ``progress.json`` or export. It starts afresh, with or without ``--resume``.
    """
    run_dir = Path(run_dir)
    if latest_checkpoint(run_dir) is not None or any((run_dir / n).exists() for n in _RUN_FILES if n != "config.json"):
        return False
    try:
        data = json.loads((run_dir / "config.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(data, dict) and isinstance(data.get("train_config"), dict)


def input_path(field: str, path: str | Path) -> Path:
    """The absolute path an input of a run names: a policy's stem (``X/policy.npz`` and ``X/policy`` are one input)."""
    p = Path(path)
    if field in _POLICY_INPUTS and p.suffix in (".npz", ".json"):
        p = p.with_name(p.name[:-len(p.suffix)])
    return p.resolve()


def config_diff(saved: Any, given: Any, name: str = "") -> list[str]:
    """The dotted names of the fields in which two resolved configs (JSON objects) differ, e.g. ``env.num_envs``."""
    if isinstance(saved, dict) and isinstance(given, dict):
        return [field for key in sorted(set(saved) | set(given))
                for field in config_diff(saved.get(key), given.get(key), f"{name}.{key}" if name else key)]
    return [] if saved == given else [name]


def saved_train_config(run_dir: str | Path) -> dict[str, Any] | None:
    """The ``train_config`` object of a run's ``config.json``, or None where there is no readable one.

    A resumed run takes from it the settings its command line leaves out; `check_run_dir` refuses a damaged one.
    """
    try:
        data = json.loads((Path(run_dir) / "config.json").read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    saved = data.get("train_config") if isinstance(data, dict) else None
    return saved if isinstance(saved, dict) else None


def _input_hashes(field: str, value: str | Path) -> dict[str, str]:
    """The sha256 of the files an input names, by kind (``.npz``/``.json`` for a policy, ``file`` otherwise)."""
    path = input_path(field, value)
    files = {".npz": Path(f"{path}.npz"), ".json": Path(f"{path}.json")} if field in _POLICY_INPUTS else {"file": path}
    return {kind: _sha256(f) for kind, f in files.items() if f.is_file()}


def _recorded_hashes(field: str, recorded: dict[str, Any]) -> dict[str, str]:
    """`_input_hashes` of an input as ``config.json`` recorded it (`input_files`): its files' sha256 by kind."""
    hashes = recorded.get("sha256")
    if not isinstance(hashes, dict):
        return {}
    return {(Path(name).suffix if field in _POLICY_INPUTS else "file"): str(h) for name, h in hashes.items()}


def _same_input(field: str, saved: Any, given: Any, recorded: Any) -> bool:
    """Whether a resumed run reads the input it began with: the same content (sha256), wherever it now lies.

    A run directory may move, with the previous stage's export beside it: the input is the file's content, its path
    only reported. A run begun before the hashes were recorded compares the paths.
    """
    if saved is None or given is None:
        return saved is given
    if isinstance(recorded, dict) and _recorded_hashes(field, recorded):
        return _input_hashes(field, given) == _recorded_hashes(field, recorded)
    if isinstance(recorded, dict) and isinstance(recorded.get("path"), str):  # where it was, resolved at the start
        return Path(recorded["path"]) == input_path(field, given)
    return isinstance(saved, str) and input_path(field, saved) == input_path(field, given)


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def scenario_record(path: str | Path) -> dict[str, Any]:
    """The scenario file a run plays, as its ``config.json`` and its exports' ``training`` block record it.

    ``path`` (resolved) and ``sha256``, the sha256 of the file's bytes (None where it cannot be read), which a comment
    or a layout change alters; ``name``, ``version`` and ``content_hash``, the scenario's as the arena names it
    (`wbc.scenario.scenario.load_scenario`: ``trials.csv``, ``summary.json``, ``wbc scenario check`` and
    ``scenarios/published.toml`` give its content hash, the sha256 of its parsed content,
    `wbc.scenario.scenario.content_hash`), None where the file does not load.
    """
    resolved = resolve_scenario_path(path).resolve()
    try:
        digest: str | None = hashlib.sha256(resolved.read_bytes()).hexdigest()
    except OSError:
        digest = None
    try:
        scenario = load_scenario(resolved)
        named = {"name": scenario.name, "version": scenario.version, "content_hash": scenario.hash}
    except (WbcError, OSError):
        named = {"name": None, "version": None, "content_hash": None}
    return {"path": str(resolved), "sha256": digest, **named}


def input_files(cfg: TrainConfig) -> dict[str, dict[str, Any]]:
    """The files a run reads, for its ``config.json``: a resumed run refuses inputs that changed since it began.

    Returns:
        For each `INPUTS` field that names a file: ``{"path": the resolved path (a policy's stem), "sha256":
        {file: its sha256}}``, over the files that exist (a policy's ``.npz`` and ``.json``).
    """
    found: dict[str, dict[str, Any]] = {}
    for field in INPUTS:
        value = getattr(cfg, field)
        if value is None:
            continue
        path = input_path(field, value)
        files = [Path(f"{path}.npz"), Path(f"{path}.json")] if field in _POLICY_INPUTS else [path]
        found[field] = {"path": str(path), "sha256": {str(f): _sha256(f) for f in files if f.is_file()}}
    return found


def _other_input(field: str, saved: Any, given: Any, recorded: Any, config: Path) -> ConfigError:
    """The refusal of a resume whose input `field` is not the one the run began with (`_same_input`).

    It names the file the run reads now and the one ``config.json`` recorded; a file of the same path whose content
    changed is said as such (the previous stage trained again).
    """
    if saved is None or given is None:
        return ConfigError(f"--resume: {config} differs from this run's config in ['{field}'] (the run began "
                           f"{'without' if saved is None else 'with'} one, this run has "
                           f"{'none' if given is None else given}): give the run's own options, or leave them out")
    now = input_path(field, given)
    was = recorded.get("path") if isinstance(recorded, dict) else saved
    hashes = _recorded_hashes(field, recorded) if isinstance(recorded, dict) else {}
    if hashes and was is not None and Path(str(was)) == now:
        kind, before = next((k, h) for k, h in hashes.items() if _input_hashes(field, given).get(k) != h)
        name = Path(f"{now}{kind}") if kind != "file" else now
        found = _input_hashes(field, given).get(kind)
        return ConfigError(f"--resume: {name} ({field}) changed since the run began: {config} inputs.{field} "
                           f"records sha256 {before[:16]}..., the file's is now "
                           f"{found[:16] + '...' if found else 'missing'}; the checkpoints learnt from the earlier "
                           "file: restore it, or start a new run under another --run-root")
    how = "sha256" if hashes else "path"
    return ConfigError(f"--resume: {field}: this run reads {now}, whose {'content' if hashes else 'path'} is not the "
                       f"one {config} records ({was}, compared by {how}): give the file the run began with (moved or "
                       "copied, its content is the same), or start a new run under another --run-root")


def check_run_root(run_dir: str | Path) -> None:
    """Refuse a run directory that cannot be made or written.

    A file stands where it, or a folder above it, would be; or the nearest folder that exists is not this user's to
    write (``os.access``).

    Raises:
        ConfigError: naming ``--run-root`` and the file in the way, or the folder that cannot be written.
    """
    for path in (Path(run_dir), *Path(run_dir).parents):
        if path.exists():
            if not path.is_dir():
                raise ConfigError(f"--run-root: {path} is a file, not a directory, so the run directory {run_dir} "
                                  "cannot be made there; give a directory")
            if not os.access(path, os.W_OK | os.X_OK):
                raise ConfigError(f"--run-root: {path} cannot be written by this user, so the run directory "
                                  f"{run_dir} cannot be {'written' if path == Path(run_dir) else 'made'}; give a "
                                  "directory this user can write")
            return


def _in_use(run_dir: str | Path, held: DirectoryInUse) -> ConfigError:
    """The refusal of a run directory another run holds, naming it and the holder's pid (as its lock file says)."""
    holder = f"pid {held.pid}" if held.pid is not None else "its pid not yet written"
    return ConfigError(f"{run_dir} is in use by another run ({holder}, holding {held.path}): wait for it to end, or "
                       "choose another --run-root")


def lock_run_dir(run_dir: str | Path) -> DirectoryLock:
    """Lock a run directory for this process, or refuse it: another run holds it (`wbc.output_files.lock_directory`).

    Raises:
        ConfigError: another process holds the lock (the message names the directory and its pid), or the lock file
            cannot be made or locked.
    """
    path = Path(run_dir) / LOCK_FILE
    try:
        return lock_directory(run_dir)
    except DirectoryInUse as held:
        raise _in_use(run_dir, held) from None
    except OSError as exc:
        raise ConfigError(f"--run-root: cannot make or lock the run directory's lock file {path} "
                          f"({exc.strerror or exc}): a run must hold its directory alone; give a directory this user "
                          "can write, on a file system that takes locks") from None


def check_unlocked(run_dir: str | Path) -> None:
    """Refuse a run directory another run holds (`lock_run_dir`), without holding it: a dry run's check.

    Raises:
        ConfigError: another process holds the lock, naming the directory and its pid.
    """
    held = directory_holder(run_dir)
    if held is not None:
        raise _in_use(run_dir, held)


@contextmanager
def locked_run_dir(run_dir: str | Path, check: Callable[[], T]) -> Iterator[T]:
    """Hold a run directory's lock (`lock_run_dir`) from before `check` reads it to the end of the block.

    A directory that exists is locked first, then checked. One that does not has nothing to read: it is checked
    first (a refused run then leaves nothing behind), made, locked, and checked again, which refuses a run begun in
    it between the two.

    Args:
        run_dir: the run directory.
        check: the run's checks of its directory and inputs (`check_run`); what it returns is the block's value.

    Raises:
        ConfigError: another run holds the directory (naming it and the holder's pid); a directory that cannot be
            made or written (`check_run_root`); what `check` raises.
    """
    run_dir = Path(run_dir)
    check_run_root(run_dir)
    if not run_dir.is_dir():
        check()
        make_run_dir(run_dir)
    with lock_run_dir(run_dir):
        yield check()


def make_run_dir(run_dir: str | Path) -> None:
    """Make a run directory, or raise a `ConfigError` naming ``--run-root`` and why it cannot be made."""
    try:
        Path(run_dir).mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--run-root: cannot make the run directory {run_dir} ({exc.strerror or exc}); give a "
                          "directory this user can write") from None


def names_a_file(path: str | Path) -> bool:
    """Whether `path` is a file, or the common stem of a policy's ``.npz``/``.json`` pair."""
    p = Path(path)
    return p.is_file() or Path(f"{p}.npz").is_file() or Path(f"{p}.json").is_file()


def load_input_policy(path: str | Path, role: str, option: str | None = None) -> PolicyFile:
    """Load a policy file a run reads, or raise a `ConfigError` saying what is wrong.

    Args:
        path: the file (either of its ``.npz``/``.json`` pair, or their stem).
        role: what it is to the run, for a default input (the previous stage's export): the message then says to
            train that stage first.
        option: the option that named the file (``--teacher``, ``--fine-tune``), named in the message instead.
    """
    try:
        return load_policy(path)
    except PolicyFileError as exc:
        if option is not None:
            raise ConfigError(f"{option} {path}: not usable: {exc}; give a policy file that a run exported (its "
                              "policy.npz, beside its policy.json)") from None
        raise ConfigError(f"{role} is not usable: {exc}. Train the previous stage first, or pass its path") from None


def check_inputs(cfg: TrainConfig, options: Mapping[str, str] | None = None) -> PolicyFile | None:
    """Check the files `cfg` reads: they load, and they drive the robot and arm the run needs.

    Args:
        cfg: the run.
        options: for each `INPUTS` field that an option of ``wbc train`` set, that option (``{"teacher":
            "--teacher"}``, ``{"student": "--fine-tune", ...}``): a refusal names it, not the field, and the others
            are defaults (the previous stage's export).

    Returns:
        The student (`TrainConfig.student`), loaded, or None.

    Raises:
        ConfigError: a file is missing or unusable, drives another robot or arm, or the expert samples of a fine-tune
            come from another task or robot.
        NetworkMismatchError: a student that does not read its own history (`student_layout`).
    """
    options = options or {}

    def named(field: str, default: str) -> str:
        """How a refusal names an input: by the option that set it, else as `default` says."""
        return f"{options[field]} {getattr(cfg, field)}" if field in options else default

    if cfg.init_from is not None:
        load_input_policy(cfg.init_from, "the policy this run starts from (init_from)", options.get("init_from"))
    if cfg.frozen_legs is not None:
        if cfg.extrinsics_dim > 0:
            raise ConfigError("with frozen_legs the actor observes the robot's measurements only: set "
                              "extrinsics_dim=0 (RMA phase 2 is not built for a part of a composite policy)")
        legs = load_input_policy(cfg.frozen_legs, "the frozen leg policy (frozen_legs)", options.get("frozen_legs"))
        if legs.meta["robot"] != cfg.env.robot or legs.meta["arm_mode"] != cfg.env.teacher_arm_mode:
            raise ConfigError(f"{named('frozen_legs', f'frozen leg policy {cfg.frozen_legs}')} drives "
                              f"{legs.meta['robot']} with arm {legs.meta['arm_mode']!r}; this run needs "
                              f"{cfg.env.robot} with arm {cfg.env.teacher_arm_mode!r} (EnvConfig.teacher_arm_mode)")
    student = None
    if cfg.student is not None:
        student = load_input_policy(cfg.student, "the student to fine-tune (student)", options.get("student"))
        if cfg.extrinsics_dim != 0 or cfg.frozen_legs is not None or cfg.init_from is not None:
            raise ConfigError("fine-tuning a student: the actor is the student (extrinsics_dim=0, no frozen_legs, "
                              "no init_from)")
        try:
            student_layout(student)  # one that reads its own history
        except NetworkMismatchError as exc:
            if "student" not in options:
                raise
            raise NetworkMismatchError(f"{named('student', '')}: {exc}") from None
        _check_student_env(student, cfg, named("student", f"student {cfg.student}"))
    if cfg.expert_data is not None:
        if student is None or cfg.bc is None:
            raise ConfigError("expert_data is the BC term's target when fine-tuning a student: set student and bc too")
        _check_expert_data(cfg, student, named("expert_data", f"expert samples {cfg.expert_data}"))
        return student
    if cfg.bc is None:
        return student
    if cfg.teacher is None:
        raise ConfigError("TrainConfig.bc is set but no teacher policy file is given")
    if "teacher" in options:
        teacher = load_input_policy(cfg.teacher, "the teacher", options["teacher"])
    else:
        try:
            teacher = load_policy(cfg.teacher)
        except PolicyFileError as exc:
            raise ConfigError(f"stage {cfg.stage} learns from the previous stage's policy, which is not usable: "
                              f"{exc}. Train the previous stage first, or pass --teacher PATH") from None
    arm = cfg.env.arm_mode if cfg.student is not None else cfg.env.teacher_arm_mode  # a student teaches itself
    if teacher.meta["robot"] != cfg.env.robot or teacher.meta["arm_mode"] != arm:
        what = "the fine-tune" if cfg.student is not None else f"stage {cfg.stage}"
        raise ConfigError(f"{named('teacher', f'teacher {cfg.teacher}')} drives {teacher.meta['robot']} with arm "
                          f"{teacher.meta['arm_mode']!r}; {what} needs {cfg.env.robot} with arm {arm!r}")
    return student


def student_layout(policy: PolicyFile) -> tuple[int, int, int]:
    """(D, H, z): observation size, window length and latent size of a student that reads its own history.

    Raises:
        NetworkMismatchError: the file's latent does not come from its observation history alone (it has an
            encoder of privileged observations, or no adaptation module).
    """
    meta = policy.meta
    extr, adapt = meta.get("extrinsics"), meta.get("adaptation")
    if extr is None or adapt is None or policy.layers("encoder") or extr.get("privileged_parts"):
        raise NetworkMismatchError(
            "fine-tuning takes a student whose latent z comes from its observation history alone (a DAgger student, "
            "`wbc train --teacher mpc`, with --history > 0); this file's z is "
            + ("absent" if extr is None else "read from privileged observations"))
    d = int(policy.arrays["obs_mean"].shape[0])
    return d, int(adapt["history"]), int(extr["dim"])


def env_meta(env: EnvConfig, joints: np.ndarray | None = None) -> dict[str, Any]:
    """What a policy file says of the env it was trained in: the numbers its inputs and outputs mean.

    Robot, arm mode, observation scales, action scale and clip, joint defaults and gains (of `joints`, default all),
    policy period.
    """
    desc = get_robot(env.robot, env.arm_mode)
    idx = np.arange(desc.num_joints) if joints is None else np.asarray(joints, dtype=int)
    kp, kd = env.gains(desc.num_joints)
    return {
        "robot": env.robot, "arm_mode": env.arm_mode,
        "obs_scales": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(env.obs_scales).items()},
        "action_scale": env.action_scale, "clip_actions": env.clip_actions,
        "default_q": desc.nominal_q[idx].tolist(), "kp": kp[idx].tolist(), "kd": kd[idx].tolist(),
        "policy_dt": env.policy_dt,
    }


def _check_student_env(student: PolicyFile, cfg: TrainConfig, name: str) -> None:
    """The env must give the student the observations and motor law it was made for: the same numbers mean the same.

    `name` is how a refusal names the student (``--fine-tune PATH``).
    """
    meta, given = student.meta, env_meta(cfg.env)
    for key, value in given.items():
        exact = key in ("robot", "arm_mode", "obs_scales")
        if (meta[key] != value) if exact else not np.allclose(meta[key], value):
            raise ConfigError(f"{name}: its {key} is {meta[key]}, the fine-tune's env gives {value} "
                              f"(EnvConfig); a student fine-tuned in another env would read other numbers than it was "
                              "trained on: fine-tune it on its own task's env")


def read_expert_samples(path: str | Path, name: str | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A DAgger run's ``data.npz``: (obs (N, D), actions (N, A), episode (N,)), N >= 1.

    `name` is how a refusal names the file (default ``expert samples PATH``; ``--expert-data PATH`` for the option).

    Raises:
        ConfigError: the file is missing or unreadable, lacks one of the arrays, or their shapes disagree.
    """
    name = name or f"expert samples {path}"
    try:
        data = np.load(path)
        if not isinstance(data, np.lib.npyio.NpzFile):  # a single array (.npy)
            raise ValueError("a single array, not an archive of arrays")
        with data:
            arrays = {k: data[k] for k in ("obs", "actions", "episode") if k in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
        raise ConfigError(f"{name}: cannot be read ({exc}); give a DAgger run's data.npz") from None
    missing = [k for k in ("obs", "actions", "episode") if k not in arrays]
    if missing:
        raise ConfigError(f"{name}: no {', '.join(missing)} array; give a DAgger run's data.npz "
                          "(obs, actions, episode)")
    obs, actions, episode = arrays["obs"], arrays["actions"], arrays["episode"]
    n = obs.shape[0] if obs.ndim else 0
    if obs.ndim != 2 or actions.ndim != 2 or actions.shape[0] != n or episode.shape != (n,) or n == 0:
        raise ConfigError(f"{name}: obs {obs.shape}, actions {actions.shape} and episode "
                          f"{episode.shape} do not describe the same N >= 1 samples")
    return obs, actions, episode


def _check_expert_data(cfg: TrainConfig, student: PolicyFile, name: str) -> None:
    """The expert's samples: a DAgger run's of the fine-tune's task (and robot), readable, for the student's actions.

    Their task is the one the DAgger run's ``config.json`` beside them names, when there is one. `name` is how a
    refusal names the file (``--expert-data PATH``).
    """
    path = Path(cfg.expert_data)
    if not path.is_file():
        raise ConfigError(f"{name}: no such file; give a DAgger run's data.npz")
    config = path.parent / "config.json"
    if config.is_file():  # a DAgger run's directory: its config names the task the samples were collected on
        try:
            task = json.loads(config.read_text())["dagger_config"]["task"]
        except (OSError, ValueError, KeyError, TypeError):
            task = None
        if isinstance(task, str) and task != cfg.task:
            robot = TASKS[task].robot if task in TASKS else "an unknown robot"
            raise ConfigError(f"{name}: collected on task {task!r} ({robot}; {config} "
                              f"dagger_config.task), the fine-tune is of task {cfg.task!r} ({cfg.env.robot}): give a "
                              f"DAgger run's data.npz of task {cfg.task!r}")
    obs, actions, _ = read_expert_samples(path, name)
    # the actor is the student: its inputs and outputs are the student's
    for what, have, actor in (("actions", actions.shape[1], student.num_actions),
                              ("observations", obs.shape[1], int(student.arrays["obs_mean"].shape[0]))):
        if have != actor:
            raise ConfigError(f"{name}: their {what} have {have} entries, the actor has {actor} (the "
                              f"student {cfg.student}); give the data of a DAgger run on this robot")


def read_run_json(path: Path, what: str) -> Any:
    """A JSON file of a run directory that ``--resume`` reads, or a `ConfigError` naming it and what is wrong.

    Args:
        path: the file.
        what: what to do when it is missing (the end of the message).
    """
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"--resume: {path}: no such file; {what}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"--resume: {path}: not readable ({exc})") from None
    except ValueError as exc:
        raise ConfigError(f"--resume: {path}: not JSON ({exc}); the run directory is damaged: restore the file or "
                          "start a new run under another --run-root") from None


def check_run_dir(cfg: TrainConfig, *, resume: bool) -> ResumePoint | None:
    """Check the run directory before anything is written or built.

    Args:
        cfg: the run.
        resume: whether the run continues the one in ``cfg.run_dir``.

    Returns:
        Where a resumed run continues from, or None for a run that starts at iteration 0: a new run, or one
        interrupted before its first checkpoint (`unstarted_run`; its ``config.json`` is then written anew).

    Raises:
        ConfigError: a run directory that cannot be made (`check_run_root`); a new run in a directory that holds a
            run; a resumed run without a checkpoint, with a missing or
            damaged ``config.json`` or ``progress.json``, with another config, or whose input files changed since it
            began (`input_files`).
    """
    run_dir = Path(cfg.run_dir)
    check_run_root(run_dir)
    if unstarted_run(run_dir):
        return None
    checkpoint = latest_checkpoint(run_dir)
    if not resume:
        held = [n for n in _RUN_FILES if (run_dir / n).exists()] + ([checkpoint.name] if checkpoint else [])
        if held:
            raise ConfigError(f"{run_dir} already holds a training run ({', '.join(held)}); pass --resume to continue "
                              "it or choose another --run-root")
        return None
    if checkpoint is None:
        raise ConfigError(f"--resume: no model_<it>.pt checkpoint in {run_dir}; start the run without --resume")
    config = run_dir / "config.json"
    data = read_run_json(config, "the run directory is not a complete run: start a new run under another --run-root")
    saved = data.get("train_config") if isinstance(data, dict) else None
    if not isinstance(saved, dict):
        raise ConfigError(f"--resume: {config}: train_config: missing or not an object; the run directory is damaged: "
                          "start a new run under another --run-root")
    resolved = json.loads(json.dumps(asdict(cfg), default=list))
    # where the run lies is not part of its config (a run directory may move), and an input is the file it names
    diff = [field for key in sorted(resolved) if key not in (*RESUMABLE, "run_dir", *INPUTS)
            for field in config_diff(saved.get(key), resolved[key], key) if field not in RESUMABLE_ENV]
    inputs = data.get("inputs")
    recorded = inputs if isinstance(inputs, dict) else {}
    if diff:
        raise ConfigError(f"--resume: {config} differs from this run's config in {diff}: give the run's own options, "
                          "or leave them out (a resumed run takes the ones not given from its config.json)")
    for field in INPUTS:
        if not _same_input(field, saved.get(field), resolved[field], recorded.get(field)):
            raise _other_input(field, saved.get(field), resolved[field], recorded.get(field), config)
    done = checkpoint_iteration(checkpoint) + 1
    progress: dict[str, Any] = {"iteration": done - 1, "env_steps": 0, "wall_s": 0.0}
    path = run_dir / "progress.json"
    if path.exists():
        progress = read_run_json(path, "")
        kinds = {"iteration": int, "env_steps": int, "wall_s": (int, float)}
        if not isinstance(progress, dict):
            raise ConfigError(f"--resume: {path}: not a JSON object; restore it or delete it (the counts restart)")
        for key, kind in kinds.items():
            value = progress.get(key)
            if not isinstance(value, kind) or isinstance(value, bool) or not math.isfinite(value) or value < 0:
                raise ConfigError(f"--resume: {path}: {key}: missing, negative or not a finite number; restore it or "
                                  "delete the file (the counts restart)")
        counted = progress["iteration"] + 1
        if counted != done:
            # its counts are of another checkpoint (a newer one deleted, or an interruption between a checkpoint and
            # its progress): every iteration steps each env the same number of times, so the steps scale exactly;
            # the wall time is the same share of it, an estimate
            progress = {"iteration": done - 1, "env_steps": round(progress["env_steps"] * done / counted),
                        "wall_s": progress["wall_s"] * done / counted}
            note = (f"{path} counts {counted} iterations, {checkpoint.name} holds {done}: its env steps and wall time "
                    f"are scaled to {done} iterations ({progress['env_steps']:,} steps; the wall time an estimate)")
            return ResumePoint(checkpoint=checkpoint, done=done, saved=saved, progress=progress, note=note)
    return ResumePoint(checkpoint=checkpoint, done=done, saved=saved, progress=progress)


CHECKPOINT_KEY = "wbc"
"""The key of a checkpoint's rsl-rl ``infos`` under which a run records what it is (`checkpoint_identity`)."""


def checkpoint_identity(cfg: TrainConfig, iteration: int) -> dict[str, Any]:
    """What a checkpoint of `cfg`'s run at `iteration` is: the run it belongs to, which ``--resume`` compares.

    Its task, stage, baseline and variant, the robot and arm mode it trains, and its iteration (the ``<it>`` of its
    ``model_<it>.pt``). A checkpoint copied from another run, or renamed, then says so (`check_checkpoint`).
    """
    return {"task": cfg.task, "stage": cfg.stage, "baseline": cfg.baseline, "variant": cfg.variant,
            "robot": cfg.env.robot, "arm_mode": cfg.env.arm_mode, "iteration": iteration}


def check_checkpoint(path: Path, cfg: TrainConfig | None = None) -> None:
    """Refuse a checkpoint rsl-rl cannot load (a truncated one, another program's), or another run's, before training.

    It needs torch (the ``train`` extra), as the run does.

    The run is not resumed from the checkpoint before it on its own: the file may be whole and unreadable here only
    (pickled by another version), and the resumed run would write over it when it reached its iteration again. The
    message names the checkpoint before it, from which a resume continues once the file is moved away.

    A checkpoint's own iteration (rsl-rl's ``iter``) must be its name's ``<it>``, and what it records of its run
    (`checkpoint_identity`, written since runs record it) must be `cfg`'s: a checkpoint of another task, stage,
    baseline, robot or arm mode copied into the run directory is refused, naming the fields that differ. A checkpoint
    written before runs recorded it is taken on its iteration alone.

    Raises:
        ConfigError: naming the file (and the field), and what to do.
    """
    torch = require("torch")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # noqa: BLE001 - torch raises anything from a damaged pickle
        raise ConfigError(f"--resume: {path}: not a readable checkpoint ({type(exc).__name__}: "
                          f"{str(exc).splitlines()[0] if str(exc) else 'no detail'}); {unreadable_fix(path)}, or "
                          "start a new run under another --run-root") from None
    if not isinstance(saved, dict) or not isinstance(saved.get("iter"), int):
        raise ConfigError(f"--resume: {path}: iter: missing; not an rsl-rl checkpoint: {unreadable_fix(path)}, or "
                          "start a new run under another --run-root")
    named = checkpoint_iteration(path)
    infos = saved.get("infos")
    recorded = infos.get(CHECKPOINT_KEY) if isinstance(infos, dict) else None
    if cfg is not None and isinstance(recorded, dict):  # what it says it is, compared first: it names the most
        expected = checkpoint_identity(cfg, named)
        differ = [f"{key} {recorded.get(key)!r} (this run: {value!r})" for key, value in expected.items()
                  if recorded.get(key) != value]
        if differ:
            raise ConfigError(f"--resume: {path}: a checkpoint of another run: {', '.join(differ)}: "
                              f"{unreadable_fix(path)}, or start a new run under another --run-root")
    if saved["iter"] != named:
        raise ConfigError(f"--resume: {path}: iter: {saved['iter']}, not the {named} its name says (a checkpoint "
                          f"renamed or copied from another run): {unreadable_fix(path)}, or start a new run under "
                          "another --run-root")


def unreadable_fix(path: Path) -> str:
    """What to do with a newest checkpoint `check_checkpoint` refuses: the checkpoint before it, or none."""
    before = [(checkpoint_iteration(p), p) for p in path.parent.glob("model_*.pt")
              if re.fullmatch(r"model_(\d+)\.pt", p.name) and checkpoint_iteration(p) < checkpoint_iteration(path)]
    if not before:
        return "it is the run's only checkpoint: restore it"
    it, previous = max(before)
    return (f"move it out of the run directory (or delete it) to resume from {previous.name}, the newest checkpoint "
            f"before it (training again from iteration {it + 1})")


def check_inputs_settled(cfg: TrainConfig, options: Mapping[str, str] | None = None) -> None:
    """Refuse an input policy file whose run directory another run holds: a run still training, whose export it is.

    Stage 2 started while stage 1 trains would learn from whatever stage 1 exported last (before its adaptation
    phase, none of it), and its resume would then be refused, the teacher having changed since.

    Raises:
        ConfigError: naming the input, the option that set it (or the default it is) and the holder's pid.
    """
    options = options or {}
    for field in ("teacher", "init_from", "frozen_legs", "student", "expert_data"):
        path = getattr(cfg, field, None)
        if path is None or Path(path).parent.resolve() == Path(cfg.run_dir).resolve():
            continue
        held = directory_holder(Path(path).parent)
        if held is not None:
            holder = f"pid {held.pid}" if held.pid is not None else "its pid not yet written"
            given = f" ({options[field]})" if field in options else ""
            raise ConfigError(f"the {field.replace('_', ' ')}{given} {path} is the export of a run still training in "
                              f"{Path(path).parent} ({holder}), which replaces it as it trains: wait for that run to "
                              "end, then start this one")


def check_run(cfg: TrainConfig, *, resume: bool, options: Mapping[str, str] | None = None,
              default_input_missing: Callable[[ConfigError], None] | None = None) -> ResumePoint | None:
    """Every check a run makes before it builds its env: its run directory, its input files, its checkpoint.

    `wbc.learned.train.train.train` calls it before it trains, ``wbc train --dry-run`` instead of training.

    Args:
        cfg: the run.
        resume: whether the run continues the one in ``cfg.run_dir``.
        options: the options that set its input files, named in a refusal (`check_inputs`).
        default_input_missing: called with the refusal of an input file instead of raising it, for a dry run whose
            inputs are all the defaults (the previous stage's export, which may be trained after the dry run).

    Returns:
        Where a resumed run continues from (`check_run_dir`), or None.

    Raises:
        ConfigError: what `check_run_dir`, `check_inputs` and `check_checkpoint` refuse.
        NetworkMismatchError: a student that does not read its own history (`student_layout`).
    """
    point = check_run_dir(cfg, resume=resume)
    check_inputs_settled(cfg, options)
    try:
        check_inputs(cfg, options)
    except ConfigError as exc:
        if default_input_missing is None:
            raise
        default_input_missing(exc)
    if point is not None:
        check_checkpoint(point.checkpoint, cfg)
    return point
