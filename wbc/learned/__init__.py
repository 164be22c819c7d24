"""The learned contender: batched training env, staged PPO + BC (pi1, pi2, pi3), RMA, numpy inference, controllers.

Torch-free names are re-exported here; the training pieces that need torch (``train``, ``ppo_bc``, ``rma``,
``vec_env``, ``frozen_legs_vec_env``, ``export``, ``extrinsics_actor``, ``torch_policy``, ``warm_start``) are
imported from their modules.
"""

from wbc.learned.adaptation_config import AdaptationConfig
from wbc.learned.bc_schedule import BCSchedule
from wbc.learned.composite_policy import CompositePolicyFile, PolicyPart, load_composite, save_composite
from wbc.learned.controller import LearnedController, shipped_weights
from wbc.learned.env import BatchedEnv, StepResult
from wbc.learned.env_config import DomainRandomisation, EnvConfig, ObsNoise, ObsScales, RewardScales
from wbc.learned.numpy_composite import NumpyComposite
from wbc.learned.numpy_policy import NumpyPolicy
from wbc.learned.obs_history import ObsHistory
from wbc.learned.observations import ObsLayout, compatible_observation, policy_observation
from wbc.learned.policy_file import PolicyFile, PolicyFileError, load_policy, save_policy
from wbc.learned.stages import BASELINES, TASKS, stage_config
from wbc.learned.throughput import bench_train
from wbc.learned.train_config import PPOConfig, TrainConfig

__all__ = [
    "AdaptationConfig",
    "BASELINES",
    "BCSchedule",
    "BatchedEnv",
    "CompositePolicyFile",
    "DomainRandomisation",
    "EnvConfig",
    "LearnedController",
    "NumpyComposite",
    "NumpyPolicy",
    "ObsHistory",
    "ObsLayout",
    "ObsNoise",
    "ObsScales",
    "PPOConfig",
    "PolicyFile",
    "PolicyFileError",
    "PolicyPart",
    "RewardScales",
    "StepResult",
    "TASKS",
    "TrainConfig",
    "bench_train",
    "compatible_observation",
    "load_composite",
    "load_policy",
    "policy_observation",
    "save_composite",
    "save_policy",
    "shipped_weights",
    "stage_config",
]
