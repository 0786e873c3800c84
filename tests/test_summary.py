"""Samples to threshold, the threshold's meaning and the shared-seed comparison, on known answers."""

import math

import numpy as np
import pytest

from tatl_mj.experiments.results import comparison, notes, pairs, records, summary, verdicts
from tatl_mj.experiments.results.summary_data import Experiment, Summary


def compare(exp: dict, methods: list | None = None) -> comparison.Comparison:
    return comparison.comparison_of(Experiment.from_json("toy", exp), methods)


def typed(data: dict) -> Summary:
    """A hand-made summary (no schema version: an older one) as a reader gets it, upgraded."""
    return Summary.from_json(records.upgrade({"preset": "p", "seeds": [], "methods": [], **data}))


def test_samples_to_threshold_is_where_the_return_stays_above():
    budgets = [100, 200, 400, 800]
    # Crosses at 100, falls back at 200, stays from 400 on: 400, not 100.
    assert comparison.samples_to_threshold(budgets, [5, 1, 5, 6], threshold=5) == 400
    assert comparison.samples_to_threshold(budgets, [5, 5, 5, 5], threshold=5) == 100  # "at or above"
    # Reaches it and ends below: never.
    assert comparison.samples_to_threshold(budgets, [9, 9, 9, 4.99], threshold=5) == math.inf
    assert comparison.samples_to_threshold(budgets, [9, float("nan"), 9, 9], threshold=5) == 400


def test_samples_to_threshold_rejects_bad_curves():
    with pytest.raises(ValueError, match="differ in length"):
        comparison.samples_to_threshold([1, 2], [1.0], 0.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        comparison.samples_to_threshold([2, 1], [1.0, 1.0], 0.0)


def test_threshold_at_or_below_random_is_not_meaningful():
    threshold, best, meaningful = comparison.threshold_for({"a": 10.0, "b": 0.0}, random_return=-10.0)
    assert (threshold, best, meaningful) == (pytest.approx(9.0), "a", True)
    # Best final return below random: the threshold lies below random too.
    threshold, best, meaningful = comparison.threshold_for({"a": -20.0, "b": -30.0}, random_return=-10.0)
    assert threshold == pytest.approx(-19.5) and best == "a" and not meaningful
    assert not comparison.threshold_for({"a": -10.0}, random_return=-10.0)[2]  # equal: not above


def experiment(methods: dict, random_returns: dict) -> dict:
    """A summary experiment from {method: {seed: [return per budget]}} at budgets 100, 1000."""
    return {
        "methods": {
            m: {
                "seeds": sorted(runs),
                "final_return": [runs[s][-1] for s in sorted(runs)],
                "curve": {
                    "samples": [100, 1000],
                    "mean_return": [runs[s] for s in sorted(runs)],
                    "target_transitions": [[100, 1000] for _ in runs],
                    "rollout_transitions": [[0, 0] for _ in runs],
                },
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
    c = compare(exp)
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
    c = compare(exp, ["a", "b"])
    assert c.missing == ("b",) and c.seed_sets_differ and [r.method for r in c.methods] == ["a"]
    same = compare(experiment({"a": {0: [0, 1]}, "b": {0: [1, 1]}}, random_returns={0: 0.0}))
    assert not same.seed_sets_differ


def test_compare_without_meaningful_threshold_reports_no_samples():
    exp = experiment({"a": {0: [-50, -20]}, "b": {0: [-5, -30]}}, random_returns={0: -10.0})
    c = compare(exp)
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
    c = compare(experiment({"ta-tl-h": mine, "apprentice-upright": ablation}, SEEDS3))
    text = verdicts.ablation_verdict(c, "ta-tl-h", "apprentice-upright")
    assert text.startswith("`ta-tl-h` vs `apprentice-upright`: mean final return") and verdict in text, text
    assert verdicts.ablation_verdict(c, "ta-tl-h", "replan-no-source") is None


def test_ablation_pairs_follow_built_ins_and_variants():
    methods = {
        "ta-tl": {},
        "ta-tl-h": {"horizon": 20},
        "ta-tl-h-no-cart": {"method": "ta-tl-h", "source_zero": ["x"]},
        "apprentice-upright": {},
        "rl": {},
    }
    assert pairs.ablation_pairs(methods) == [
        ("ta-tl-h", "apprentice-upright"),
        ("ta-tl-h-no-cart", "apprentice-upright"),
    ]
    assert pairs.ablation_pairs({"ta-tl-replan": {}, "rl": {}}) == []  # no ablation listed: nothing to say
    # A placebo variant is an ablation itself, judged against its trained method only.
    placebo = {"ta-tl-h-placebo": {"method": "ta-tl-h", "horizon": 20, "source": "placebo"}}
    assert pairs.ablation_pairs({**methods, **placebo}) == pairs.ablation_pairs(methods)


def _with_counts(exp: dict) -> dict:
    for data in exp["methods"].values():
        data["curve"]["target_transitions"] = [list(data["curve"]["samples"]) for _ in data["seeds"]]
        data["curve"]["rollout_transitions"] = [[0] * len(data["curve"]["samples"]) for _ in data["seeds"]]
    return exp


def test_a_fixed_reference_threshold_does_not_move_when_a_method_is_added():
    runs = {"ta-tl": {s: [5.0, 8.0] for s in range(4)}, "rl": {s: [1.0, 2.0] for s in range(4)}}
    random = {s: 0.0 for s in range(4)}
    alone = {**experiment(runs, random), "reference_return": 10.0}
    stronger = {**experiment({**runs, "oracle": {s: [50.0, 60.0] for s in range(4)}}, random), "reference_return": 10.0}
    assert compare(alone).threshold == compare(stronger).threshold == pytest.approx(9.0)
    # Without a reference the old relative rule moves with the best method listed.
    del alone["reference_return"], stronger["reference_return"]
    assert compare(alone).threshold != compare(stronger).threshold


def test_statistics_give_normalised_iqm_areas_and_interval_verdicts():
    rng = np.random.default_rng(0)
    seeds = range(8)
    good = {s: [6.0 + rng.normal(), 9.0 + rng.normal()] for s in seeds}
    twin = {s: list(v) for s, v in good.items()}
    poor = {s: [1.0 + rng.normal(), 2.0 + rng.normal()] for s in seeds}
    exp = _with_counts(
        {
            **experiment(
                {"ta-tl-h": good, "apprentice-upright": twin, "ta-tl": poor, "apprentice-fqi": good},
                {s: 0.0 for s in seeds},
            ),
            "reference_return": 10.0,
        }
    )
    spec = {"methods": {"ta-tl-h": {}, "apprentice-upright": {}, "ta-tl": {}, "apprentice-fqi": {}}}
    summary.add_statistics(exp, spec, list(seeds))
    data = exp["methods"]["ta-tl-h"]
    np.testing.assert_allclose(data["normalised"], np.array([good[s] for s in seeds]) / 10.0)
    assert data["iqm"][1]["low"] < data["iqm"][1]["value"] < data["iqm"][1]["high"]
    judged = {(p["method"], p["other"]): (p["final"]["verdict"], p["efficiency"]["verdict"]) for p in exp["verdicts"]}
    assert judged == {
        ("ta-tl-h", "apprentice-upright"): ("not credited", "not credited"),
        ("ta-tl", "apprentice-fqi"): ("worse", "worse"),
    }


def test_survival_is_kaplan_meier_over_the_compared_seeds_at_the_largest_budget():
    exp = experiment({"a": {0: [1.0, 2.0], 1: [1.0, 2.0]}}, {0: 0.0, 1: 0.0})
    exp["methods"]["a"]["final_steps"] = {"0": [3, 10], "1": [5, 10]}  # cap 10: two fell, two did not
    notes.survival(exp, 10)
    got = exp["methods"]["a"]["survival"]
    assert got["steps"] == [3.0, 5.0] and got["episodes"] == 4
    assert got["probability"] == pytest.approx([3 / 4, 3 / 4 * 2 / 3]) and got["at_cap"] == pytest.approx(0.5)


def test_stopping_rule_notes_are_one_line_per_experiment_with_their_meaning():
    exp = experiment({"ta-tl": {0: [1.0, 2.0], 1: [1.0, 2.0]}}, {0: 0.0, 1: 0.0})
    exp["algorithm2_not_met"] = {"ta-tl": [1]}
    lines = notes.notes(typed({"experiments": {"flip": exp, "other": experiment({"rl": {0: [1.0, 1.0]}}, {0: 0.0})}}))
    assert len(lines) == 1 and lines[0].startswith("note: flip: Algorithm 2's stopping rule")
    assert "ta-tl on 1 of 2 seeds" in lines[0] and "not an error" in lines[0]


def test_survival_is_reported_only_where_an_early_end_is_a_fall():
    def spec(domain, task):
        return {"target": {"domain": domain, "task": task, "task_kwargs": {}}}

    assert notes.falls(spec("bicycle", "balance")) and notes.falls(spec("cartpole", "balance"))
    # Reaching the grid's goal ends an episode early: a success, not a fall.
    assert not notes.falls(spec("gridworld", "windy")) and not notes.falls(spec("pendulum", "swingup"))
    assert not notes.falls({"target": {"domain": "no_such_domain", "task": "x"}})


def test_a_note_names_the_kernels_only_when_the_records_mix_them():
    one = {"experiments": {}, "kernels": {"openblas 0.3.31 Haswell; numpy X86_V3": 12, "unknown": 3}}
    assert notes.notes(typed(one)) == []  # older records without the field are not a second set
    two = {"experiments": {}, "kernels": {"openblas 0.3.31 Haswell; numpy X86_V3": 12, "openblas 0.3.31 SkylakeX": 4}}
    (line,) = notes.notes(typed(two))
    assert "2 sets of arithmetic kernels" in line
    assert "[openblas 0.3.31 Haswell; numpy X86_V3]: 12 records" in line and "[openblas 0.3.31 SkylakeX]: 4" in line
    assert notes.notes(typed({"experiments": {}})) == []  # a summary written before the field
