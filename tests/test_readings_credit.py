"""Known answers for the headline tables (issue 68): a verdict against a privileged comparator is
information, the non-privileged comparator's row first; both readings of TA-TL's action a row each,
the continuous one marked as having more actions; the apprentice's samples per budget."""

from __future__ import annotations

import types

from tatl_mj.experiments.report import privileges, tables
from tatl_mj.experiments.results.summary_data import Answer, Curve, Interval, PairVerdict

METHODS = {
    "ta-tl": {},
    "ta-tl-continuous": {"method": "ta-tl", "actions": "continuous"},
    "ta-tl-placebo": {"method": "ta-tl", "source": "placebo"},
    "apprentice-fqi": {},
    "apprentice-fqi-samples": {},
    "rl": {},
}


def _answer(verdict: str) -> Answer:
    return Answer(Interval(0.9, 0.55, 1.0), {"better": 9, "tied": 0, "worse": 1}, verdict)


def _pair(method: str, other: str, role: str, verdict: str) -> PairVerdict:
    return PairVerdict(method, other, role, False, _answer(verdict), _answer(verdict), _answer(verdict))


def _method(samples_used=None):
    curve = Curve((100, 300), ((0.0, 0.0),) * 3, ((100, 300),) * 3, ((0, 0),) * 3, samples_used)
    return types.SimpleNamespace(
        final_iqm=Interval(0.5, 0.4, 0.6), first_policy=None, curve=curve, seeds=(100, 101, 102), rows=_rows
    )


def _rows(seeds):
    return [(100, 101, 102).index(s) for s in seeds]


def _summary():
    # Declared in an order the table must not keep: privileged comparator, placebo, then the
    # non-privileged one; the continuous reading before the discrete one.
    judged = (
        _pair("ta-tl-continuous", "apprentice-fqi", "ablation", "worse"),
        _pair("ta-tl", "apprentice-fqi", "ablation", "worse"),
        _pair("ta-tl", "ta-tl-placebo", "placebo", "credited"),
        _pair("ta-tl", "apprentice-fqi-samples", "ablation", "credited"),
        _pair("ta-tl-continuous", "apprentice-fqi-samples", "ablation", "credited"),
    )
    exp = types.SimpleNamespace(
        spec={"name": "e", "title": "E", "methods": METHODS},
        spec_methods=METHODS,
        verdicts=judged,
        methods={m: _method() for m in METHODS},
    )
    return types.SimpleNamespace(experiments={"e": exp})


def test_a_privileged_comparators_verdict_is_information_and_the_non_privileged_row_comes_first():
    rows = tables.verdict_table(_summary(), methods=tables.READINGS).splitlines()[2:]
    cells = [[c.strip() for c in row.strip("|").split("|")] for row in rows]
    assert [(c[1], c[2].split(" ")[0]) for c in cells] == [
        ("`ta-tl` (privileged)", "`apprentice-fqi-samples`"),
        ("`ta-tl` (privileged)", "`apprentice-fqi`"),
        ("`ta-tl` (privileged)", "`ta-tl-placebo`"),
        ("`ta-tl-continuous` (privileged)", "`apprentice-fqi-samples`"),
        ("`ta-tl-continuous` (privileged)", "`apprentice-fqi`"),
    ]
    samples, fqi, placebo, continuous_samples, continuous_fqi = cells
    # Against the non-privileged comparator: a verdict that credits, unmarked.
    assert samples[2] == "`apprentice-fqi-samples` (source-free)"
    assert (samples[4], samples[6], samples[7]) == ("**credited**", "**credited**", "**credited**")
    # Against the privileged one: printed as now, as information.
    assert fqi[2] == "`apprentice-fqi` (source-free, privileged: does not credit or discredit transfer)"
    assert (fqi[4], fqi[6], fqi[7]) == ("**worse** (information)",) * 3
    # The placebo is the same method, with the same resources: it credits.
    assert placebo[4] == "**credited**" and "information" not in placebo[2]
    # The continuous reading has more actions than its comparators.
    assert continuous_samples[4] == "**credited** (more actions than its comparator)"
    assert continuous_fqi[4] == "**worse** (information; more actions than its comparator)"
    assert privileges.credits(_summary().experiments["e"].verdicts[3], privileges.privileged(METHODS))
    assert not privileges.credits(_summary().experiments["e"].verdicts[1], privileges.privileged(METHODS))


def test_the_readings_are_declared_once_and_credit_reads_the_same_actions():
    assert tables.READINGS == ("ta-tl", "ta-tl-continuous")
    assert tables.CREDIT_READING == "ta-tl"
    assert (
        tables.reproduced({"ta-tl-continuous": 100.0, "uma-tl": float("inf"), "rl": 300.0}, "ta-tl-continuous") == "yes"
    )
    assert tables.reproduced({"ta-tl-continuous": 100.0}) == "no"  # ta-tl's row by default


def test_the_apprentice_samples_are_the_median_over_the_compared_seeds_per_budget():
    exp = types.SimpleNamespace(
        spec_methods={"ta-tl": {}, "rl": {}},
        methods={"ta-tl": _method(((100, 100), (100, 300), (100, 200))), "rl": _method(((100, 300),) * 3)},
    )
    assert tables.apprentice_samples(exp, "ta-tl", (100, 101, 102)) == [100.0, 200.0]
    assert tables.apprentice_samples(exp, "ta-tl", (100, 101)) == [100.0, 200.0]
    comparison = types.SimpleNamespace(
        methods=[
            types.SimpleNamespace(method="ta-tl", seeds=(100, 101, 102)),
            types.SimpleNamespace(method="rl", seeds=(100,)),
        ]
    )
    assert tables.apprentice_rows(exp, comparison)[-3:] == [
        "| method | 100 | 300 |",
        "|---|---|---|",
        "| TA-TL (paper, Alg. 1) | 100 | 200 |",
    ]  # rl fits no apprentice: no row
    # A summary older than the samples: no table.
    old = types.SimpleNamespace(spec_methods={"ta-tl": {}}, methods={"ta-tl": _method(None)})
    assert tables.apprentice_rows(old, comparison) == []


def test_an_older_summary_without_the_samples_still_loads():
    curve = {"samples": [100], "mean_return": [[0.0]], "target_transitions": [[100]], "rollout_transitions": [[0]]}
    assert Curve.from_json(curve).samples_used is None
    assert Curve.from_json({**curve, "samples_used": [[50]]}).samples_used == ((50,),)


def test_a_verdict_credits_only_against_a_comparator_with_no_privilege_the_method_lacks():
    methods = {
        "ta-tl": {},
        "ta-tl-no-alg2": {"method": "ta-tl", "zeta": None},
        "apprentice-fqi": {},
        "apprentice-fqi-samples": {},
        "uma-tl-reset": {},
        "rl-reset": {},
        "rl": {},
    }
    marked = privileges.privileged(methods)
    assert marked == {
        "ta-tl": frozenset({"reward function"}),
        "apprentice-fqi": frozenset({"reward function", "reset box"}),
        "uma-tl-reset": frozenset({"resets"}),
        "rl-reset": frozenset({"resets"}),
    }
    credit = {
        (m, o): privileges.credits(_pair(m, o, "ablation", "worse"), marked)
        for m, o in [
            ("ta-tl", "apprentice-fqi-samples"),  # none held: credits
            ("ta-tl-no-alg2", "apprentice-fqi-samples"),
            ("ta-tl", "apprentice-fqi"),  # the reset box's states ta-tl lacks
            ("ta-tl-no-alg2", "apprentice-fqi"),
            ("uma-tl-reset", "rl-reset"),  # the same privilege on both sides
            ("rl", "rl-reset"),
            ("ta-tl-no-alg2", "ta-tl"),  # the reward function the variant lacks
        ]
    }
    assert credit == {
        ("ta-tl", "apprentice-fqi-samples"): True,
        ("ta-tl-no-alg2", "apprentice-fqi-samples"): True,
        ("ta-tl", "apprentice-fqi"): False,
        ("ta-tl-no-alg2", "apprentice-fqi"): False,
        ("uma-tl-reset", "rl-reset"): True,
        ("rl", "rl-reset"): False,
        ("ta-tl-no-alg2", "ta-tl"): False,
    }


def test_privileges_are_named_from_the_declared_list_and_checked_once():
    import pytest

    from tatl_mj.transfer.method import PRIVILEGES, contract

    legacy = types.SimpleNamespace(name="mine", privileged=True)
    assert contract(legacy).privileges == frozenset({"unnamed"}) and contract(legacy).privileged
    assert not contract(types.SimpleNamespace(name="mine")).privileged
    assert set(PRIVILEGES) >= {"resets", "reward function", "reset box", "true model"}
    for bad in (("reward",), "resets"):
        with pytest.raises(ValueError, match=r"method 'mine' declares privileges .*: each must be one of \["):
            contract(types.SimpleNamespace(name="mine", privileges=bad))


def test_the_credit_table_can_be_limited_to_named_experiments():
    everything = tables.verdict_table(_summary(), methods=tables.READINGS).splitlines()
    assert tables.verdict_table(_summary(), methods=tables.READINGS, experiments=["e"]).splitlines() == everything
    assert tables.verdict_table(_summary(), methods=tables.READINGS, experiments=[]).splitlines() == everything[:2]
