"""Sweeps over target conditions: one experiment per condition, each what it is run alone."""

import json
import tomllib

import numpy as np
import pytest
from conftest import ROOT, TINY

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.report import credit_maps, tables
from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.summary_data import Experiment
from tatl_mj.experiments.run import runner

COSTS = ("physics_substeps", "blob_sha256")


def _flipped(sweep=None, **target_kwargs):
    table = tomllib.loads((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text())
    table["presets"] = {"tiny": {**TINY, "target_budgets": [60, 120], "evaluation_steps": 40}}
    table["source_learning"]["iterations"] = 5
    table["methods"] = {"ta-tl": table["methods"]["ta-tl"], "projected-source": {}}
    table.pop("best_baseline", None)  # names methods this test leaves out
    table["target"]["task_kwargs"] = dict(target_kwargs)
    if sweep is not None:
        table["sweep"] = sweep
    return spec_mod.parse_spec(table, "ip_to_flipped_ip.toml")


def _strip(record):
    if isinstance(record, dict):
        # Costs, and the pickle's hash, are not results.
        return {k: _strip(v) for k, v in record.items() if not k.endswith("_s") and k not in COSTS}
    if isinstance(record, list):
        return [_strip(v) for v in record]
    return record


def test_a_sweeps_condition_records_equal_the_condition_run_alone(tmp_path):
    swept = _flipped(sweep={"gain": [0.5, 2.0]})
    names = [c.name for c in spec_mod.conditions(swept)]
    assert names == ["ip_to_flipped_ip.gain-0.5", "ip_to_flipped_ip.gain-2.0"]
    runner.run([swept], "tiny", [0], tmp_path / "sweep", workers=1, progress=False)
    runner.run([_flipped(gain=2.0)], "tiny", [0], tmp_path / "alone", workers=1, progress=False)
    for method in ("source", "ta-tl", "projected-source"):
        in_sweep = json.loads((tmp_path / f"sweep/records/{names[1]}/seed0/{method}.json").read_text())
        alone = json.loads((tmp_path / f"alone/records/ip_to_flipped_ip/seed0/{method}.json").read_text())
        in_sweep.pop("experiment", None), alone.pop("experiment", None)
        assert _strip(in_sweep) == _strip(alone), method
    # The two conditions differ: the gain reaches the physics.
    a, b = (json.loads((tmp_path / f"sweep/records/{n}/seed0/ta-tl.json").read_text()) for n in names)
    assert a["curve"][-1]["returns"] != b["curve"][-1]["returns"]


@pytest.mark.parametrize(
    ("sweep", "message"),
    [
        ({"gain": [1.0], "a": [1], "b": [2]}, "key 'sweep' must be one or two target task_kwargs"),
        ({"gain": []}, "key 'sweep.gain' must be a non-empty list of distinct numbers or strings"),
        ({"gain": [1.0, 1.0]}, "key 'sweep.gain' must be a non-empty list of distinct numbers or strings"),
        ({"gain": [1.0, -2.0]}, "gain must be a number > 0, got -2.0 (in the sweep's condition {'gain': -2.0})"),
        ({"wind": [1.0]}, "key 'target.task_kwargs'"),
    ],
)
def test_a_bad_sweep_is_one_line_naming_the_key(sweep, message):
    with pytest.raises(spec_mod.SpecError, match=None) as caught:
        _flipped(sweep=sweep)
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_the_credit_of_a_method_against_itself_sits_at_one_half():
    scores = np.random.default_rng(0).normal(size=10)
    answer = verdicts.answer(scores, scores.copy()).as_dict()
    assert answer["probability"]["value"] == 0.5 and answer["probability"]["low"] < 0.5 < answer["probability"]["high"]
    assert answer["verdict"] == verdicts.NOT_CREDITED
    pair = {"method": "m", "other": "m-copy", "role": "ablation", "final": answer, "efficiency": answer}
    experiment = Experiment.from_json("toy", {"verdicts": [pair], "methods": {}})
    cells = [({"gain": g}, experiment) for g in (0.5, 1.0)]
    table = tables.credit_table("toy", cells)
    assert table.splitlines()[2] == "| gain | `m` > `m-copy`: final; efficiency |"
    assert table.splitlines()[4] == (
        "| 0.5 | 0.50 [0.19, 0.81] (0/10/0) not credited; 0.50 [0.19, 0.81] (0/10/0) not credited |"
    )


def test_a_credit_maps_privileged_comparator_is_labelled_information_and_comes_after():
    scores = np.random.default_rng(0).normal(size=10)
    answer = verdicts.answer(scores, scores.copy()).as_dict()
    judged = [
        {"method": "ta-tl-no-alg2", "other": other, "role": "ablation", "final": answer, "efficiency": answer}
        for other in ("apprentice-fqi", "apprentice-fqi-samples")
    ]
    methods = {"ta-tl-no-alg2": {"method": "ta-tl", "zeta": None}, "apprentice-fqi": {}, "apprentice-fqi-samples": {}}
    experiment = Experiment.from_json("toy", {"verdicts": judged, "methods": {}, "spec": {"methods": methods}})
    header = tables.credit_table("toy", [({"gain": 1.0}, experiment)]).splitlines()[2]
    assert header == (
        "| gain | `ta-tl-no-alg2` > `apprentice-fqi-samples`: final; efficiency | `ta-tl-no-alg2` > "
        "`apprentice-fqi` (privileged) (information: does not credit or discredit transfer): final; efficiency |"
    )


def typed(exp: dict) -> Experiment:
    """A hand-made experiment of a summary, each method with no seed but its ``final_iqm``."""
    curve = {"samples": [], "mean_return": [], "target_transitions": [], "rollout_transitions": []}
    methods = {m: {"seeds": [], "final_return": [], "curve": curve, **d} for m, d in exp["methods"].items()}
    return Experiment.from_json("toy", {**exp, "methods": methods})


@pytest.mark.parametrize("two", [False, True], ids=["one-parameter", "two-parameters"])
def test_credit_map_draws_each_conditions_estimate_with_its_interval(tmp_path, drawn, two):

    def exp(p):
        seeds = {"better": 5, "tied": 0, "worse": 5}
        answer = {
            "probability": {"value": p, "low": p - 0.1, "high": p + 0.1},
            "seeds": seeds,
            "verdict": "not credited",
        }
        final = {**answer, "probability": {"value": 0.5, "low": 0.2, "high": 0.8}}
        return typed(
            {
                "verdicts": [{"method": "m", "other": "a", "role": "ablation", "efficiency": answer, "final": final}],
                "methods": {"m": {"final_iqm": {"value": 0.5, "low": 0.4, "high": 0.6}}},
            }
        )

    conditions = [{"g": 1, "s": 2}, {"g": 1, "s": 3}] if two else [{"g": 1}, {"g": 2}]
    credit_maps.credit_map("toy", [(c, exp(p)) for c, p in zip(conditions, (0.3, 0.8))], tmp_path / "c.png")
    (fig,) = drawn
    left = fig.axes[0]
    if two:  # a heat map: each cell says its value and interval
        assert sorted(t.get_text() for t in left.texts) == ["0.30\n[0.20, 0.40]", "0.80\n[0.70, 0.90]"]
    else:  # curves with error bars at each swept value, one per question
        lines = [ln for ln in left.get_lines() if len(ln.get_xdata()) == 2 and ln.get_linestyle() == "-"]
        assert sorted(list(ln.get_ydata()) for ln in lines) == [[0.3, 0.8], [0.5, 0.5]]
    assert (tmp_path / "c.png").exists()


def test_credit_map_clips_a_baselines_blow_up_and_marks_it(tmp_path, drawn):
    def final(v):
        return {"final_iqm": {"value": v, "low": v - 0.05, "high": v + 0.05}}

    cells = [
        ({"g": g}, typed({"verdicts": [], "methods": {"m": final(0.8), "base": final(b)}}))
        for g, b in ((1, 0.9), (2, 0.7), (3, -15.0))
    ]
    credit_maps.credit_map("toy", cells, tmp_path / "c.png")
    (fig,) = drawn
    right = fig.axes[1]
    low, high = right.get_ylim()
    assert -2.0 < low < 0.0 and high > 0.9  # the others keep their scale; -15 lies outside
    marked = [c for c in right.collections if c.get_offsets().shape[0] == 1]
    assert any(float(c.get_offsets()[0][1]) == low for c in marked)  # a triangle on the lower edge
