"""A sequential paired comparison of success: an anytime-valid test that lets a run stop once the difference is settled.

``wbc compare --until-significant`` plays trials round by round and stops as soon as every paired success difference
it tests is significant, instead of playing the whole budget. Looking at a fixed-n test (McNemar) after every round
and stopping at the first p <= alpha would inflate the error rate far beyond alpha: on simulated streams of 300
pairs with equal success rates, a look after every pair rejects in 18-32 % of the streams instead of 5 % (more the
more pairs are discordant; `tests/test_significance.py` measures it). This module's test keeps its error rate however
often it is looked at and whenever it stops (about 3 % on the same streams).

The test (a mixture sequential probability ratio test on the discordant pairs). Of the pairs of trials, only the
discordant ones say anything about which controller succeeds more often: "A only succeeded" or "B only succeeded".
Under H0 (equal success probabilities), each discordant pair is B's with probability theta = 1/2. After b pairs
"A only" and c pairs "B only", the likelihood ratio of theta against 1/2, averaged over theta ~ Beta(a, a), is

    E = B(a + c, a + b) / B(a, a) * 2^(b + c)          (B the Beta function; a = 1/2 here)

and E = 1 before any pair. Under H0, E is a nonnegative martingale in the sequence of pairs (a concordant pair leaves
it unchanged; a discordant one multiplies it by 2 (a + c) / (2a + b + c) or 2 (a + b) / (2a + b + c), each with
probability 1/2, whose mean is 1). Ville's inequality then bounds the chance that it *ever* reaches 1 / alpha:
P_H0(sup_n E_n >= 1 / alpha) <= alpha. Rejecting H0 the first time E >= 1 / alpha is therefore a level-alpha test at
any stopping time: after every pair, after every round, or when the budget is spent; ``p = min(1, 1 / max E)`` is its
anytime-valid p-value. Several comparisons (controller pairs x bands) share alpha by Bonferroni: each is tested at
alpha / m, so the chance that any true H0 is rejected stays <= alpha.

What it saves: the mixture test needs no effect size in advance, and it stops about where a fixed-n McNemar test
planned with the true effect would have ended. Simulated: success 50 % against 95 % stops after a median of 16 pairs
(90 % of runs within 31), where the exact McNemar test needs 19 pairs for 80 % power (`wbc.arena.statistical_power`); a
10-point difference with 20 % of the pairs discordant (5 % "A only", 15 % "B only"): a median of about 150 pairs
against 168 (15 % of runs not settled within 300). A run whose budget was sized for the smallest difference worth
finding (hundreds of pairs) ends after a few dozen when the difference is large.

Pairs are fed in the trials' fixed order (round by round, in `SequentialComparison`), never in the order trials
finish: a trial that ends in an early fall finishes sooner, and the order of completion would leak the outcomes into
the sequence and void the martingale argument.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from wbc.arena.trial_record import TrialRecord
from wbc.errors import ConfigError, RecordError

__all__ = ["PRIOR", "DiscordantPairTest", "SequentialComparison", "mixture_log_e"]

PRIOR = 0.5
"""The mixture's Beta(a, a) parameter a (1/2: Jeffreys' prior, the Krichevsky-Trofimov mixture)."""


def mixture_log_e(a_only: np.ndarray | int, b_only: np.ndarray | int, prior: float = PRIOR) -> np.ndarray | float:
    """The log e-value after `a_only` pairs "A only succeeded" and `b_only` "B only succeeded" (module docstring).

    Vectorised: arrays of counts give an array of log e-values.
    """
    from scipy.special import betaln

    b = np.asarray(a_only, dtype=float)
    c = np.asarray(b_only, dtype=float)
    log_e = betaln(prior + c, prior + b) - betaln(prior, prior) + (b + c) * math.log(2.0)
    return float(log_e) if log_e.ndim == 0 else log_e


class DiscordantPairTest:
    """Anytime-valid test of equal success probability for two controllers, fed pair by pair.

    Args:
        alpha: the level of this test (after any Bonferroni split), in (0, 1).
        prior: the mixture's Beta(prior, prior) parameter, > 0.

    Raises:
        ConfigError: alpha or prior out of range.
    """

    def __init__(self, *, alpha: float = 0.05, prior: float = PRIOR) -> None:
        if not 0.0 < alpha < 1.0:
            raise ConfigError(f"alpha must be in (0, 1), got {alpha}; pass a significance level such as 0.05")
        if not prior > 0.0:
            raise ConfigError(f"prior must be > 0, got {prior}")
        self.alpha = alpha
        self.prior = prior
        self.a_only = 0
        self.b_only = 0
        self.pairs = 0
        self.max_log_e = 0.0
        self.rejected_after: int | None = None

    @property
    def threshold_log_e(self) -> float:
        """log(1 / alpha): the test rejects once log E reaches it."""
        return -math.log(self.alpha)

    @property
    def log_e(self) -> float:
        """The log e-value now."""
        return mixture_log_e(self.a_only, self.b_only, self.prior)

    @property
    def rejected(self) -> bool:
        """E has reached 1 / alpha at some point: the success probabilities differ (at level alpha)."""
        return self.rejected_after is not None

    @property
    def p_value(self) -> float:
        """Anytime-valid p-value: min(1, 1 / max E so far)."""
        return min(1.0, math.exp(-self.max_log_e))

    def observe(self, a_success: bool, b_success: bool) -> None:
        """Feed one pair: A's and B's success on the same trial."""
        self.pairs += 1
        if bool(a_success) == bool(b_success):
            return
        if a_success:
            self.a_only += 1
        else:
            self.b_only += 1
        self.max_log_e = max(self.max_log_e, self.log_e)
        if self.rejected_after is None and self.max_log_e >= self.threshold_log_e:
            self.rejected_after = self.pairs


class SequentialComparison:
    """The sequential tests of an arena run: one `DiscordantPairTest` per (controller pair, band), fed round by round.

    A round is one (trial index, seed): every band's trial of that index and seed, played by every controller.
    Rounds must be added in the order the run defines (trial index, then seed), each complete.

    Args:
        pairs: the (A, B) controller pairs to test.
        bands: the bands; each pair is tested in each band.
        alpha: the family-wise level; each of the m = len(pairs) * len(bands) tests runs at alpha / m.
        prior: the mixture's Beta parameter.

    Raises:
        ConfigError: no pair or no band, or alpha out of range.
    """

    def __init__(self, pairs: Sequence[tuple[str, str]], bands: Sequence[str], *, alpha: float = 0.05,
                 prior: float = PRIOR) -> None:
        if not pairs or not bands:
            raise ConfigError("a sequential comparison needs at least two controllers and one band")
        if not 0.0 < alpha < 1.0:
            raise ConfigError(f"alpha must be in (0, 1), got {alpha}; pass a significance level such as 0.05")
        self.alpha = alpha
        self.prior = prior
        self.pairs = tuple(pairs)
        self.bands = tuple(bands)
        m = len(self.pairs) * len(self.bands)
        self.tests = {(a, b, band): DiscordantPairTest(alpha=alpha / m, prior=prior)
                      for a, b in self.pairs for band in self.bands}
        self.rounds = 0
        self.settled_after: int | None = None  # the rounds fed when every test had first rejected

    @property
    def settled(self) -> bool:
        """Every test has rejected: every tested success difference is established."""
        return all(test.rejected for test in self.tests.values())

    def add_round(self, records: Iterable[TrialRecord]) -> None:
        """Feed one complete round: the records of every controller on the round's trials.

        Raises:
            RecordError: a controller's record of one of the round's trials is missing.
        """
        by_trial: dict[tuple[str, int, int], dict[str, TrialRecord]] = {}
        for record in records:
            by_trial.setdefault(record.pair_key, {})[record.controller] = record
        for key in sorted(by_trial, key=lambda k: (self.bands.index(k[0]) if k[0] in self.bands else -1, k)):
            band = key[0]
            played = by_trial[key]
            for a, b in self.pairs:
                if (a, b, band) not in self.tests:
                    continue
                if a not in played or b not in played:
                    raise RecordError(f"round {self.rounds}: trial {key} lacks the record of "
                                      f"{a if a not in played else b}; feed complete rounds")
                self.tests[(a, b, band)].observe(played[a].success, played[b].success)
        self.rounds += 1
        if self.settled_after is None and self.settled:
            self.settled_after = self.rounds

    def as_dict(self) -> dict[str, Any]:
        """The state of every test, JSON-serialisable (for ``summary.json`` and the printed table)."""
        return {
            "alpha": self.alpha,
            "prior": self.prior,
            "rounds": self.rounds,
            "settled": self.settled,
            "settled_after_rounds": self.settled_after,
            "tests": [
                {"a": a, "b": b, "band": band, "pairs": t.pairs, "a_only": t.a_only, "b_only": t.b_only,
                 "alpha": t.alpha, "e_value": math.exp(min(t.log_e, 700.0)), "p_value": t.p_value,
                 "rejected": t.rejected, "rejected_after_pairs": t.rejected_after}
                for (a, b, band), t in self.tests.items()
            ],
        }
