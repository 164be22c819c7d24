"""A record counts the pushes of its episode's length: a trial cut short does not report pushes it never met."""

import dataclasses

import numpy as np

from wbc.arena.sim_trial import run_trial
from wbc.scenario import Push, load_scenario


def _trial(duration_s, pushes):
    trial = load_scenario("scenarios/push.toml").trial("in", 0, 0)
    return dataclasses.replace(trial, duration_s=duration_s, pushes=tuple(pushes))


def test_pushes_after_the_end_of_a_shortened_episode_are_not_counted():
    early = Push.horizontal(60.0, 0.0, (0.0, 0.0, 0.0), start=0.3, duration=0.1)
    late = Push.horizontal(250.0, np.pi / 2, (0.0, 0.0, 0.0), start=1.5, duration=0.1)
    record, episode = run_trial(_trial(1.0, [early, late]), "stand")
    assert len(episode.pushes) == 1  # the episode met the early push only
    assert record.n_pushes == 1
    assert record.push_force_n == np.float64(np.linalg.norm(early.force_in_world))


def test_a_push_within_the_duration_counts_whether_played_or_not():
    # a push at the very end counts, played or not: the record says what the trial put within its length
    first = Push.horizontal(60.0, 0.0, (0.0, 0.0, 0.0), start=0.3, duration=0.1)
    last = Push.horizontal(90.0, 0.0, (0.0, 0.0, 0.0), start=0.99, duration=0.1)
    record, _ = run_trial(_trial(1.0, [first, last]), "stand")
    assert record.n_pushes == 2
    assert record.push_force_n == np.float64(np.linalg.norm(last.force_in_world))
