"""`NumpyComposite`: inference of a `CompositePolicyFile` in numpy, each part a `NumpyPolicy` on its own joints.

    actions[:, part.joints] = NumpyPolicy(part)(obs[:, part's observation entries], z_part)

for every part, where ``obs`` is the robot's full policy observation. A single policy file is the composite of one
part, so this is also how the controller runs an ordinary policy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wbc.learned.policy.composite_policy import CompositePolicyFile
from wbc.learned.policy.numpy_policy import NumpyPolicy

__all__ = ["NumpyComposite", "NumpyPart"]


@dataclass(frozen=True)
class NumpyPart:
    """One part, ready to run.

    Attributes:
        name: the part's name.
        policy: its network.
        joints: (k,) robot joint index of each output.
        obs_index: indices of the robot's observation that the part observes.
    """

    name: str
    policy: NumpyPolicy
    joints: np.ndarray
    obs_index: np.ndarray


class NumpyComposite:
    """A composite policy evaluated in numpy.

    Args:
        composite: a loaded, validated composite.
    """

    def __init__(self, composite: CompositePolicyFile) -> None:
        self.file = composite
        self.num_actions = composite.num_actions
        self.parts = tuple(NumpyPart(name=p.name, policy=NumpyPolicy(p.policy), joints=np.asarray(p.joints),
                                     obs_index=p.observation_index(self.num_actions)) for p in composite.parts)

    def __call__(self, obs: np.ndarray, z: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """Deterministic actions, (N, obs_size) -> (N, num_actions).

        Args:
            obs: the robot's full policy observations.
            z: extrinsics of each part that observes them, by part name.

        Raises:
            PolicyInputError: a part that observes the extrinsics has none in `z` (`NumpyPolicy`).
        """
        obs = np.asarray(obs, dtype=np.float64)
        out = np.empty((obs.shape[0], self.num_actions))
        for part in self.parts:
            out[:, part.joints] = part.policy(obs[:, part.obs_index], (z or {}).get(part.name))
        return out
