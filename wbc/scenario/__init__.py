"""Scenarios, the world data every controller is played against: files, sampling, the publish lock, trials.

A scenario file (``scenarios/*.toml``) is validated and hashed into a `Scenario`, which samples `Trial`s: terrain,
domain parameters, command schedule and pushes. Nothing here knows a robot backend; the backends apply these data.
"""

from wbc.scenario.domain import DomainParams, SensorNoise
from wbc.scenario.lock import check_published, warn_if_unpublished
from wbc.scenario.push import Push
from wbc.scenario.scenario import Scenario, ScenarioError, load_scenario, resolve_scenario_path
from wbc.scenario.terrain import TerrainConfig
from wbc.scenario.trial import CommandChange, CommandSchedule, Trial
from wbc.scenario.trial_file import trial_scenario_text, write_trial_scenario

__all__ = ["CommandChange", "CommandSchedule", "DomainParams", "Push", "Scenario", "ScenarioError", "SensorNoise",
           "TerrainConfig", "Trial", "check_published", "load_scenario", "resolve_scenario_path", "trial_scenario_text",
           "warn_if_unpublished", "write_trial_scenario"]
