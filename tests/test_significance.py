"""The arena's statistics a reviewer checks: exact McNemar, Wilcoxon, Wilson, power, and the sequential test.

Known cases by hand and from the literature; cross-checks against statsmodels' independent implementations; the
sequential test's error rate on many seeded null streams (and the naive repeated test's, which it must beat), its
early stop on a clear difference, and ``wbc compare --until-significant`` end to end on short trials.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from conftest import SHORT_SCENARIO
from scipy.stats import binom

from wbc.arena import paired_tests
from wbc.arena.compare import ArenaConfig, run_arena
from wbc.arena.paired_tests import hodges_lehmann, mcnemar_exact, paired_values, wilcoxon_signed_rank
from wbc.arena.report import (
    _sequential_lines,
    cell_text,
    compare_pair,
    format_table,
    format_verdict,
    n80_text,
    p_text,
    paired_comparison,
    summarize,
    write_report,
)
from wbc.arena.sequential import DiscordantPairTest, SequentialComparison, mixture_log_e
from wbc.arena.statistical_power import mcnemar_power, pairs_for_mcnemar, pairs_for_mean_difference, t_test_power
from wbc.arena.stats import wilson_interval
from wbc.arena.summary import MetricSummary, PairSummary, Summary, p_digits
from wbc.arena.trial_record import TrialRecord
from wbc.arena.verdict import signed, verdicts
from wbc.errors import ConfigError, RecordError


def make_record(controller: str, band: str, seed: int, trial: int, **overrides) -> TrialRecord:
    """A record with plain values; `overrides` replace fields."""
    fields = {"controller": controller, "scenario": "flat_push", "scenario_hash": "abc123", "band": band,
              "seed": seed, "trial": trial, "success": True, "ttf": 1.0, "fall_time_s": math.nan, "vlin_err": 0.1,
              "vang_err": 0.2, "max_roll_deg": 5.0, "max_pitch_deg": 3.0, "energy_j": 100.0, "arm_travel_rad": 0.5,
              "push_force_n": 0.0, "n_pushes": 0, "vx_cmd": 0.0, "vy_cmd": 0.0, "yaw_rate_cmd": 0.0,
              "friction": 0.8, "payload_kg": 0.0, "fallbacks": 0, "wbc_failures": 0, "debug_truth": False,
              "wall_s": 1.0}
    fields |= overrides
    fields.setdefault("outcome", "success" if fields["success"] else "fall")
    return TrialRecord(**fields)

# --- exact McNemar ------------------------------------------------------------------------------------------------


def test_mcnemar_exact_matches_hand_computed_and_published_values():
    # 0 against 6 discordant pairs: p = 2 / 2^6
    assert mcnemar_exact(np.ones(6, bool), np.zeros(6, bool)).p_value == pytest.approx(2 / 64, abs=1e-15)
    # 1 against 9: p = 2 (1 + 9) / 2^10 ... written as a 2x2 table with 7 concordant pairs
    a = np.array([1] * 1 + [0] * 9 + [1] * 4 + [0] * 3, bool)
    b = np.array([0] * 1 + [1] * 9 + [1] * 4 + [0] * 3, bool)
    result = mcnemar_exact(a, b)
    assert (result.a_only, result.b_only, result.n) == (1, 9, 17)
    assert result.p_value == pytest.approx(22 / 1024, abs=1e-15)
    # the worked example of Fagerland, Lydersen and Laake (BMC Med Res Methodol 2013, 13:91; airway
    # hyper-responsiveness before and after stem cell transplantation): 1 against 7 discordant pairs, exact
    # conditional p = 0.070 (= 18 / 256), where the asymptotic McNemar test gives 0.034
    a = np.array([1, 1] + [0] * 7 + [0] * 12, bool)
    b = np.array([1, 0] + [1] * 7 + [0] * 12, bool)
    assert mcnemar_exact(a, b).p_value == pytest.approx(18 / 256, abs=1e-15)
    assert round(mcnemar_exact(a, b).p_value, 3) == 0.070
    # symmetric and two-sided; no discordant pair: nothing to test
    assert mcnemar_exact(b, a).p_value == mcnemar_exact(a, b).p_value
    none = mcnemar_exact(np.ones(5, bool), np.ones(5, bool))
    assert (none.a_only, none.b_only, none.p_value) == (0, 0, 1.0)


def test_mcnemar_exact_agrees_with_statsmodels():
    contingency = pytest.importorskip("statsmodels.stats.contingency_tables")
    rng = np.random.default_rng(3)
    for _ in range(40):
        n = int(rng.integers(1, 300))
        a = rng.random(n) < rng.random()
        b = rng.random(n) < rng.random()
        table = [[np.sum(a & b), np.sum(a & ~b)], [np.sum(~a & b), np.sum(~a & ~b)]]
        theirs = contingency.mcnemar(table, exact=True).pvalue
        assert mcnemar_exact(a, b).p_value == pytest.approx(min(1.0, theirs), rel=1e-12, abs=1e-300)


def test_mcnemar_refuses_unpaired_or_continuous_values():
    with pytest.raises(RecordError, match="pair them first"):
        mcnemar_exact(np.ones(3), np.ones(4))
    with pytest.raises(RecordError, match="wilcoxon_signed_rank"):
        mcnemar_exact(np.array([0.5, 1.0]), np.array([1.0, 0.0]))


# --- Wilcoxon signed-rank ---------------------------------------------------------------------------------------------


def test_wilcoxon_exact_small_samples_by_hand():
    # six positive differences: every sign pattern equally likely under H0, p = 2 / 2^6
    assert wilcoxon_signed_rank(np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])).p_value == pytest.approx(2 / 64)
    # ranks 1..5 positive, rank 6 negative: T- = 6; 14 of the 64 subsets of {1..6} sum to <= 6, p = 2 * 14 / 64
    result = wilcoxon_signed_rank(np.array([1.0, 2.0, 3.0, 4.0, 5.0, -6.0]))
    assert result.p_value == pytest.approx(28 / 64)
    assert result.statistic == 6.0 and result.nonzero == 6
    # zero differences are dropped (Wilcoxon's convention): the same six and two ties at zero
    padded = wilcoxon_signed_rank(np.array([0.0, 0.1, 0.2, 0.0, 0.3, 0.4, 0.5, 0.6]))
    assert (padded.n, padded.nonzero) == (8, 6) and padded.p_value == pytest.approx(2 / 64)
    # nothing differs: p = 1
    assert wilcoxon_signed_rank(np.zeros(5)).p_value == 1.0
    with pytest.raises(RecordError, match="finite"):
        wilcoxon_signed_rank(np.array([1.0, math.nan]))


def _signs_enumerated(d: np.ndarray) -> float:
    """The exact two-sided signed-rank p-value by enumerating every sign pattern (ties share their mean rank)."""
    import itertools

    from scipy.stats import rankdata

    nonzero = d[d != 0.0]
    ranks = rankdata(np.abs(nonzero))
    total, observed = ranks.sum(), ranks[nonzero > 0].sum()
    sums = np.array([ranks[np.array(signs, dtype=bool)].sum()
                     for signs in itertools.product((0, 1), repeat=nonzero.size)])
    return float(np.mean(np.abs(2 * sums - total) >= abs(2 * observed - total) - 1e-9))


def test_wilcoxon_is_exact_with_ties_and_equals_scipys_exact_test_without():
    from scipy.stats import wilcoxon

    rng = np.random.default_rng(7)
    for k in range(60):  # ties from rounding: scipy would switch to an approximation there
        d = np.round(rng.normal(0.3, 1.0, rng.integers(2, 12)), k % 2)
        if np.any(d):
            assert wilcoxon_signed_rank(d).p_value == pytest.approx(_signs_enumerated(d), abs=1e-12)
    for n in (6, 20, 50):  # untied: scipy's exact null distribution
        d = rng.normal(0.2, 1.0, n)
        assert wilcoxon_signed_rank(d).p_value == pytest.approx(wilcoxon(d, method="exact").pvalue, abs=1e-12)
    # beyond the exact range, the normal approximation stays close to the exact p
    d = np.round(rng.normal(0.1, 1.0, 300), 1)
    approx = wilcoxon_signed_rank(d)
    assert not approx.exact and approx.nonzero > paired_tests.WILCOXON_EXACT_MAX
    exact_max = paired_tests.WILCOXON_EXACT_MAX
    try:
        paired_tests.WILCOXON_EXACT_MAX = 1000
        assert wilcoxon_signed_rank(d).exact
        assert approx.p_value == pytest.approx(wilcoxon_signed_rank(d).p_value, abs=2e-3)
    finally:
        paired_tests.WILCOXON_EXACT_MAX = exact_max


def test_fall_times_on_one_tick_grid_tie_instead_of_being_ranked_by_rounding_noise():
    # TTF is a share of the episode; differences equal in ticks differ in their last bits after the subtraction
    dt, episode = 0.02, 10.0
    ticks_a = np.array([453, 452, 426, 215, 371, 142, 405])
    ticks_b = np.array([483, 462, 436, 245, 381, 172, 395])
    d = (ticks_b + 1) * dt / episode - (ticks_a + 1) * dt / episode
    assert len(set(d.tolist())) > len(set((ticks_b - ticks_a).tolist()))  # the noise is there
    assert wilcoxon_signed_rank(d).p_value == pytest.approx(_signs_enumerated((ticks_b - ticks_a).astype(float)))
    assert wilcoxon_signed_rank(d).p_value == pytest.approx(0.078125)  # not significant; noise ranks gave 0.047


def test_the_hodges_lehmann_shift_is_the_median_of_walsh_averages():
    assert hodges_lehmann(np.array([1.0, 2.0, 9.0])) == 3.5  # averages 1, 1.5, 2, 5, 5.5, 9: their median
    assert hodges_lehmann(np.array([0.01] * 20 + [-1.0])) == pytest.approx(0.01)
    assert hodges_lehmann(np.array([0.0] * 30 + [-0.1] * 10)) == pytest.approx(-0.1)  # the zeros are not ranked
    assert math.isnan(hodges_lehmann(np.array([]))) and math.isnan(hodges_lehmann(np.zeros(4)))


def test_a_significant_test_whose_side_is_not_the_means_calls_neither_better():
    # B is 0.01 m/s worse on 20 trials and 1.0 better on one: the mean favours B, the test finds B worse
    a = [make_record("a", "in", 0, i, vlin_err=0.5) for i in range(21)]
    b = [make_record("b", "in", 0, i, vlin_err=0.51 if i < 20 else -0.5) for i in range(21)]
    vlin = paired_comparison(a, b, "vlin_err")
    assert vlin["diff"] < 0 < vlin["shift"] and vlin["p"] < 0.05
    entry = PairSummary(a="a", b="b", band="in", metric="vlin_err_common", ci95=tuple(vlin.pop("ci95")), **vlin)
    (sentence,) = [line for line in verdicts(Summary(scenario_name="s", scenario_hash="h", cells={},
                                                     paired=(entry,), warnings=()))]
    assert "differ in how they track the linear velocity" in sentence and "not one way" in sentence
    assert "the pairs' ranks favour a (rank-biserial r = +0.82" in sentence and "favours b" in sentence
    assert "neither is called better" in sentence and "tracks the linear velocity better" not in sentence


def test_pairs_tied_at_zero_do_not_turn_a_one_sided_test_into_a_split():
    # TTF: 30 trials both survive (tied at 0), on 10 B falls earlier: every pair that differs favours A
    a = [make_record("a", "in", 0, i, ttf=1.0) for i in range(40)]
    b = [make_record("b", "in", 0, i, ttf=1.0 if i < 30 else 0.9) for i in range(40)]
    ttf = paired_comparison(a, b, "ttf")
    assert ttf["p"] < 0.01 and ttf["rank_biserial"] == -1.0 and ttf["shift"] == pytest.approx(-0.1)
    entry = PairSummary(a="a", b="b", band="in", metric="ttf", ci95=tuple(ttf.pop("ci95")), **ttf)
    (sentence,) = verdicts(Summary(scenario_name="s", scenario_hash="h", cells={}, paired=(entry,), warnings=()))
    assert "a stays up longer than b" in sentence and "not one way" not in sentence


def test_the_hodges_lehmann_shift_of_many_pairs_is_estimated_in_bounded_memory():
    rng = np.random.default_rng(3)
    d = rng.normal(0.2, 1.0, paired_tests.HODGES_LEHMANN_EXACT_MAX + 2000)
    estimate = hodges_lehmann(d)  # from a fixed-seed sample of the Walsh averages
    assert estimate == hodges_lehmann(d) and abs(estimate - 0.2) < 0.05


def test_a_p_value_is_never_printed_on_the_other_side_of_005():
    assert p_digits(0.0499832) == "0.04998" and p_text(0.0499832) == "0.04998"
    assert p_digits(0.05) == "0.05" and p_digits(0.0500004) == "0.05"  # not significant, and written so
    assert p_digits(0.0123456) == "0.0123" and p_digits(0.9999) == "1"
    # a McNemar p just under 0.05: 117 pairs A alone won, 150 B alone (n = 300)
    p = mcnemar_exact(np.array([1] * 117 + [0] * 150 + [1] * 33), np.array([0] * 117 + [1] * 150 + [1] * 33)).p_value
    assert 0.0499 < p < 0.05 and float(p_text(p)) < 0.05


def test_a_success_interval_just_clear_of_zero_is_not_printed_as_zero():
    entry = PairSummary(a="a", b="b", band="in", metric="success_rate", diff=0.11, ci95=(0.0004, 0.226),
                        interval="exact", n=300, mean_a=0.5, mean_b=0.61, test="exact McNemar", p=0.0499832, n80=None,
                        a_only=117, b_only=150)
    (sentence,) = verdicts(Summary(scenario_name="s", scenario_hash="h", cells={}, paired=(entry,), warnings=()))
    assert "95 % interval [+4.0e-02, +22.6]" in sentence and "significant (exact McNemar p = 0.04998)" in sentence


def test_one_pair_of_a_continuous_metric_gives_no_n80_and_says_why():
    a = [make_record("a", "in", 0, 0, vlin_err=0.2, vlin_err_by_s="0.2")]
    b = [make_record("b", "in", 0, 0, vlin_err=0.3, vlin_err_by_s="0.3")]
    summary = summarize([*a, *b], scenario_name="flat_push", scenario_hash="abc123", controllers=["a", "b"],
                        bands=["in"])
    (entry,) = [p for p in summary.paired if p.metric == "vlin_err_common"]
    assert n80_text(entry) == "n/a"
    (line,) = [v for v in verdicts(summary) if "linear velocity" in v]
    assert "one pair shows nothing of how the differences spread" in line and "search's limit" not in line


# --- Wilson interval --------------------------------------------------------------------------------------------------


def test_wilson_interval_by_its_formula():
    for k, n in ((0, 10), (3, 10), (10, 10), (57, 80)):
        p, z = k / n, 1.959963984540054
        centre = (p + z * z / (2 * n)) / (1 + z * z / n)
        half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
        lo, hi = wilson_interval(k, n)
        assert lo == pytest.approx(max(0.0, centre - half), abs=1e-12)
        assert hi == pytest.approx(min(1.0, centre + half), abs=1e-12)
    assert wilson_interval(10, 10)[0] == pytest.approx(0.7225, abs=1e-4)  # 10 of 10 does not mean 100 % +- 0
    assert all(math.isnan(x) for x in wilson_interval(0, 0))
    with pytest.raises(ConfigError):
        wilson_interval(4, 3)


# --- power ------------------------------------------------------------------------------------------------------------


def test_exact_mcnemar_power_matches_simulation_and_bisection_is_tight():
    rng = np.random.default_rng(11)
    n, p_a, p_b = 40, 0.05, 0.25
    u = rng.random((4000, n))
    a_only, b_only = (u < p_a).sum(1), ((u >= p_a) & (u < p_a + p_b)).sum(1)
    m = a_only + b_only
    p = np.where(m > 0, np.minimum(1.0, 2.0 * binom.cdf(np.minimum(a_only, b_only), m, 0.5)), 1.0)
    simulated = float(np.mean(p <= 0.05))
    assert mcnemar_power(n, p_a, p_b) == pytest.approx(simulated, abs=0.025)  # 3.2 sigma of 4000 draws
    n80 = pairs_for_mcnemar(p_a, p_b)
    assert mcnemar_power(n80, p_a, p_b) >= 0.8 > mcnemar_power(n80 - 1, p_a, p_b)
    # a larger difference needs fewer pairs; a smaller one more; none observed, nothing to detect
    assert pairs_for_mcnemar(0.025, 0.475) < n80 < pairs_for_mcnemar(0.10, 0.20)
    assert pairs_for_mcnemar(0.1, 0.1) is None
    assert pairs_for_mcnemar(0.0, 1e-6) is None  # beyond the search: more than N_MAX pairs
    assert mcnemar_power(0, p_a, p_b) == 0.0 and mcnemar_power(10, 0.0, 0.0) == 0.0


def test_t_power_and_wilcoxon_pairs_agree_with_statsmodels():
    power = pytest.importorskip("statsmodels.stats.power")
    for effect in (0.2, 0.5, 1.0, 2.0):
        assert t_test_power(25, effect) == pytest.approx(power.TTestPower().power(effect, nobs=25, alpha=0.05),
                                                         abs=1e-9)
        n_t = math.ceil(power.TTestPower().solve_power(effect_size=effect, alpha=0.05, power=0.8))
        assert pairs_for_mean_difference(effect, 1.0) == max(6, math.ceil(n_t * math.pi / 3))
    assert pairs_for_mean_difference(0.01, 0.0) == 6  # identical differences: the exact test's smallest n
    assert pairs_for_mean_difference(0.0, 1.0) is None


def test_paired_comparison_on_records_counts_discordant_pairs():
    a = [make_record("a", "in", 0, i, success=i >= 2) for i in range(10)]
    b = [make_record("b", "in", 0, i, success=i != 9, vlin_err=0.1 + 0.01 * (i + 1)) for i in range(10)]
    success = paired_comparison(a, b, "success")
    assert (success["a_only"], success["b_only"], success["n"]) == (1, 2, 10)
    assert success["test"] == "exact McNemar" and success["p"] == pytest.approx(1.0)
    assert success["diff"] == pytest.approx(0.1)
    assert success["n80"] == pairs_for_mcnemar(0.1, 0.2)
    err = paired_comparison(a, b, "vlin_err")
    assert err["test"] == "Wilcoxon signed-rank" and err["p"] == pytest.approx(2 / 1024)
    assert err["a_only"] is None and err["n80"] >= 6
    values_a, values_b = paired_values(a, b[:5], "success")
    assert values_a.size == values_b.size == 5


def test_one_seed_tables_show_an_interval_over_trials_not_a_zero_spread():
    records = [make_record(c, "in", 0, i, success=(c == "a" or i < 6)) for c in ("a", "b") for i in range(10)]
    summary = summarize(records, scenario_name="flat_push", scenario_hash="abc123", controllers=["a", "b"],
                        bands=["in"])
    table = format_table(summary)
    lo, hi = wilson_interval(6, 10)
    assert f"60.00 [{100 * lo:.2f}, {100 * hi:.2f}]" in table
    assert "± 0.00" not in table
    assert "exact McNemar" in table and "n80" in table
    # several seeds: the spread across them, as the paper prints, and success's interval over all the trials
    cell = MetricSummary(mean=0.9, std=0.05, ci95=(0.8, 0.95))
    assert cell_text(cell, "success_rate", 5) == "90.00 ± 5.00 [80.00, 95.00]"
    assert cell_text(MetricSummary(mean=0.9, std=0.05, ci95=(0.8, 0.95)), "ttf", 5) == "0.900 ± 0.050"
    assert cell_text(cell, "success_rate", 1) == "90.00 [80.00, 95.00]"


# --- the sequential test ----------------------------------------------------------------------------------------------


def test_mixture_e_value_by_hand():
    # Beta(1/2, 1/2) mixture: the first discordant pair predicts 1/2 (E stays 1), then B's wins are predicted with
    # (c + 1/2) / (n + 1): 3/4 -> E = 1.5, then 5/6 -> E = 2.5
    assert math.exp(mixture_log_e(0, 0)) == pytest.approx(1.0)
    assert math.exp(mixture_log_e(0, 1)) == pytest.approx(1.0)
    assert math.exp(mixture_log_e(0, 2)) == pytest.approx(1.5)
    assert math.exp(mixture_log_e(0, 3)) == pytest.approx(2.5)
    assert mixture_log_e(3, 0) == pytest.approx(mixture_log_e(0, 3))
    test = DiscordantPairTest(alpha=0.05)
    for _ in range(6):
        test.observe(False, True)
        test.observe(True, True)  # concordant pairs change nothing
    assert not test.rejected and test.b_only == 6 and test.pairs == 12
    test.observe(False, True)  # the 7th win: E = 26.8 >= 20
    assert test.rejected and test.rejected_after == 13 and test.p_value == pytest.approx(math.exp(-test.log_e))


def _null_streams(rng, runs, pairs, discordance):
    u = rng.random((runs, pairs))
    return np.cumsum(u < discordance / 2, axis=1), np.cumsum((u >= discordance / 2) & (u < discordance), axis=1)


def test_sequential_test_keeps_its_error_rate_on_null_streams_where_repeated_mcnemar_does_not():
    rng = np.random.default_rng(2024)
    runs, pairs, alpha = 2000, 300, 0.05
    margin = 3 * math.sqrt(alpha * (1 - alpha) / runs)
    for discordance in (0.2, 1.0):
        a_only, b_only = _null_streams(rng, runs, pairs, discordance)
        # the mixture test, looked at after every pair
        sequential = np.mean((mixture_log_e(a_only, b_only) >= math.log(1 / alpha)).any(axis=1))
        assert sequential <= alpha + margin
        # the exact McNemar test looked at after every pair and stopped at the first p <= alpha
        m = a_only + b_only
        p = np.where(m > 0, np.minimum(1.0, 2.0 * binom.cdf(np.minimum(a_only, b_only), m, 0.5)), 1.0)
        naive = np.mean((p <= alpha).any(axis=1))
        assert naive > 3 * alpha


def test_sequential_test_stops_early_on_a_clear_difference():
    rng = np.random.default_rng(7)
    runs, pairs = 2000, 200
    # A succeeds in 50 % of the trials and B in 95 %, independently: 2.5 % "A only", 47.5 % "B only"
    u = rng.random((runs, pairs))
    a_only, b_only = np.cumsum(u < 0.025, axis=1), np.cumsum((u >= 0.025) & (u < 0.5), axis=1)
    hit = mixture_log_e(a_only, b_only) >= math.log(20)
    stop = np.where(hit.any(axis=1), hit.argmax(axis=1) + 1, pairs + 1)
    assert np.all(stop <= pairs) and np.mean(stop <= 50) >= 0.99
    assert np.median(stop) <= 20  # the fixed-n exact McNemar test needs 19 pairs for 80 % power here
    assert pairs_for_mcnemar(0.025, 0.475) == 19


def test_sequential_comparison_splits_alpha_and_refuses_incomplete_rounds():
    comparison = SequentialComparison([("a", "b"), ("a", "c")], ["in", "ood"], alpha=0.05)
    assert all(t.alpha == pytest.approx(0.0125) for t in comparison.tests.values())
    with pytest.raises(RecordError, match="lacks the record of c"):
        comparison.add_round([make_record("a", "in", 0, 0), make_record("b", "in", 0, 0)])
    with pytest.raises(ConfigError):
        SequentialComparison([], ["in"])


def test_a_sequential_stop_is_reported_at_the_round_it_settled_and_the_rounds_under_way_after_it():
    comparison = SequentialComparison([("a", "b")], ["in"], alpha=0.05)
    # every pair discordant: the mixture reaches 1 / alpha = 20 at the 7th round; an 8th was under way
    for k in range(8):
        comparison.add_round([make_record("a", "in", 0, k), make_record("b", "in", 0, k, success=False)])
    state = comparison.as_dict()
    assert (state["settled"], state["settled_after_rounds"], state["rounds"]) == (True, 7, 8)
    line = _sequential_lines(state)[0]
    assert "every tested difference settled after 7 rounds (8 played: the 1 after it were under way" in line



def test_until_significant_stops_the_run_once_the_difference_is_settled(limp, tmp_path):
    scenario = tmp_path / "short.toml"
    scenario.write_text(SHORT_SCENARIO)
    cfg = ArenaConfig(controllers=("stand", limp), scenario=scenario, trials=12, out_dir=tmp_path / "run",
                      workers=1, progress=False, until_significant=True)
    result = run_arena(cfg)
    records = TrialRecord.read_csv(tmp_path / "run" / "trials.csv")
    # stand survives every soft push and the limp robot falls every time: every pair is discordant, and the mixture
    # test reaches 1 / alpha = 20 at the 7th (E = 1, 1, 1.5, 2.5, 4.4, 7.9, 14.4, 26.8)
    assert all(r.success for r in records if r.controller == "stand")
    assert not any(r.success for r in records if r.controller == limp)
    sequential = result.summary.sequential
    assert sequential["settled"] and sequential["rounds"] == 7
    assert sequential["tests"][0]["rejected_after_pairs"] == 7 and sequential["tests"][0]["b_only"] == 0
    assert len(records) == 14 and result.played == 14 and result.budget == 24
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["sequential"] == sequential
    report = (tmp_path / "run" / "report.md").read_text()
    assert "7 of at most 12: the sequential test settled every difference after 7 rounds" in report
    assert "after the sequential test's stop these p-values are optimistic" in format_verdict(result.summary)
    # resuming the finished run plays nothing more; a fixed-budget run is another configuration
    again = run_arena(ArenaConfig(**{**cfg.__dict__, "resume": True}))
    assert again.played == 0 and again.summary == result.summary
    with pytest.raises(ConfigError, match="local executor"):
        ArenaConfig(controllers=("stand", limp), scenario=scenario, executor="ray", until_significant=True)


def _verdict_of(a_records, b_records, metric, band="in"):
    entry = compare_pair(a_records, b_records, a="a", b="b", band=band, metric=metric)
    return entry, verdicts(Summary(scenario_name="s", scenario_hash="h", cells={}, paired=(entry,), warnings=()))


def test_a_survival_difference_the_test_does_not_reject_is_neither_a_winner_nor_an_equivalence():
    # 20 pairs, 6 : 5 discordant: the interval spans about -51 to +41 points, n80 is in the thousands
    a = [make_record("a", "in", 0, i, success=i < 6 or i >= 11) for i in range(20)]
    b = [make_record("b", "in", 0, i, success=i >= 6) for i in range(20)]
    entry, (sentence,) = _verdict_of(a, b, "success_rate")
    assert entry.p == 1.0 and entry.n80 > 1000
    assert sentence.startswith("band in: a and b do not differ significantly in survival: a 15 against 14 of 20")
    assert "survives more than" not in sentence and "practical purposes" not in sentence
    assert "there is none" not in sentence and "leaves the difference open" in sentence
    assert f"about {entry.n80} paired trials would settle" in sentence


def test_tracking_and_fall_times_the_test_does_not_reject_do_not_open_with_a_better_side():
    rng = np.random.default_rng(5)
    d = rng.normal(0.0, 0.05, 12)
    d = d - d.mean() + 0.002
    a = [make_record("a", "in", 0, i, vlin_err=0.2, vlin_err_by_s="0.2", ttf=0.5, success=False) for i in range(12)]
    b = [make_record("b", "in", 0, i, vlin_err=0.2 + d[i], vlin_err_by_s=repr(float(0.2 + d[i])), ttf=0.5 + d[i],
                     success=False) for i in range(12)]
    for metric, subject in (("vlin_err_common", "how they track the linear velocity"),
                            ("ttf", "how long they stay up (TTF)")):
        entry, (sentence,) = _verdict_of(a, b, metric)
        assert not entry.significant
        assert sentence.startswith(f"band in: a and b do not differ significantly in {subject}"), sentence
        assert "better than" not in sentence and "longer than" not in sentence and "there is none" not in sentence


def test_a_significant_test_with_a_zero_mean_difference_follows_the_tests_lean():
    # 16 pairs lean one way by a little, one pair the other way by as much as all of them: the mean difference is 0
    t_a = [0.5] * 16 + [1.0]
    t_b = [0.5625] * 16 + [0.0]
    a = [make_record("a", "in", 0, i, ttf=t_a[i], success=False) for i in range(17)]
    b = [make_record("b", "in", 0, i, ttf=t_b[i], success=False) for i in range(17)]
    entry, (sentence,) = _verdict_of(a, b, "ttf")
    assert entry.diff == 0.0 and entry.significant and entry.rank_biserial > 0
    assert sentence.startswith("band in: b stays up longer than a"), sentence
    e_a = [0.1] * 17
    e_b = [0.0375] * 16 + [1.1]
    a = [make_record("a", "in", 0, i, vlin_err_by_s=f"{e_a[i]!r}") for i in range(17)]
    b = [make_record("b", "in", 0, i, vlin_err_by_s=f"{e_b[i]!r}") for i in range(17)]
    entry, (sentence,) = _verdict_of(a, b, "vlin_err_common")
    assert entry.diff == pytest.approx(0.0, abs=1e-15) and entry.significant and entry.rank_biserial < 0
    assert sentence.startswith("band in: b tracks the linear velocity better than a"), sentence


def test_a_negated_zero_is_written_with_a_plus_sign():
    assert signed(-0.0, 3) == "+0.000" and signed(-0.0, 1) == "+0.0"
    assert signed(-1e-5, 3) == "-1.0e-05" and signed(-0.25, 1) == "-0.2"


def test_reportmd_qualifies_significance_after_a_sequential_stop_as_the_printed_table_does(tmp_path):
    records = [make_record(c, "in", 0, i, success=(c == "a" or i < 3)) for c in ("a", "b") for i in range(8)]
    summary = summarize(records, scenario_name="flat_push", scenario_hash="abc123", controllers=["a", "b"],
                        bands=["in"])
    comparison = SequentialComparison([("a", "b")], ["in"], alpha=0.05)
    for k in range(8):
        comparison.add_round([records[k], records[8 + k]])
    sequential = dataclasses.replace(summary, sequential=comparison.as_dict())
    write_report(tmp_path / "seq", sequential, records, {})
    report = (tmp_path / "seq" / "report.md").read_text(encoding="utf-8")
    verdict_section = report.split("## Verdict")[1].split("## Results")[0]
    assert "after the sequential test's stop these p-values are optimistic" in verdict_section
    assert "after the sequential test's stop these p-values are optimistic" in format_verdict(sequential)
    write_report(tmp_path / "fixed", summary, records, {})
    fixed = (tmp_path / "fixed" / "report.md").read_text(encoding="utf-8")
    assert "(paired trials; significant: p < 0.05)" in fixed and "optimistic" not in fixed


def test_a_several_seed_success_cell_shows_its_wilson_interval_beside_the_spread_of_seed_means():
    # every trial of both seeds succeeds: the seeds' means do not spread, the success rate is still uncertain
    records = [make_record("a", "in", s, i) for s in (0, 1) for i in range(8)]
    summary = summarize(records, scenario_name="flat_push", scenario_hash="abc123", controllers=["a"], bands=["in"])
    lo, hi = wilson_interval(16, 16)
    table = format_table(summary)
    assert f"100.00 ± 0.00 [{100 * lo:.2f}, {100 * hi:.2f}]" in table and lo < 0.85
    assert "not the mean's uncertainty" in table
