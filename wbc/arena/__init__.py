"""The arena: one runner loop, executors, episode logs, metrics, the results store, statistics and reports."""

from wbc.arena.compare import ArenaConfig, ArenaResult, run_arena

__all__ = ["ArenaConfig", "ArenaResult", "run_arena"]
