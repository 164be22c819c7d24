"""The arena: one runner loop, executors, episode logs, metrics, the results store, statistics and reports.

The package re-exports the loop and its records only; the simulated trials (`wbc.arena.sim_trial`), the executors
and the comparison (`wbc.arena.compare`) are imported from their modules, so a hardware trial that imports the loop
does not load the simulator or every controller.
"""

from wbc.arena.episode import Episode, PushLog, SafetyLog
from wbc.arena.runner import TickObserver, run_episode
from wbc.arena.trial_record import TrialRecord

__all__ = ["Episode", "PushLog", "SafetyLog", "TickObserver", "TrialRecord", "run_episode"]
