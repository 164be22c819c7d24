"""`FrozenLegsVecEnv`: the decoupled baseline's env, where a frozen policy drives the legs and PPO only the rest.

The paper's decoupled baseline (Table III) is pi2's legs plus a separately trained arm policy. The batched env runs the
robot with its arm actuated; this wrapper exposes only the arm's actions to rsl-rl (``num_actions`` = 3) and, before
every step, fills in the leg actions from the frozen leg policy (a `NumpyPolicy` of pi2's exported file), fed its own
observation: the env's ``teacher`` group (the locked-arm view of the same state) and, when pi2 observes the RMA
extrinsics, z from its encoder on the ``privileged`` group (as `PPOWithBC` evaluates a teacher, and as pi2 acted in
its own training). Nothing in rsl-rl changes: its actor simply has 3 outputs.

The leg policy's ``last_action`` entries of the observation are its own previous (clipped) actions, as in pi2's
training, because the env records the whole 15-joint action it was given.
"""

from __future__ import annotations

import numpy as np

from wbc.errors import ConfigError
from wbc.learned.env.env import BatchedEnv
from wbc.learned.policy.numpy_policy import NumpyPolicy
from wbc.learned.policy.policy_file import PolicyFile
from wbc.learned.train.vec_env import RslVecEnv
from wbc.optional import require

torch = require("torch")

__all__ = ["FrozenLegsVecEnv"]


class FrozenLegsVecEnv(RslVecEnv):
    """An `RslVecEnv` whose first ``legs.num_actions`` joints follow a frozen policy.

    Args:
        env: the batched env, arm actuated, with ``teacher_arm_mode`` set to the leg policy's arm mode.
        legs: the frozen leg policy file (pi2).
        device: torch device of the returned tensors.

    Raises:
        ConfigError: the env offers no observation for the leg policy, or the policy is for another robot or arm mode.
    """

    def __init__(self, env: BatchedEnv, legs: PolicyFile, device: str = "cpu") -> None:
        cfg = env.config
        if cfg.teacher_arm_mode is None or env.teacher_layout is None:
            raise ConfigError("the frozen leg policy needs its own observation: set EnvConfig.teacher_arm_mode to its "
                              "arm mode")
        if legs.meta["robot"] != cfg.robot or legs.meta["arm_mode"] != cfg.teacher_arm_mode:
            raise ConfigError(f"the frozen leg policy drives {legs.meta['robot']} with arm "
                              f"{legs.meta['arm_mode']!r}; the env offers {cfg.robot} with arm "
                              f"{cfg.teacher_arm_mode!r}")
        if legs.num_actions >= env.num_actions:
            raise ConfigError(f"the frozen policy commands {legs.num_actions} joints of {env.num_actions}: nothing is "
                              "left to learn")
        self.legs = NumpyPolicy(legs)
        self.num_legs = legs.num_actions
        self._legs_input: tuple[np.ndarray, np.ndarray | None] | None = None
        super().__init__(env, device=device)
        self.num_actions = env.num_actions - self.num_legs

    def leg_actions(self) -> np.ndarray:
        """The frozen policy's actions for the current state, (N, num_legs)."""
        teacher, privileged = self._legs_input
        z = self.legs.extrinsics(privileged) if self.legs.uses_extrinsics else None
        return self.legs(teacher, z)

    def step(self, actions):
        """One policy step with the learned joints' `actions` (N, num_actions); the legs come from the frozen policy."""
        arm = actions.detach().cpu().numpy().astype(np.float64)
        full = np.concatenate([self.leg_actions(), arm], axis=1)
        return super().step(torch.from_numpy(full))

    def _pack(self, obs: np.ndarray, privileged: np.ndarray, teacher: np.ndarray | None):
        self._legs_input = (teacher, privileged)
        return super()._pack(obs, privileged, None)  # the leg policy's view is not the actor's or the critic's
