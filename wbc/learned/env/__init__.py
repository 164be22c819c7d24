"""The batched training env: N robots stepped by `mujoco.rollout`, observations, rewards, pushes, model variants."""

from wbc.learned.env.env import BatchedEnv, StepResult
from wbc.learned.env.env_config import DomainRandomisation, EnvConfig, ObsNoise, RewardScales

__all__ = ["BatchedEnv", "DomainRandomisation", "EnvConfig", "ObsNoise", "RewardScales", "StepResult"]
