"""Distillation: a policy of our observation and action form fitted to an expert's actions (DAgger's learning half).

`expert_action` turns any controller's `MotorCommand` into the action our policies would have to output to exert the
same joint torques at the same state: a policy commands ``q* = default_q + action_scale * a`` under its own PD gains
(``kp``, ``kd``, no velocity target, no feed-forward torque), so the torque it asks for is
``kp (q* - q) - kd dq``; matching the expert's ``kp_e (q_e - q) + kd_e (dq_e - dq) + tau_e`` at this state gives
``q* = q + (tau_expert + kd dq) / kp``. The match is exact at the instant of the label and drifts over the policy
period, while the policy holds its target and the expert would have updated its command; DAgger's later rounds show
the student the states its own drift leads to.

`fit_student` regresses a `StudentNet` (the same MLP and observation normaliser as our exported actors) onto the
aggregated (observation, expert action) pairs by mean squared error; `student_policy_file` exports it in the
torch-free `PolicyFile` format through the same path as every trained actor, so the arena, the viewer and the hardware
runner load a distilled policy as any other (`policy:PATH`). The collecting half, which plays the expert and the
student in the arena, is `wbc.tools.dagger`.

A student with memory (`FitConfig.history` H > 0) has the policy file's RMA form: an adaptation module reads the last
H normalised observations (oldest first, the window filled with the episode's first observation, as `ObsHistory`
does) and outputs a small latent z, which the actor reads beside the observation. The expert's internal state (the
MPC's gait clock: which legs swing) is absent from a single observation but shows in the recent joint motion and
previous actions, so the window lets the student tell the phases apart. Both networks are fitted end to end on the
expert's labels; the file declares z as extrinsics with no privileged parts and no encoder (the format's latent
learned from the history alone), with a note that it observes nothing privileged.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from wbc.errors import ConfigError
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.policy.policy_file import PolicyFile
from wbc.learned.train.export import policy_file_from_actor
from wbc.optional import require
from wbc.types import MotorCommand

torch = require("torch")

__all__ = ["FitConfig", "StudentNet", "expert_action", "fit_student", "history_index", "load_student", "save_student",
           "student_policy_file"]


def expert_action(command: MotorCommand, q: np.ndarray, dq: np.ndarray, *, default_q: np.ndarray,
                  action_scale: float, kp: np.ndarray, kd: np.ndarray) -> np.ndarray:
    """The policy action that asks for the expert command's joint torques at joint state (q, dq).

    Args:
        command: the expert's motor command at this state.
        q: joint positions the command was computed for [rad].
        dq: joint velocities the command was computed for [rad/s].
        default_q: the policy's joint defaults [rad].
        action_scale: the policy's action scale [rad per unit action].
        kp: the policy's position gains (all > 0).
        kd: the policy's velocity gains.

    Returns:
        The unclipped action, shape (num_joints,).

    Raises:
        ConfigError: a policy gain kp is not positive (no target would exert the torque).
    """
    kp = np.asarray(kp, dtype=np.float64)
    if np.any(kp <= 0.0):
        raise ConfigError(f"expert_action: the policy's kp must all be positive, got {kp.tolist()}")
    torque = command.kp * (command.q - q) + command.kd * (command.dq - dq) + command.tau
    target = q + (torque + kd * dq) / kp
    return (target - default_q) / action_scale


class _Normaliser:
    """What `policy_file_from_actor` reads of an observation normaliser: ``_mean``, ``_std``, ``eps``."""

    def __init__(self, mean: np.ndarray, std: np.ndarray, eps: float) -> None:
        self._mean = torch.as_tensor(mean, dtype=torch.float32)
        self._std = torch.as_tensor(std, dtype=torch.float32)
        self.eps = eps


def _mlp(sizes: tuple[int, ...]) -> Any:
    layers: list[Any] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True)):
        layers.append(torch.nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(torch.nn.ELU())
    return torch.nn.Sequential(*layers)


class StudentNet(torch.nn.Module):
    """An MLP on the normalised policy observation, exported like our actors (`policy_file_from_actor`).

    With a history (H > 0), an adaptation MLP maps the last H normalised observations, flattened oldest first, to a
    latent z of `z_dim`, and the actor reads [normalised observation, z].

    Args:
        obs_dim: observation size.
        num_actions: action size.
        hidden_dims: hidden layer sizes of the actor.
        mean, std: the observation normaliser (fixed; computed from the data by `fit_student`).
        eps: added to the std when normalising, as in the exported file's ``normalizer_eps``.
        history: observations the adaptation module reads (0: no memory, the actor reads the observation alone).
        z_dim: size of the latent z (with a history).
        adaptation_dims: hidden layer sizes of the adaptation module (with a history).
    """

    def __init__(self, obs_dim: int, num_actions: int, hidden_dims: tuple[int, ...], mean: np.ndarray,
                 std: np.ndarray, eps: float = 1e-2, *, history: int = 0, z_dim: int = 8,
                 adaptation_dims: tuple[int, ...] = (128,)) -> None:
        super().__init__()
        self.history = int(history)
        self.z_dim = int(z_dim) if self.history else 0
        self.adaptation_dims = tuple(adaptation_dims)
        self.mlp = _mlp((obs_dim + self.z_dim, *hidden_dims, num_actions))
        self.adaptation = _mlp((self.history * obs_dim, *adaptation_dims, self.z_dim)) if self.history else None
        self.obs_dim = obs_dim
        self.obs_normalizer = _Normaliser(mean, std, eps)

    def normalise(self, obs: Any) -> Any:
        """Observations as the networks see them (any leading shape)."""
        norm = self.obs_normalizer
        return (obs - norm._mean) / (norm._std + norm.eps)

    def forward(self, obs: Any, window: Any = None) -> Any:
        """Actions for a batch of raw observations (N, obs_dim) and, with a history, their raw windows (N, H, obs_dim).

        The window holds the last H observations, oldest first, the newest being `obs` itself.
        """
        x = self.normalise(obs)
        if self.adaptation is None:
            return self.mlp(x)
        if window is None:
            raise ConfigError("StudentNet: this student reads an observation history; pass its window")
        z = self.adaptation(self.normalise(window).reshape(window.shape[0], -1))
        return self.mlp(torch.cat([x, z], dim=-1))


def history_index(episode: np.ndarray, history: int) -> np.ndarray:
    """For each sample, the indices of its window: its episode's last `history` samples, oldest first.

    Samples are in time order within each episode; before an episode has `history` samples, the window repeats its
    first sample (as `ObsHistory.fill` does after a reset).

    Args:
        episode: (N,) episode id of each sample; an episode's samples are contiguous and in time order.
        history: window length H >= 1.

    Returns:
        (N, H) integer indices into the samples.
    """
    episode = np.asarray(episode)
    n = episode.size
    starts = np.ones(n, dtype=bool)
    starts[1:] = episode[1:] != episode[:-1]
    first = np.maximum.accumulate(np.where(starts, np.arange(n), 0))
    idx = np.arange(n)[:, None] - (history - 1) + np.arange(history)[None, :]
    return np.maximum(idx, first[:, None])


@dataclass(frozen=True, kw_only=True)
class FitConfig:
    """Supervised fit of the student.

    Attributes:
        hidden_dims: MLP sizes (our actors' by default).
        epochs: passes over the aggregated data per round.
        batch_size: samples per gradient step.
        learning_rate: Adam's step size.
        seed: seeds the weights' initialisation and the batch order.
        std_floor: the least standard deviation the observation normaliser divides by. An expert's own episodes
            barely move some inputs (its arm joints by 0.01 rad, gravity's z by 0.004): divided by that spread, the
            student's first deviation from the expert's states became an input of 25-70, and the student, never
            having seen one, fell within 0.6 s of every episode it drove.
        history: observations (policy ticks) the adaptation module reads, 0 for a memoryless student. 25 (0.5 s at
            50 Hz) spans 1.6 cycles of the MPC's trot (0.32 s, `wbc.mpc.gait.TROT`).
        z_dim: size of the latent the adaptation module passes to the actor.
        adaptation_dims: hidden layer sizes of the adaptation module.
    """

    hidden_dims: tuple[int, ...] = (256, 128, 64)
    epochs: int = 30
    batch_size: int = 512
    learning_rate: float = 1e-3
    seed: int = 0
    std_floor: float = 0.1
    history: int = 25
    z_dim: int = 8
    adaptation_dims: tuple[int, ...] = (128,)

    def __post_init__(self) -> None:
        if min(self.epochs, self.batch_size) < 1 or not self.hidden_dims or min(self.hidden_dims) < 1:
            raise ConfigError("FitConfig: epochs, batch_size and every hidden size must be >= 1")
        if not self.std_floor >= 0.0:
            raise ConfigError(f"FitConfig: std_floor must be >= 0, got {self.std_floor}")
        if not self.learning_rate > 0.0:
            raise ConfigError(f"FitConfig: learning_rate must be > 0, got {self.learning_rate}")
        if self.history < 0 or (self.history and (self.z_dim < 1 or min(self.adaptation_dims, default=1) < 1)):
            raise ConfigError("FitConfig: history must be >= 0, and with a history z_dim and every adaptation size "
                              ">= 1")


def fit_student(obs: np.ndarray, actions: np.ndarray, cfg: FitConfig, start: StudentNet | None = None, *,
                episode: np.ndarray | None = None) -> tuple[StudentNet, list[float]]:
    """Fit a student to (observation, action) pairs by mean squared error.

    Args:
        obs: (N, obs_dim) raw policy observations.
        actions: (N, num_actions) target actions (clipped to the policy's range by the caller).
        cfg: the fit.
        start: a student to continue from (its normaliser and sizes are kept), or None for a fresh one whose
            normaliser is the data's mean and standard deviation (at least `FitConfig.std_floor`).
        episode: (N,) episode id of each sample, the samples of an episode contiguous and in time order: each
            sample's window of the last `FitConfig.history` observations is built from them (`history_index`).
            Required with a history.

    Returns:
        The fitted student and its mean loss per epoch.

    Raises:
        ConfigError: no samples, shapes that do not match, or a history without `episode`.
    """
    obs = np.asarray(obs, dtype=np.float32)
    actions = np.asarray(actions, dtype=np.float32)
    if obs.ndim != 2 or actions.ndim != 2 or obs.shape[0] != actions.shape[0] or obs.shape[0] == 0:
        raise ConfigError(f"fit_student: need (N, obs) and (N, actions) with N >= 1, got {obs.shape} and "
                          f"{actions.shape}")
    gen = torch.Generator().manual_seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    if start is None:
        net = StudentNet(obs.shape[1], actions.shape[1], cfg.hidden_dims, obs.mean(axis=0),
                         np.maximum(obs.std(axis=0), cfg.std_floor), history=cfg.history, z_dim=cfg.z_dim,
                         adaptation_dims=cfg.adaptation_dims)
    else:
        net = start
    windows = None
    if net.history:
        if episode is None or np.shape(episode) != (obs.shape[0],):
            raise ConfigError(f"fit_student: a student with a history of {net.history} needs each sample's episode "
                              f"(N,), got {None if episode is None else np.shape(episode)}")
        windows = torch.from_numpy(history_index(episode, net.history))
    x, y = torch.from_numpy(obs), torch.from_numpy(actions)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    losses = []
    for _ in range(cfg.epochs):
        order = torch.randperm(x.shape[0], generator=gen)
        total, count = 0.0, 0
        for i in range(0, x.shape[0], cfg.batch_size):
            idx = order[i:i + cfg.batch_size]
            pred = net(x[idx]) if windows is None else net(x[idx], x[windows[idx]])
            loss = torch.nn.functional.mse_loss(pred, y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * idx.numel()
            count += idx.numel()
        losses.append(total / count)
    return net, losses


def student_policy_file(net: StudentNet, env: EnvConfig, *, task: str, extra: dict[str, Any]) -> PolicyFile:
    """The student as a `PolicyFile` (stage 3: it drives every joint of the robot, arm included).

    A student with a history exports its adaptation module as the file's (``adaptation``), and its latent z as the
    file's extrinsics with no privileged parts and no encoder: z only ever comes from the history.
    """
    pf = policy_file_from_actor(net, env, task=task, stage=3, extra=extra)
    if net.adaptation is None:
        return pf
    arrays, meta = dict(pf.arrays), dict(pf.meta)
    z = net.z_dim
    for i, m in enumerate(mod for mod in net.adaptation if isinstance(mod, torch.nn.Linear)):
        arrays[f"adaptation/{i}/weight"] = m.weight.detach().double().numpy()
        arrays[f"adaptation/{i}/bias"] = m.bias.detach().double().numpy()
    meta["extrinsics"] = {
        "dim": z, "hidden_dims": [], "privileged_parts": [],
        "note": "z is a latent learned from the observation history by the adaptation module, fitted end to end "
                "with the actor on the expert's actions; it observes nothing privileged"}
    meta["adaptation"] = {"history": net.history, "hidden_dims": list(net.adaptation_dims), "source": "distilled"}
    return PolicyFile(meta=meta, arrays=arrays)


def save_student(net: StudentNet, path: str | Path | BinaryIO) -> None:
    """Save a student (weights, normaliser, sizes) to continue fitting it later (`load_student`)."""
    norm = net.obs_normalizer
    hidden = tuple(m.out_features for m in net.mlp if isinstance(m, torch.nn.Linear))[:-1]
    num_actions = [m for m in net.mlp if isinstance(m, torch.nn.Linear)][-1].out_features
    torch.save({"state": net.state_dict(), "mean": norm._mean, "std": norm._std, "eps": norm.eps,
                "obs_dim": net.obs_dim, "num_actions": num_actions, "hidden_dims": hidden, "history": net.history,
                "z_dim": net.z_dim, "adaptation_dims": net.adaptation_dims}, path)


def load_student(path: str | Path) -> StudentNet:
    """A student saved by `save_student`."""
    saved = torch.load(path, map_location="cpu", weights_only=True)
    net = StudentNet(saved["obs_dim"], saved["num_actions"], tuple(saved["hidden_dims"]), saved["mean"].numpy(),
                     saved["std"].numpy(), saved["eps"], history=int(saved.get("history", 0)),
                     z_dim=int(saved.get("z_dim", 8)) or 8, adaptation_dims=tuple(saved.get("adaptation_dims", (128,))))
    net.load_state_dict(saved["state"])
    return net
