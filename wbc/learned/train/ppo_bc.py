"""`PPOWithBC`: rsl-rl's PPO plus the paper's behaviour-cloning term towards the previous stage's policy (eq. 3).

    loss = L_PPO + lambda(it) * mean over the minibatch of || mu_theta(o)[mask] - pi_prev(o_prev) ||^2 / |mask|

mu_theta is the actor's mean action; pi_prev is the previous stage's exported policy (a frozen `TorchPolicy`) on the
compatible part of the observation (the ``teacher`` group, which the env builds from the same state) and, when that
policy observes the extrinsics, the ``privileged`` group, or its observation window (the ``history`` group) when it
reads its own memory (a distilled student fine-tuned against its starting self); `mask` lists the actor's action
indices that correspond, in order, to the teacher's actions (the legs when the arm is new). The expectation runs over
on-policy states: the teacher labels the states the student visits, as the paper prescribes. lambda follows a
`BCSchedule` over PPO iterations and is saved with the checkpoint, so a resumed run continues the same schedule.

With `expert_data` (a DAgger run's ``data.npz``: observations, the expert's actions, episode ids) the BC term is the
expert's own instead: each minibatch draws as many of the expert's samples, the actor reads each one's observation
and window (built from its episode, as the student was fitted), and lambda weighs the mean squared difference to the
expert's action. That is BC towards the expert where the expert cannot run (an MPC in a batched env), on the states
DAgger labelled; the teacher policy is then not used.

`actor_frozen_iterations` trains the critic alone for the first iterations: an actor that starts as a good policy
(a student) would otherwise be moved by the advantages of a critic that has not yet learnt anything.

rsl-rl's `PPO.update` has no hook for an extra loss, so `update` is re-implemented here for the configuration this
project uses (feed-forward models, one device, no RND, no symmetry augmentation); other configurations are refused.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wbc.errors import ConfigError, NetworkMismatchError
from wbc.learned.policy.policy_file import load_policy
from wbc.learned.train.bc_schedule import BCSchedule
from wbc.learned.train.distill import history_index
from wbc.learned.train.preflight import read_expert_samples
from wbc.learned.train.torch_policy import TorchPolicy
from wbc.optional import require

torch = require("torch")
_ppo = require("rsl_rl.algorithms")

__all__ = ["ExpertSamples", "PPOWithBC", "bc_loss"]


class ExpertSamples:
    """A DAgger run's samples, drawn as an actor that reads its observation window sees them.

    Args:
        path: the run's ``data.npz``: ``obs`` (N, D), ``actions`` (N, A) (the expert's, clipped to the policy's
            range), ``episode`` (N,) (an episode's samples contiguous and in time order).
        history: the window length the actor reads (>= 1).

    Raises:
        ConfigError: the file is missing or unreadable, lacks one of the arrays, or their shapes disagree; or
            `history` < 1 (an actor without a window).
    """

    def __init__(self, path: str, history: int) -> None:
        if history < 1:
            raise ConfigError(f"BC towards the expert's samples ({path}) is for an actor that reads an observation "
                              "window (a distilled student); this actor reads none")
        obs, actions, episode = read_expert_samples(path)  # the checks a dry run makes too
        self.obs = torch.from_numpy(np.ascontiguousarray(obs, dtype=np.float32))
        self.actions = torch.from_numpy(np.ascontiguousarray(actions, dtype=np.float32))
        self.windows = torch.from_numpy(history_index(episode, history))
        self.size = obs.shape[0]

    def draw(self, count: int, generator) -> tuple[dict[str, Any], Any]:
        """`count` samples at random: ({"policy": (count, D), "history": (count, H * D)}, expert actions)."""
        idx = torch.randint(self.size, (count,), generator=generator)
        window = self.obs[self.windows[idx]]
        return {"policy": self.obs[idx], "history": window.reshape(count, -1)}, self.actions[idx]


def bc_loss(student_mean, teacher_actions, mask):
    """Mean squared difference on the compatible part of the action.

    Args:
        student_mean: (B, n_student) actor mean actions.
        teacher_actions: (B, n_teacher) teacher actions.
        mask: (n_teacher,) long tensor: student action index of each teacher action.

    Returns:
        Scalar: mean over the batch and the compatible actions of the squared difference.

    Raises:
        NetworkMismatchError: the mask does not have one entry per teacher action.
    """
    if mask.numel() != teacher_actions.shape[-1]:
        raise NetworkMismatchError(f"BC mask has {mask.numel()} entries for a teacher with "
                                   f"{teacher_actions.shape[-1]} actions; give one student index per teacher action")
    return (student_mean.index_select(-1, mask) - teacher_actions).pow(2).mean()


class PPOWithBC(_ppo.PPO):
    """PPO with an annealed BC term (see the module docstring).

    Args:
        actor, critic, storage: as `rsl_rl.algorithms.PPO`.
        teacher_path: the previous stage's policy file (.npz/.json pair).
        bc_schedule: keyword arguments of `BCSchedule`.
        action_mask: student action index for each teacher action (default: the first n_teacher).
        teacher_group: observation group the teacher sees.
        privileged_group: observation group of the teacher's extrinsics input.
        history_group: observation group of the teacher's window, when it reads its history.
        actor_frozen_iterations: first iterations in which only the critic learns.
        expert_data: a DAgger run's ``data.npz`` whose expert actions the BC term pulls towards (the actor must read
            an observation window: `wbc.learned.train.history_actor.HistoryActor`); None: the teacher's actions.
        expert_seed: seeds the draw of the expert's samples.
        **kwargs: `PPO` arguments.

    Raises:
        ConfigError: the rsl-rl configuration uses what `update` does not re-implement (RND, symmetry, recurrence).
        NetworkMismatchError: `action_mask` does not have one entry per teacher action.
        PolicyFileError: the teacher's file is missing or malformed.
    """

    def __init__(self, actor, critic, storage, *, teacher_path: str | None = None,
                 bc_schedule: dict[str, Any] | None = None, action_mask: list[int] | None = None,
                 teacher_group: str = "teacher", privileged_group: str = "privileged", history_group: str = "history",
                 actor_frozen_iterations: int = 0, expert_data: str | None = None, expert_seed: int = 0,
                 **kwargs) -> None:
        super().__init__(actor, critic, storage, **kwargs)
        if self.rnd or self.symmetry or self.is_multi_gpu or actor.is_recurrent or critic.is_recurrent:
            raise ConfigError("PPOWithBC supports feed-forward models on one device, without RND or symmetry: "
                              "remove rnd_cfg / symmetry_cfg and recurrent models from the rsl-rl configuration")
        self.expert = None if expert_data is None else ExpertSamples(expert_data, int(getattr(actor, "history", 0)))
        if self.expert is not None:
            outputs = [m for m in actor.mlp if isinstance(m, torch.nn.Linear)][-1].out_features
            if self.expert.actions.shape[1] != outputs:
                raise ConfigError(f"expert samples {expert_data}: their actions have {self.expert.actions.shape[1]} "
                                  f"entries, the actor has {outputs}; give the data of a DAgger run on this robot")
        self._expert_gen = torch.Generator().manual_seed(int(expert_seed))
        self.teacher = None
        if self.expert is None:
            if teacher_path is None:
                raise ConfigError("PPOWithBC needs a teacher policy file (teacher_path) or the expert's samples "
                                  "(expert_data)")
            teacher = load_policy(teacher_path)
            self.teacher = TorchPolicy(teacher).to(self.device)
            n_teacher = teacher.num_actions
            mask = list(range(n_teacher)) if action_mask is None else list(action_mask)
            self.action_mask = torch.as_tensor(mask, dtype=torch.long, device=self.device)
            if self.action_mask.numel() != n_teacher:
                raise NetworkMismatchError(f"action_mask has {len(mask)} entries, the teacher {teacher_path} has "
                                           f"{n_teacher} actions; set TrainConfig.action_mask to one student index per "
                                           "teacher action")
        self.schedule_bc = BCSchedule(**(bc_schedule or {}))
        self.teacher_group = teacher_group
        self.privileged_group = privileged_group
        self.history_group = history_group
        self.actor_frozen_iterations = int(actor_frozen_iterations)
        self.bc_iteration = 0
        self.bc_weight: float | None = None
        """The BC weight (lambda) of the last update: logged as ``Train/bc_weight``, not among the losses."""

    def teacher_actions(self, obs):
        """The teacher's actions for an observation TensorDict."""
        if self.teacher.reads_history:
            return self.teacher(obs[self.teacher_group], history=obs[self.history_group])
        priv = obs[self.privileged_group] if self.teacher.uses_extrinsics else None
        return self.teacher(obs[self.teacher_group], priv)

    def update(self) -> dict[str, float]:
        """PPO epochs over the rollout, with lambda * BC added to every minibatch's loss."""
        lam = self.schedule_bc.weight(self.bc_iteration)
        actor_learns = self.bc_iteration >= self.actor_frozen_iterations
        sums = {"value": 0.0, "surrogate": 0.0, "entropy": 0.0, "bc": 0.0}
        n = 0
        for batch in self.storage.mini_batch_generator(self.num_mini_batches, self.num_learning_epochs):
            adv = batch.advantages
            if self.normalize_advantage_per_mini_batch:
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
            self.actor(batch.observations, stochastic_output=True)
            log_prob = self.actor.get_output_log_prob(batch.actions)
            values = self.critic(batch.observations)
            params = self.actor.output_distribution_params
            entropy = self.actor.output_entropy
            if actor_learns and self.desired_kl is not None and self.schedule == "adaptive":  # frozen: KL 0
                with torch.inference_mode():
                    kl = self.actor.get_kl_divergence(batch.old_distribution_params, params).mean()
                    if kl > self.desired_kl * 2.0:
                        self.learning_rate = max(1e-5, self.learning_rate / 1.5)
                    elif 0.0 < kl < self.desired_kl / 2.0:
                        self.learning_rate = min(1e-2, self.learning_rate * 1.5)
                    for group in self.optimizer.param_groups:
                        group["lr"] = self.learning_rate
            ratio = torch.exp(log_prob - torch.squeeze(batch.old_actions_log_prob))
            a = torch.squeeze(adv)
            surrogate = torch.max(-a * ratio, -a * torch.clamp(ratio, 1.0 - self.clip_param, 1.0 + self.clip_param))
            surrogate_loss = surrogate.mean()
            if self.use_clipped_value_loss:
                clipped = batch.values + (values - batch.values).clamp(-self.clip_param, self.clip_param)
                value_loss = torch.max((values - batch.returns).pow(2), (clipped - batch.returns).pow(2)).mean()
            else:
                value_loss = (batch.returns - values).pow(2).mean()
            if self.expert is not None:
                inputs, labels = self.expert.draw(int(adv.shape[0]), self._expert_gen)
                bc = (self.actor(inputs) - labels).pow(2).mean()
            else:
                with torch.no_grad():
                    target = self.teacher_actions(batch.observations)
                bc = bc_loss(self.actor.output_mean, target, self.action_mask)
            if actor_learns:
                loss = surrogate_loss + self.value_loss_coef * value_loss - self.entropy_coef * entropy.mean()
                if lam > 0.0:
                    loss = loss + lam * bc
            else:
                loss = self.value_loss_coef * value_loss
            self.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.actor.parameters(), self.max_grad_norm)
            torch.nn.utils.clip_grad_norm_(self.critic.parameters(), self.max_grad_norm)
            self.optimizer.step()
            sums["value"] += value_loss.item()
            sums["surrogate"] += surrogate_loss.item()
            sums["entropy"] += entropy.mean().item()
            sums["bc"] += bc.item()
            n += 1
        obs = self.storage.observations.flatten(0, 1)
        self.actor.update_normalization(obs)
        self.critic.update_normalization(obs)
        self.storage.clear()
        self.bc_iteration += 1
        # the losses only: lambda is a weight, not a loss; the runner logs it as Train/bc_weight (`bc_weight`)
        self.bc_weight = lam
        return {k: v / max(n, 1) for k, v in sums.items()}

    def save(self) -> dict:
        """PPO's checkpoint dict plus the BC schedule's position."""
        saved = super().save()
        saved["bc_iteration"] = self.bc_iteration
        return saved

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        """PPO's load, restoring the BC schedule's position."""
        out = super().load(loaded_dict, load_cfg, strict)
        self.bc_iteration = int(loaded_dict.get("bc_iteration", 0))
        return out
