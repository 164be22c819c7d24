"""Training (the ``train`` extra): stages and baselines, PPO + BC, RMA phase 2, warm starts, export to policy files.

Configuration modules (`stages`, `train_config`, `bc_schedule`, `adaptation_config`) are torch-free; the others import
torch when they are imported.
"""

from wbc.learned.train.adaptation_config import AdaptationConfig
from wbc.learned.train.bc_schedule import BCSchedule
from wbc.learned.train.stages import BASELINES, TASKS, stage_config
from wbc.learned.train.train_config import PPOConfig, TrainConfig

__all__ = ["AdaptationConfig", "BASELINES", "BCSchedule", "PPOConfig", "TASKS", "TrainConfig", "stage_config"]
