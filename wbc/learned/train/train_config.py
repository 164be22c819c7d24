"""`TrainConfig`: one training run (env, networks, PPO, BC, teacher, iterations, where it writes)."""

from __future__ import annotations

from dataclasses import dataclass, field

from wbc.learned.env.env_config import EnvConfig
from wbc.learned.train.adaptation_config import AdaptationConfig
from wbc.learned.train.bc_schedule import BCSchedule

__all__ = ["PPOConfig", "TrainConfig"]


@dataclass(frozen=True, kw_only=True)
class PPOConfig:
    """PPO hyper-parameters (legged_gym's defaults, ``legged_gym/envs/base/legged_robot_config.py``)."""

    learning_rate: float = 1e-3
    schedule: str = "adaptive"
    desired_kl: float = 0.01
    clip_param: float = 0.2
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 0.01
    value_loss_coef: float = 1.0
    max_grad_norm: float = 1.0


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """A training run.

    Attributes:
        task: ``push`` or ``turn``.
        stage: 1, 2 or 3.
        baseline: None for the paper's method, else a baseline name (`wbc.learned.train.stages.BASELINES`).
        variant: None, or a one-change variant of the method's stage 3 (`wbc.learned.train.stages.RECIPE_VARIANTS`).
        env: the environment.
        seed: seeds torch (the env has its own seed in `env`).
        max_iterations: PPO iterations of the whole run (a resumed run trains up to this count).
        num_steps_per_env: policy steps per environment per iteration.
        save_interval: iterations between checkpoints (each also exports the policy file).
        actor_hidden_dims, critic_hidden_dims: MLP sizes. Half of legged_gym's (512, 256, 128): training runs on
            CPUs here, where the PPO update's cost grows with the square of the width.
        activation: MLP activation.
        init_std: initial action noise.
        extrinsics_dim: size of the RMA extrinsics z (0: the actor sees the policy observation only).
        encoder_dims: hidden sizes of the extrinsics encoder.
        rma: RMA phase 2, run after PPO when the policy observes extrinsics (its iterations 0: skipped).
        ppo: PPO hyper-parameters.
        bc: the BC weight schedule (None: no BC term).
        teacher: the previous stage's policy file (with `bc`).
        action_mask: student action index of each teacher (or `init_from`) action (default: the first ones, the legs).
        init_from: a previous policy file the actor starts from (`wbc.learned.train.warm_start`), or None.
        frozen_legs: a policy file (pi2) that drives the legs, frozen, while PPO trains an actor for the remaining
            joints only (the decoupled baseline, `wbc.learned.train.frozen_legs_vec_env`); the run exports a composite
            policy (`wbc.learned.policy.composite_policy`). None: the actor drives every joint.
        student: a distilled student's policy file (`wbc train --teacher mpc`, with a history) to fine-tune by PPO +
            BC: the actor is that student, reading its own observation window
            (`wbc.learned.train.history_actor.HistoryActor`), the BC term pulls towards the student as it was, and the
            run exports the student's file format. None: an ordinary stage.
        actor_frozen_iterations: first PPO iterations in which only the critic learns (`PPOWithBC`).
        expert_data: with `student`, a DAgger run's ``data.npz``: the BC term pulls towards the expert's own actions
            on those samples instead of towards the student (`PPOWithBC`); None: towards `teacher`.
        run_dir: where checkpoints, TensorBoard logs, the resolved config and the exported policy go.
        device: torch device.
        torch_threads: torch's intra-op threads. 1 by default: on a shared machine with few cores, torch's
            spinning worker threads slow the PPO update of a small network many times over.
    """

    task: str
    stage: int
    baseline: str | None = None
    variant: str | None = None
    env: EnvConfig = field(default_factory=EnvConfig)
    seed: int = 0
    max_iterations: int = 1500
    num_steps_per_env: int = 24
    save_interval: int = 50
    actor_hidden_dims: tuple[int, ...] = (256, 128, 64)
    critic_hidden_dims: tuple[int, ...] = (256, 128, 64)
    activation: str = "elu"
    init_std: float = 1.0
    extrinsics_dim: int = 8
    encoder_dims: tuple[int, ...] = (64, 32)
    rma: AdaptationConfig = field(default_factory=AdaptationConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    bc: BCSchedule | None = None
    teacher: str | None = None
    action_mask: tuple[int, ...] | None = None
    init_from: str | None = None
    frozen_legs: str | None = None
    student: str | None = None
    actor_frozen_iterations: int = 0
    expert_data: str | None = None
    run_dir: str = "runs/train"
    device: str = "cpu"
    torch_threads: int = 1
