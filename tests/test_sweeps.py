"""Sweeps over target conditions: one experiment per condition, each what it is run alone."""

import json
import tomllib

import numpy as np
import pytest
from conftest import ROOT, TINY

from tatl_mj.experiments import plot, runner
from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments import statistics as stats

COSTS = ("physics_substeps", "blob_sha256")


def _flipped(sweep=None, **target_kwargs):
    table = tomllib.loads((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text())
    table["presets"] = {"tiny": {**TINY, "target_budgets": [60, 120], "evaluation_steps": 40}}
    table["source_learning"]["iterations"] = 5
    table["methods"] = {"ta-tl": table["methods"]["ta-tl"], "projected-source": {}}
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
    estimate = stats.improvement_interval([(scores, scores)])
    assert estimate.value == 0.5 and estimate.low <= 0.5 <= estimate.high
    assert stats.verdict(estimate) == stats.NOT_CREDITED
    pair = {
        "method": "m",
        "ablation": "m-copy",
        "probability_of_improvement": estimate.as_dict(),
        "verdict": "not credited",
    }
    cells = [({"gain": g}, {"ablations": [pair], "methods": {}}) for g in (0.5, 1.0)]
    table = plot.credit_table("toy", cells)
    assert table.splitlines()[2] == "| gain | `m` > `m-copy` |"
    assert table.splitlines()[4].startswith("| 0.5 | 0.50 [") and table.splitlines()[4].endswith("not credited |")


@pytest.mark.parametrize("two", [False, True], ids=["one-parameter", "two-parameters"])
def test_credit_map_draws_each_conditions_estimate_with_its_interval(tmp_path, drawn, two):

    def exp(p):
        pair = {"value": p, "low": p - 0.1, "high": p + 0.1}
        return {
            "ablations": [{"method": "m", "ablation": "a", "probability_of_improvement": pair, "verdict": "x"}],
            "methods": {"m": {"final_iqm": {"value": 0.5, "low": 0.4, "high": 0.6}}},
        }

    conditions = [{"g": 1, "s": 2}, {"g": 1, "s": 3}] if two else [{"g": 1}, {"g": 2}]
    plot.credit_map("toy", [(c, exp(p)) for c, p in zip(conditions, (0.3, 0.8))], tmp_path / "c.png")
    (fig,) = drawn
    left = fig.axes[0]
    if two:  # a heat map: each cell says its value and interval
        assert sorted(t.get_text() for t in left.texts) == ["0.30\n[0.20, 0.40]", "0.80\n[0.70, 0.90]"]
    else:  # curves with error bars at each swept value
        (line,) = [ln for ln in left.get_lines() if len(ln.get_xdata()) == 2 and ln.get_linestyle() == "-"]
        assert list(line.get_ydata()) == [0.3, 0.8]
    assert (tmp_path / "c.png").exists()


def test_credit_map_clips_a_baselines_blow_up_and_marks_it(tmp_path, drawn):
    def final(v):
        return {"final_iqm": {"value": v, "low": v - 0.05, "high": v + 0.05}}

    cells = [
        ({"g": g}, {"ablations": [], "methods": {"m": final(0.8), "base": final(b)}})
        for g, b in ((1, 0.9), (2, 0.7), (3, -15.0))
    ]
    plot.credit_map("toy", cells, tmp_path / "c.png")
    (fig,) = drawn
    right = fig.axes[1]
    low, high = right.get_ylim()
    assert -2.0 < low < 0.0 and high > 0.9  # the others keep their scale; -15 lies outside
    marked = [c for c in right.collections if c.get_offsets().shape[0] == 1]
    assert any(float(c.get_offsets()[0][1]) == low for c in marked)  # a triangle on the lower edge
