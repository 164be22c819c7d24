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
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wbc.errors import ConfigError
from wbc.learned.env.env_config import EnvConfig
from wbc.learned.policy.policy_file import PolicyFile
from wbc.learned.train.export import policy_file_from_actor
from wbc.optional import require
from wbc.types import MotorCommand

torch = require("torch")

__all__ = ["FitConfig", "StudentNet", "expert_action", "fit_student", "load_student", "save_student",
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


class StudentNet(torch.nn.Module):
    """An MLP on the normalised policy observation, exported like our actors (`policy_file_from_actor`).

    Args:
        obs_dim: observation size.
        num_actions: action size.
        hidden_dims: hidden layer sizes.
        mean, std: the observation normaliser (fixed; computed from the data by `fit_student`).
        eps: added to the std when normalising, as in the exported file's ``normalizer_eps``.
    """

    def __init__(self, obs_dim: int, num_actions: int, hidden_dims: tuple[int, ...], mean: np.ndarray,
                 std: np.ndarray, eps: float = 1e-2) -> None:
        super().__init__()
        layers: list[Any] = []
        sizes = (obs_dim, *hidden_dims)
        for a, b in zip(sizes[:-1], sizes[1:], strict=True):
            layers += [torch.nn.Linear(a, b), torch.nn.ELU()]
        layers.append(torch.nn.Linear(sizes[-1], num_actions))
        self.mlp = torch.nn.Sequential(*layers)
        self.obs_dim = obs_dim
        self.obs_normalizer = _Normaliser(mean, std, eps)

    def forward(self, obs: Any) -> Any:
        """Actions for a batch of raw observations."""
        norm = self.obs_normalizer
        return self.mlp((obs - norm._mean) / (norm._std + norm.eps))


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
    """

    hidden_dims: tuple[int, ...] = (256, 128, 64)
    epochs: int = 30
    batch_size: int = 512
    learning_rate: float = 1e-3
    seed: int = 0
    std_floor: float = 0.1

    def __post_init__(self) -> None:
        if min(self.epochs, self.batch_size) < 1 or not self.hidden_dims or min(self.hidden_dims) < 1:
            raise ConfigError("FitConfig: epochs, batch_size and every hidden size must be >= 1")
        if not self.std_floor >= 0.0:
            raise ConfigError(f"FitConfig: std_floor must be >= 0, got {self.std_floor}")
        if not self.learning_rate > 0.0:
            raise ConfigError(f"FitConfig: learning_rate must be > 0, got {self.learning_rate}")


def fit_student(obs: np.ndarray, actions: np.ndarray, cfg: FitConfig,
                start: StudentNet | None = None) -> tuple[StudentNet, list[float]]:
    """Fit a student to (observation, action) pairs by mean squared error.

    Args:
        obs: (N, obs_dim) raw policy observations.
        actions: (N, num_actions) target actions (clipped to the policy's range by the caller).
        cfg: the fit.
        start: a student to continue from (its normaliser is kept), or None for a fresh one whose normaliser is the
            data's mean and standard deviation (at least `FitConfig.std_floor`).

    Returns:
        The fitted student and its mean loss per epoch.

    Raises:
        ConfigError: no samples, or shapes that do not match.
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
                         np.maximum(obs.std(axis=0), cfg.std_floor))
    else:
        net = start
    x, y = torch.from_numpy(obs), torch.from_numpy(actions)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    losses = []
    for _ in range(cfg.epochs):
        order = torch.randperm(x.shape[0], generator=gen)
        total, count = 0.0, 0
        for i in range(0, x.shape[0], cfg.batch_size):
            idx = order[i:i + cfg.batch_size]
            loss = torch.nn.functional.mse_loss(net(x[idx]), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * idx.numel()
            count += idx.numel()
        losses.append(total / count)
    return net, losses


def student_policy_file(net: StudentNet, env: EnvConfig, *, task: str, extra: dict[str, Any]) -> PolicyFile:
    """The student as a `PolicyFile` (stage 3: it drives every joint of the robot, arm included)."""
    return policy_file_from_actor(net, env, task=task, stage=3, extra=extra)


def save_student(net: StudentNet, path: str | Path) -> None:
    """Save a student (weights, normaliser, sizes) to continue fitting it later (`load_student`)."""
    norm = net.obs_normalizer
    hidden = tuple(m.out_features for m in net.mlp if isinstance(m, torch.nn.Linear))[:-1]
    num_actions = [m for m in net.mlp if isinstance(m, torch.nn.Linear)][-1].out_features
    torch.save({"state": net.state_dict(), "mean": norm._mean, "std": norm._std, "eps": norm.eps,
                "obs_dim": net.obs_dim, "num_actions": num_actions, "hidden_dims": hidden}, path)


def load_student(path: str | Path) -> StudentNet:
    """A student saved by `save_student`."""
    saved = torch.load(path, map_location="cpu", weights_only=True)
    net = StudentNet(saved["obs_dim"], saved["num_actions"], tuple(saved["hidden_dims"]), saved["mean"].numpy(),
                     saved["std"].numpy(), saved["eps"])
    net.load_state_dict(saved["state"])
    return net
