"""Interval estimates (tatl_mj.experiments.results.statistics) against independent computations."""

import numpy as np
import pytest

from tatl_mj.experiments.results import statistics as st
from tatl_mj.experiments.results import verdicts


def test_iqm_is_the_mean_of_the_middle_half():
    x = np.array([9.0, -3.0, 1.0, 4.0, 100.0, 2.0, 7.0, 0.0])  # sorted: -3 0 1 2 4 7 9 100
    assert st.iqm(x) == pytest.approx((1 + 2 + 4 + 7) / 4)
    assert st.iqm(np.arange(4.0)) == pytest.approx(1.5)


def test_normalised_scores_put_random_at_0_and_the_reference_at_1():
    np.testing.assert_allclose(verdicts.normalised([-10.0, 0.0, 5.0], -10.0, 0.0), [0.0, 1.0, 1.5])
    np.testing.assert_allclose(verdicts.normalised([1.0, 1.0], np.array([0.0, 0.5]), 2.0), [0.5, 1 / 3])
    with pytest.raises(ValueError, match="must lie above the random"):
        verdicts.normalised([1.0], 3.0, 2.0)


def _manual_iqm_interval(strata, reps, rng):
    stats = []
    for _ in range(reps):
        stats.append(st.iqm(np.concatenate([rng.choice(s, size=len(s), replace=True) for s in strata])))
    return np.percentile(stats, [2.5, 97.5])


def test_iqm_interval_matches_an_independent_stratified_bootstrap():
    rng = np.random.default_rng(5)
    strata = [rng.normal(0.0, 1.0, 10), rng.normal(2.0, 0.5, 7)]
    estimate = st.iqm_interval(strata)
    assert estimate.value == pytest.approx(st.iqm(np.concatenate(strata)))
    low, high = _manual_iqm_interval(strata, 4000, np.random.default_rng(1))
    assert estimate.low == pytest.approx(low, abs=0.08) and estimate.high == pytest.approx(high, abs=0.08)
    assert estimate.low < estimate.value < estimate.high


def test_probability_of_improvement_is_the_mann_whitney_statistic():
    x, y = np.array([1.0, 2.0, 3.0]), np.array([2.0, 0.0])
    # Pairs: (1>2 no, 1>0 yes), (2=2 half, 2>0 yes), (3>2 yes, 3>0 yes): 4.5 of 6.
    assert st.improvement_interval([(x, y)]).value == pytest.approx(4.5 / 6)
    u = __import__("scipy.stats").stats.mannwhitneyu(x, y).statistic
    assert st.improvement_interval([(x, y)]).value == pytest.approx(u / 6)


def test_a_method_identical_to_its_ablation_is_not_credited():
    scores = np.random.default_rng(0).normal(size=10)
    estimate = st.improvement_interval([(scores, scores.copy())])
    assert estimate.value == pytest.approx(0.5) and estimate.low < 0.5 < estimate.high
    assert verdicts.verdict(estimate) == verdicts.NOT_CREDITED
    same = st.improvement_interval([(np.ones(5), np.ones(5))])  # all tied: the interval is the point
    assert (same.value, same.low, same.high) == (0.5, 0.5, 0.5) and verdicts.verdict(same) == verdicts.NOT_CREDITED


def test_a_clearly_better_method_is_credited_and_a_clearly_worse_one_is_worse():
    rng = np.random.default_rng(1)
    good, bad = rng.normal(5.0, 1.0, 10), rng.normal(0.0, 1.0, 10)
    assert verdicts.verdict(st.improvement_interval([(good, bad)])) == verdicts.CREDITED
    assert verdicts.verdict(st.improvement_interval([(bad, good)])) == verdicts.WORSE
    # One seed each: no interval, so no credit either way.
    one = st.improvement_interval([(good[:1], bad[:1])])
    assert one.value == 1.0 and np.isnan(one.low) and verdicts.verdict(one) == verdicts.NOT_CREDITED


def test_area_under_the_curve_over_log_budget():
    budgets = [10, 100, 1000]
    assert st.area_under_curve(budgets, np.ones(3)) == pytest.approx(1.0)
    # 0 then 1 then 1 over equal log steps: (0.5 + 1) / 2.
    np.testing.assert_allclose(st.area_under_curve(budgets, np.array([[0.0, 1.0, 1.0]])), [0.75])


def test_performance_profile_counts_runs_above_each_tau():
    np.testing.assert_allclose(st.performance_profile([0.1, 0.5, 0.9, 1.2], [0.0, 0.5, 1.0]), [1.0, 0.5, 0.25])


def test_rliable_agrees_where_it_installs():
    """An optional cross-check: rliable's IQM and probability of improvement on the same arrays."""
    rly = pytest.importorskip("rliable.metrics", reason="rliable is an optional cross-check")
    rng = np.random.default_rng(3)
    x, y = rng.normal(1.0, 1.0, (12, 1)), rng.normal(0.0, 1.0, (12, 1))
    assert float(rly.aggregate_iqm(x)) == pytest.approx(st.iqm(x.ravel()))
    assert float(rly.probability_of_improvement(x, y)) == pytest.approx(
        st.improvement_interval([(x[:, 0], y[:, 0])]).value
    )


def test_kaplan_meier_equals_the_textbook_product():
    # Ends at 2, 3, 3 and 5; two episodes reach the cap of 8 (censored).
    times, s = st.survival([3, 2, 8, 5, 3, 8], cap=8)
    np.testing.assert_allclose(times, [2, 3, 5])
    # S(t) = prod over end times t_i <= t of (1 - d_i / n_i): 1 of 6 at risk ends at 2,
    # 2 of 5 at 3, 1 of 3 at 5.
    np.testing.assert_allclose(s, [5 / 6, 5 / 6 * 3 / 5, 5 / 6 * 3 / 5 * 2 / 3])
    assert st.survival([8, 8], cap=8)[0].size == 0  # nobody fell: no curve to draw


def test_the_across_experiments_interval_does_not_depend_on_the_specs_order():
    # The bootstrap resamples each experiment's seeds in stratum order; the same records given
    # in another order (another command line, or summary.json's sorted keys) give the same interval.
    from tatl_mj.experiments.results import summary

    rng = np.random.default_rng(3)
    experiments = {
        name: {"methods": {"rl": {"seeds": list(range(10)), "normalised": np.c_[np.zeros(10), rng.normal(m, 1, 10)]}}}
        for name, m in (("mc_to_ip", -1.0), ("bicycle", 0.5), ("grid", 1.0), ("flipped", -0.2))
    }
    given = summary.aggregate(experiments)["rl"]
    reordered = summary.aggregate(dict(reversed(list(experiments.items()))))["rl"]
    assert (given["low"], given["high"]) == (reordered["low"], reordered["high"])
    assert given["low"] < given["value"] < given["high"]


def test_seeds_to_credit_is_what_the_exact_sign_test_can_resolve():
    # Five seeds cannot credit at all: 5 of 5 gives [0.48, 1.00], which holds 0.5.
    five = verdicts.sign_probability(verdicts.PairedSigns(5, 0, 0))
    assert (round(five.low, 2), five.high) == (0.48, 1.0)
    assert verdicts.seeds_to_credit(5) is None
    assert verdicts.seeds_to_credit(6) == 6  # 6 of 6: [0.54, 1.00]
    assert verdicts.seeds_to_credit(10) == 9  # 9 of 10: [0.555, 0.997]; 8 of 10 holds 0.5
    assert verdicts.verdict(verdicts.sign_probability(verdicts.PairedSigns(9, 0, 1))) == verdicts.CREDITED
    assert verdicts.verdict(verdicts.sign_probability(verdicts.PairedSigns(8, 0, 2))) == verdicts.NOT_CREDITED
    assert verdicts.verdict(verdicts.sign_probability(verdicts.PairedSigns(1, 0, 9))) == verdicts.WORSE
    assert verdicts.seeds_to_credit(1) is None
