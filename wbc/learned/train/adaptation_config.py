"""`AdaptationConfig`: settings of RMA phase 2 (the adaptation module's training, `wbc.learned.train.rma`)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["AdaptationConfig"]


@dataclass(frozen=True, kw_only=True)
class AdaptationConfig:
    """RMA phase 2.

    Attributes:
        iterations: rollout + regression rounds.
        steps_per_iteration: policy steps per environment per round.
        history: observations in the window (H).
        hidden_dims: MLP sizes of phi.
        learning_rate: Adam step size.
        epochs: passes over each round's data.
        minibatch: samples per gradient step.
        seed: torch seed.
    """

    iterations: int = 200
    steps_per_iteration: int = 24
    history: int = 25
    hidden_dims: tuple[int, ...] = (256, 128)
    learning_rate: float = 5e-4
    epochs: int = 2
    minibatch: int = 4096
    seed: int = 0
