"""The learned contender: batched training env, staged PPO + BC (pi1, pi2, pi3), numpy inference, controllers."""

from wbc.learned.env import BatchedEnv, StepResult
from wbc.learned.env_config import DomainRandomisation, EnvConfig, ObsNoise, ObsScales, RewardScales
from wbc.learned.observations import ObsLayout, compatible_observation, policy_observation

__all__ = [
    "BatchedEnv",
    "DomainRandomisation",
    "EnvConfig",
    "ObsLayout",
    "ObsNoise",
    "ObsScales",
    "RewardScales",
    "StepResult",
    "compatible_observation",
    "policy_observation",
]
