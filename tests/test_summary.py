"""Samples to threshold, the threshold's meaning and the shared-seed comparison, on known answers."""

import math

import pytest

from tatl_mj.experiments import summary


def test_samples_to_threshold_is_where_the_return_stays_above():
    budgets = [100, 200, 400, 800]
    # Crosses at 100, falls back at 200, stays from 400 on: 400, not 100.
    assert summary.samples_to_threshold(budgets, [5, 1, 5, 6], threshold=5) == 400
    assert summary.samples_to_threshold(budgets, [5, 5, 5, 5], threshold=5) == 100  # "at or above"
    # Reaches it and ends below: never.
    assert summary.samples_to_threshold(budgets, [9, 9, 9, 4.99], threshold=5) == math.inf
    assert summary.samples_to_threshold(budgets, [9, float("nan"), 9, 9], threshold=5) == 400


def test_samples_to_threshold_rejects_bad_curves():
    with pytest.raises(ValueError, match="differ in length"):
        summary.samples_to_threshold([1, 2], [1.0], 0.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        summary.samples_to_threshold([2, 1], [1.0, 1.0], 0.0)


def test_threshold_at_or_below_random_is_not_meaningful():
    threshold, best, meaningful = summary.threshold_for({"a": 10.0, "b": 0.0}, random_return=-10.0)
    assert (threshold, best, meaningful) == (pytest.approx(9.0), "a", True)
    # Best final return below random: the threshold lies below random too.
    threshold, best, meaningful = summary.threshold_for({"a": -20.0, "b": -30.0}, random_return=-10.0)
    assert threshold == pytest.approx(-19.5) and best == "a" and not meaningful
    assert not summary.threshold_for({"a": -10.0}, random_return=-10.0)[2]  # equal: not above


def experiment(methods: dict, random_returns: dict) -> dict:
    """A summary experiment from {method: {seed: [return per budget]}} at budgets 100, 1000."""
    return {
        "methods": {
            m: {
                "seeds": sorted(runs),
                "final_return": [runs[s][-1] for s in sorted(runs)],
                "curve": {"samples": [100, 1000], "mean_return": [runs[s] for s in sorted(runs)]},
            }
            for m, runs in methods.items()
        },
        "source_seeds": sorted(random_returns),
        "random_returns": [random_returns[s] for s in sorted(random_returns)],
    }


def test_compare_uses_only_shared_seeds():
    exp = experiment(
        {"a": {0: [0, 10], 1: [10, 10]}, "b": {0: [0, 2], 1: [0, 4], 2: [50, 50]}},
        random_returns={0: 0.0, 1: 2.0, 2: 100.0},
    )
    c = summary.compare(exp)
    assert c.seeds == (0, 1) and c.seed_sets_differ
    assert c.random_return == pytest.approx(1.0)  # seed 2's source is not compared either
    # b's seed 2 (final 50) would make b the best; over the shared seeds a is (mean 10).
    assert c.best_method == "a" and c.threshold == pytest.approx(1 + 0.95 * 9)
    a, b = c.methods
    assert a.samples_to_threshold == (1000, 100) and a.median_samples == 550
    assert b.samples_to_threshold == (math.inf, math.inf) and b.extra_seeds == (2,)
    assert b.final_returns == (2, 4)


def test_compare_names_methods_without_any_seed():
    exp = experiment({"a": {0: [0, 10]}}, random_returns={0: 0.0})
    c = summary.compare(exp, ["a", "b"])
    assert c.missing == ("b",) and c.seed_sets_differ and [r.method for r in c.methods] == ["a"]
    same = summary.compare(experiment({"a": {0: [0, 1]}, "b": {0: [1, 1]}}, random_returns={0: 0.0}))
    assert not same.seed_sets_differ


def test_compare_without_meaningful_threshold_reports_no_samples():
    exp = experiment({"a": {0: [-50, -20]}, "b": {0: [-5, -30]}}, random_returns={0: -10.0})
    c = summary.compare(exp)
    assert not c.meaningful and c.best_method == "a"
    assert all(r.samples_to_threshold == () for r in c.methods)


SEEDS3 = {0: 0.0, 1: 0.0, 2: 0.0}


@pytest.mark.parametrize(
    "mine, verdict",
    [
        # same final returns (10), but mine reaches the threshold (9.5) at 100 on every seed, the ablation at 1000
        ({0: [10, 10], 1: [10, 10], 2: [10, 10]}, "**beats**"),
        # both at the cap from 100 samples: a tie
        ({0: [0, 10], 1: [0, 10], 2: [0, 10]}, "**does not beat** its source-free ablation (no clear difference)"),
        # lower final return on every seed, never reaching the threshold
        ({0: [0, 2], 1: [0, 3], 2: [0, 4]}, "it is **worse**"),
    ],
)
def test_ablation_verdict_reads_returns_and_samples_seed_by_seed(mine, verdict):
    ablation = {0: [0, 10], 1: [0, 10], 2: [0, 10]}
    c = summary.compare(experiment({"ta-tl-h": mine, "apprentice-upright": ablation}, SEEDS3))
    text = summary.ablation_verdict(c, "ta-tl-h", "apprentice-upright")
    assert text.startswith("`ta-tl-h` vs `apprentice-upright`: mean final return") and verdict in text, text
    assert summary.ablation_verdict(c, "ta-tl-h", "replan-no-source") is None


def test_ablation_pairs_follow_built_ins_and_variants():
    methods = {
        "ta-tl": {},
        "ta-tl-h": {"horizon": 20},
        "ta-tl-h-no-cart": {"method": "ta-tl-h", "source_zero": ["x"]},
        "apprentice-upright": {},
        "rl": {},
    }
    assert summary.ablation_pairs(methods) == [
        ("ta-tl-h", "apprentice-upright"),
        ("ta-tl-h-no-cart", "apprentice-upright"),
    ]
    assert summary.ablation_pairs({"ta-tl-replan": {}, "rl": {}}) == []  # no ablation listed: nothing to say
