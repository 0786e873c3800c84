"""The verdict rule (tatl_mj.experiments.results.verdicts): known answers, declared before any rerun.

The five cases the rule must get right (docs/protocol.md, "Verdicts"), each through the
rule's whole path (``verdicts.scored`` per method, then ``verdicts.judge``), then the pieces
against independent computations.
"""

import math

import numpy as np
import pytest
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as hs

from tatl_mj.experiments.results import pairs, verdicts
from tatl_mj.experiments.results import verdicts as st
from tatl_mj.experiments.results.summary_data import Curve, Interval, MethodSummary

BUDGETS = [100, 1000, 10000]
REFERENCE = 10.0


def _experiment(runs: dict, counts: dict | None = None, rollouts: dict | None = None) -> dict:
    """A summary experiment from {method: [[return per budget] per seed]}, random return 0 on every
    seed, counted transitions the budgets unless ``counts[method]`` gives them (per budget)."""
    counts, rollouts = counts or {}, rollouts or {}
    seeds = range(len(next(iter(runs.values()))))
    methods = {}
    for name, returns in runs.items():
        counted = counts.get(name, BUDGETS)
        methods[name] = {
            "seeds": list(seeds),
            "final_return": [r[-1] for r in returns],
            "curve": {
                "samples": BUDGETS,
                "mean_return": [list(r) for r in returns],
                "target_transitions": [list(counted) for _ in seeds],
                "rollout_transitions": [list(rollouts.get(name, [0] * len(BUDGETS))) for _ in seeds],
            },
        }
    return {
        "methods": methods,
        "source_seeds": list(seeds),
        "random_returns": [0.0 for _ in seeds],
        "reference_return": REFERENCE,
    }


def _judged(runs: dict, spec_methods: dict, **kwargs) -> dict:
    exp = _experiment(runs, **kwargs)
    per_seed: dict = {q: {} for q in verdicts.QUESTIONS}
    paper = {}
    for name, data in exp["methods"].items():
        curve = data["curve"]
        randoms = np.asarray(exp["random_returns"])
        scored = verdicts.scored(
            curve["mean_return"], randoms, REFERENCE, curve["target_transitions"], curve["rollout_transitions"], BUDGETS
        )
        per_seed[verdicts.FINAL][name] = scored.final
        per_seed[verdicts.EFFICIENCY][name] = scored.efficiency[verdicts.COUNTED]
        paper[name] = scored.efficiency[verdicts.PAPER]
    return {(v["method"], v["other"]): v for v in verdicts.judge({"methods": spec_methods}, per_seed, paper)}


SPEC = {"ta-tl": {}, "apprentice-fqi": {}}


def _returns(seed: int = 0, n: int = 10) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-5.0, 12.0, size=(n, len(BUDGETS)))


def test_a_method_against_an_exact_copy_of_itself_is_not_credited_on_either_question():
    runs = _returns(1)
    pair = _judged({"ta-tl": runs, "apprentice-fqi": runs.copy()}, SPEC)[("ta-tl", "apprentice-fqi")]
    for question in verdicts.QUESTIONS:
        assert pair[question]["seeds"] == {"better": 0, "tied": 10, "worse": 0}
        assert pair[question]["probability"]["value"] == 0.5
        assert pair[question]["verdict"] == st.NOT_CREDITED
        assert pair[question]["median_difference"]["value"] == 0.0


def test_a_constant_extra_charge_with_the_same_returns_is_not_credited_on_final():
    # The same returns at every budget, but 2,000 more transitions counted at each (Algorithm 2's
    # U_M rollouts): the final question does not see the charge; the efficiency question does.
    runs = np.tile([8.0, 9.0, 9.5], (10, 1)) + np.linspace(0, 0.5, 10)[:, None]
    charged = [b + 2000 for b in BUDGETS]
    pair = _judged(
        {"ta-tl": runs, "apprentice-fqi": runs.copy()},
        SPEC,
        counts={"ta-tl": charged},
        rollouts={"ta-tl": [2000] * 3},
    )[("ta-tl", "apprentice-fqi")]
    assert pair["final"]["verdict"] == st.NOT_CREDITED and pair["final"]["seeds"]["tied"] == 10
    assert pair["efficiency"]["verdict"] == st.WORSE and pair["efficiency"]["seeds"]["worse"] == 10
    # On the paper's accounting (apprentice samples only) the charge is gone: a tie again.
    assert pair["efficiency_paper"]["verdict"] == st.NOT_CREDITED
    assert pair["efficiency_paper"]["seeds"]["tied"] == 10


@settings(max_examples=60, deadline=None)
@given(
    hs.lists(
        hs.lists(hs.floats(-1e6, 1e3, allow_nan=False), min_size=3, max_size=3),
        min_size=1,
        max_size=12,
    ),
    hs.lists(hs.integers(100, 5000), min_size=3, max_size=3),
)
def test_identical_per_seed_returns_are_never_worse_on_final(returns, extra):
    runs = np.asarray(returns, dtype=np.float64)
    other = np.asarray(runs) + 0.0
    counts = {"ta-tl": [b + e for b, e in zip(BUDGETS, sorted(extra))]}
    pair = _judged({"ta-tl": runs, "apprentice-fqi": other}, SPEC, counts=counts)[("ta-tl", "apprentice-fqi")]
    assert pair["final"]["verdict"] == st.NOT_CREDITED
    assert pair["final"]["probability"]["value"] == 0.5


def test_the_pairing_changes_p_where_seeds_are_correlated():
    # Seeds differ a lot (an easy seed, a hard seed), and on every seed the method is a little
    # better than its ablation: unpaired, its seeds look like the ablation's; paired, it wins all.
    seed_level = np.linspace(-4.0, 9.0, 10)[:, None]
    other = np.tile([1.0, 2.0, 3.0], (10, 1)) * 0 + seed_level
    mine = other + 0.05
    pair = _judged({"ta-tl": mine, "apprentice-fqi": other}, SPEC)[("ta-tl", "apprentice-fqi")]
    final = pair["final"]
    assert final["seeds"] == {"better": 10, "tied": 0, "worse": 0}
    assert final["probability"]["value"] == 1.0 and final["verdict"] == st.CREDITED
    assert 0.5 <= final["unpaired_probability"]["value"] < 0.6
    assert final["unpaired_probability"]["low"] < 0.5 < final["unpaired_probability"]["high"]


def test_ten_of_ten_seeds_agreeing_gives_a_defined_interval_and_a_verdict():
    other = _returns(2)
    better = _judged({"ta-tl": other + 3.0, "apprentice-fqi": other}, SPEC)[("ta-tl", "apprentice-fqi")]
    worse = _judged({"ta-tl": other - 3.0, "apprentice-fqi": other}, SPEC)[("ta-tl", "apprentice-fqi")]
    for pair, verdict, value in ((better, st.CREDITED, 1.0), (worse, st.WORSE, 0.0)):
        for question in verdicts.QUESTIONS:
            estimate = pair[question]["probability"]
            assert estimate["value"] == value and pair[question]["verdict"] == verdict
            assert all(math.isfinite(estimate[k]) for k in ("low", "high")) and estimate["low"] < estimate["high"]
    # 0.025 ** (1 / 10): the exact lower bound at 10 of 10.
    assert better["final"]["probability"]["low"] == pytest.approx(0.025**0.1)
    assert worse["final"]["probability"]["high"] == pytest.approx(1 - 0.025**0.1)


# --- the pieces, against independent computations ---------------------------------


@pytest.mark.parametrize("k", range(11))
def test_the_sign_interval_and_p_value_are_clopper_pearson_and_the_exact_binomial_test(k):
    signs = st.PairedSigns(better=k, tied=0, worse=10 - k)
    estimate = st.sign_probability(signs)
    ci = scipy.stats.binomtest(k, 10).proportion_ci(confidence_level=0.95, method="exact")
    assert estimate.value == k / 10
    assert (estimate.low, estimate.high) == (pytest.approx(ci.low), pytest.approx(ci.high))
    assert st.sign_p_value(signs) == pytest.approx(scipy.stats.binomtest(k, 10).pvalue)
    # The interval and the test agree: the interval leaves 0.5 out exactly when p < 0.05.
    assert (st.verdict(estimate) != st.NOT_CREDITED) == (st.sign_p_value(signs) < 0.05)


def test_ties_count_half_in_the_sign_statistic():
    signs = st.paired_signs(np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.0, 2.0, 3.0 + 1e-12, 5.0]))
    assert signs == st.PairedSigns(better=1, tied=2, worse=1)
    assert st.sign_probability(signs).value == 0.5
    assert st.paired_signs([1.0, np.nan], [0.0, 0.0]) == st.PairedSigns(1, 1, 0)  # NaN: no side's seed
    with pytest.raises(ValueError, match="one value per seed"):
        st.paired_signs([1.0, 2.0], [1.0])


def test_the_median_difference_interval_is_the_order_statistics_one():
    x = np.arange(10.0)
    estimate = st.median_difference(x, np.zeros(10))
    assert (estimate.value, estimate.low, estimate.high) == (4.5, 1.0, 8.0)  # d_(2), d_(9) at n = 10
    # Its coverage is at least 95% for the median of any continuous distribution: 1 - 2 P(Bin <= 1).
    assert 1 - 2 * scipy.stats.binom.cdf(1, 10, 0.5) >= 0.95 > 1 - 2 * scipy.stats.binom.cdf(2, 10, 0.5)
    six = st.median_difference(np.arange(6.0), np.zeros(6))
    assert (six.low, six.high) == (0.0, 5.0)
    five = st.median_difference(np.arange(5.0), np.zeros(5))  # 2 * 0.5 ** 5 > 0.05: no 95% interval
    assert five.value == 2.0 and math.isnan(five.low)


def test_holm_steps_down_over_the_declared_family():
    # m = 4: thresholds 0.0125, 0.0167, 0.025, 0.05 in order of the sorted p-values.
    assert st.holm([0.01, 0.04, 0.015, 0.2], 4) == [True, False, True, False]
    assert st.holm([0.01, 0.02], 4) == [True, False]  # 0.02 > 0.05 / 3: a larger declared family
    assert st.holm([0.001, float("nan")], 2) == [True, False]
    with pytest.raises(ValueError, match="cannot hold"):
        st.holm([0.1, 0.2, 0.3], 2)


def test_the_efficiency_area_is_exact_over_a_fixed_log_range():
    # A policy from 100 transitions on at score 1: the whole range.
    assert st.efficiency_area([[100, 1000]], [[1.0, 1.0]], 100, 10000)[0] == pytest.approx(1.0)
    # First policy at 1,000 of [100, 10,000]: half the log range at the random policy's 0.
    assert st.efficiency_area([[1000, 5000]], [[1.0, 1.0]], 100, 10000)[0] == pytest.approx(0.5)
    # 'before' says what a method scores before its first policy.
    assert st.efficiency_area([[1000]], [[1.0]], 100, 10000, before=0.5)[0] == pytest.approx(0.75)
    # Floored at -1: a blown-up fit counts as -1, not -10^6.
    assert st.efficiency_area([[100, 1000]], [[-1e6, 1.0]], 100, 10000)[0] == pytest.approx(0.0)
    # A point counted beyond the range's end does not enter it.
    assert st.efficiency_area([[100, 20000]], [[0.5, 1.0]], 100, 10000)[0] == pytest.approx(0.5)
    # Equal counts: the later budget holds from there on.
    assert st.efficiency_area([[1000, 1000]], [[0.0, 1.0]], 100, 10000)[0] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="0 < low < high"):
        st.efficiency_area([[1]], [[1.0]], 100, 100)


RBF = {"kind": "rbf", "centers": 9, "low": [-1.0, -1.0], "high": [1.0, 1.0], "sigma": [0.5, 0.5]}
FLIPPED = {  # each table builds its method: the pairs are declared from the methods' roles
    "ta-tl": {},
    "ta-tl-placebo": {"method": "ta-tl", "source": "placebo"},
    "ta-tl-rbf": {"method": "ta-tl", "apprentice": RBF, "ablation": "apprentice-fqi-rbf"},
    "apprentice-fqi": {},
    "apprentice-fqi-rbf": {"method": "apprentice-fqi", "apprentice": RBF},
    "rl-reset": {},
    "uma-tl-reset": {},
}


def test_pairs_and_families_are_declared_by_the_spec():
    spec = {"name": "flip", "methods": FLIPPED, "best_baseline": {"final": "rl-reset", "efficiency": "uma-tl-reset"}}
    roles = {(p.method, p.other): (p.role, p.questions) for p in pairs.declared_pairs(spec)}
    assert roles[("ta-tl", "apprentice-fqi")] == ("ablation", verdicts.QUESTIONS)
    # An explicit key overrides the built-in pairing (the RBF apprentice against its own ablation).
    assert roles[("ta-tl-rbf", "apprentice-fqi-rbf")] == ("ablation", verdicts.QUESTIONS)
    assert ("ta-tl-rbf", "apprentice-fqi") not in roles
    assert roles[("ta-tl", "ta-tl-placebo")] == ("placebo", verdicts.QUESTIONS)
    # Two frozen baselines: each pair asks only the question its baseline was chosen for.
    assert roles[("ta-tl", "rl-reset")] == ("best baseline", ("final",))
    assert roles[("ta-tl", "uma-tl-reset")] == ("best baseline", ("efficiency",))
    assert ("rl-reset", "uma-tl-reset") not in roles  # baselines are not compared with each other
    assert roles[("uma-tl-reset", "rl-reset")] == ("ablation", verdicts.QUESTIONS)  # the registry's pairing
    # 4 ablation and placebo pairs ask both; 5 non-baselines against each frozen baseline.
    assert pairs.family_sizes(spec) == {"final": 4 + 5, "efficiency": 4 + 5}
    # The family does not depend on which methods a run holds.
    judged = verdicts.judge(spec, {q: {"ta-tl": np.ones(3), "apprentice-fqi": np.zeros(3)} for q in verdicts.QUESTIONS})
    assert [(v["method"], v["other"]) for v in judged] == [("ta-tl", "apprentice-fqi")]


def test_a_variants_pairs_of_two_source_free_methods_are_its_parents():
    spec = {"name": "mc_energy", "streams": "mc", "methods": FLIPPED, "best_baseline": {"final": "rl-reset"}}
    parents = [(p.method, p.other) for p in pairs.declared_pairs(spec) if pairs.parents_pair(spec, p)]
    assert sorted(parents) == [("apprentice-fqi", "rl-reset"), ("apprentice-fqi-rbf", "rl-reset")]
    assert pairs.family_sizes(spec)["final"] == 4 + 5 - 2
    # A sweep's conditions share streams with their sweep, not records: nothing is the parent's.
    condition = {**spec, "condition": {"gain": 0.5}}
    assert not any(pairs.parents_pair(condition, p) for p in pairs.declared_pairs(condition))


def test_holm_is_reported_within_the_family_beside_the_unadjusted_verdict():
    spec = {"name": "flip", "methods": FLIPPED, "best_baseline": {"final": "rl-reset"}}
    ten = np.arange(10.0)
    per_seed = {q: {"ta-tl": ten + 1, "apprentice-fqi": ten, "ta-tl-placebo": ten} for q in verdicts.QUESTIONS}
    per_seed["final"]["ta-tl-placebo"] = np.r_[ten[:9] - 1, 20.0]  # 9 of 10 below ta-tl: p = 0.021
    judged = {(v["method"], v["other"]): v for v in verdicts.judge(spec, per_seed)}
    unanimous, nine = judged[("ta-tl", "apprentice-fqi")]["final"], judged[("ta-tl", "ta-tl-placebo")]["final"]
    assert unanimous["verdict"] == nine["verdict"] == st.CREDITED
    # Family of 4 + 5 = 9 for "final": 0.002 <= 0.05 / 9 holds; 0.021 > 0.05 / 8 does not.
    assert unanimous["holm"] and not nine["holm"]


def test_the_best_baseline_is_chosen_per_question_by_its_iqm():
    def iqm(final: float, efficiency: float) -> MethodSummary:
        curve = Curve((), (), (), ())
        return MethodSummary(
            (), (), curve, final_iqm=Interval(final, None, None), efficiency=Interval(efficiency, None, None)
        )

    methods = {"rl-reset": iqm(1.0, 0.4), "uma-tl-reset": iqm(1.0, 0.6), "rl": iqm(-3.0, -1.0), "ta-tl": iqm(9.0, 9.0)}
    chosen = verdicts.choose_best_baseline(methods, ["uma-tl", "rl", "rl-reset", "rl-online", "uma-tl-reset"])
    assert chosen == {"final": "rl-reset", "efficiency": "uma-tl-reset"}  # a tie goes to the one listed first
