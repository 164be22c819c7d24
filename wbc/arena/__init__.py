"""The arena: one runner loop, executors, episode logs, metrics, the results store, statistics and reports."""

from wbc.arena.compare import ArenaConfig, ArenaResult, run_arena
from wbc.arena.episode import Episode, PushLog
from wbc.arena.executors import TrialTask
from wbc.arena.record import TrialRecord
from wbc.arena.runner import TickObserver, run_episode
from wbc.arena.sim_trial import run_trial, simulated_robot

__all__ = [
    "ArenaConfig", "ArenaResult", "Episode", "PushLog", "TickObserver", "TrialRecord", "TrialTask", "run_arena",
    "run_episode", "run_trial", "simulated_robot",
]
