"""The theorem's premises wired into the method units (record schema 3) and the reports."""

import math
import tomllib

import numpy as np
import pytest
from conftest import ROOT, TINY

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.report import premises as report
from tatl_mj.experiments.results import records
from tatl_mj.experiments.results.summary_data import Experiment, MethodSummary, Summary
from tatl_mj.experiments.run import method_unit, source_unit
from tatl_mj.experiments.run.premises import fd_budgets
from tatl_mj.transfer import premises


@pytest.fixture(scope="module")
def pendulum():
    table = tomllib.loads((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text())
    table["presets"] = {"tiny": {**TINY, "target_budgets": [40, 80, 120], "evaluation_steps": 60}}
    table["source_learning"]["iterations"] = 5
    spec = spec_mod.parse_spec(table, "ip_to_flipped_ip.toml")
    preset = spec.preset("tiny")
    artifacts = source_unit.learn_source(spec, preset, 0)
    names = ("ta-tl", "ta-tl-continuous", "rl")
    return {name: method_unit.run_method(spec, preset, 0, name, artifacts) for name in names}


def test_ta_tl_points_carry_premises_and_rl_points_none(pendulum):
    for name in ("ta-tl", "ta-tl-continuous"):
        for point in pendulum[name]["curve"]:
            found = point["premises"]
            assert set(found) == set(report.MEASURES)
            assert found["misprediction"] is None  # a continuous target's delta is delta
            for key in ("delta", "delta_stream", "infeasible", "tracking", "round_trip", "alpha", "unexplained"):
                assert found[key] is not None and math.isfinite(found[key]), (name, key)
    assert all(point["premises"] is None for point in pendulum["rl"]["curve"])


def test_continuous_actions_are_no_less_feasible_than_snapped_ones(pendulum):
    snapped = pendulum["ta-tl"]["curve"][-1]["premises"]["infeasible"]
    continuous = pendulum["ta-tl-continuous"]["curve"][-1]["premises"]["infeasible"]
    assert continuous <= snapped
    # The pendulum's step is affine in the torque and its mapping invertible.
    assert pendulum["ta-tl"]["curve"][-1]["premises"]["unexplained"] < premises.THRESHOLDS.unexplained
    assert pendulum["ta-tl"]["curve"][-1]["premises"]["round_trip"] < 1e-9


def test_fd_budgets_are_the_smallest_middle_and_largest():
    assert fd_budgets([10, 20, 30, 40, 50]) == (10, 30, 50)
    assert fd_budgets([10]) == (10,)


def test_a_schema_2_record_upgrades_with_premises_none():
    unit = {"schema_version": 2, "data": "shared", "curve": [{"samples": 1}], "final_return": 0.0}
    assert records.upgrade(unit) == {**unit, "schema_version": 3, "curve": [{"samples": 1, "premises": None}]}
    summary = {"schema_version": 2, "experiments": {"e": {"methods": {"ta-tl": {"seeds": [0]}}}}}
    upgraded = records.upgrade(summary)
    assert upgraded["schema_version"] == 3
    assert upgraded["experiments"]["e"]["methods"]["ta-tl"]["premises"] is None


def _summary(values: dict) -> Summary:
    def method(found):
        return MethodSummary(seeds=(0, 1), final_return=(0.0, 0.0), curve=None, premises=found)  # type: ignore[arg-type]

    point = {k: None for k in report.MEASURES}
    fails = [[{**point, "infeasible": 0.1}, {**point, **values, "infeasible": v}] for v in (0.95, 0.99)]
    holds = [[{**point, "infeasible": 0.1, "delta": 0.2}]] * 2
    exp = Experiment(
        name="e",
        spec={},
        methods={"ta-tl": method(fails), "ta-tl-continuous": method(holds), "rl": method(None)},
        source_seeds=(0, 1),
        random_returns=None,
    )
    return Summary("x", [0, 1], [], {"e": exp}, {}, {}, 3, 0.95, 0.9, {}, [])


def test_the_why_table_names_each_failing_premise_against_its_threshold():
    summary = _summary({"delta": 0.3})
    rows = {r.method: r for r in report.aggregate(summary)}
    assert rows["ta-tl"].failed == ("infeasible",)
    assert rows["ta-tl"].measured.infeasible == pytest.approx(0.97)
    table = report.why_table(summary)
    assert "| e | ta-tl | 2 | infeasible 0.97 > 0.5 |" in table
    assert "| e | ta-tl-continuous | 2 | none fails |" in table
    assert "rl" not in table


def test_no_premises_no_table_and_no_figure(tmp_path):
    summary = _summary({})
    bare = Summary(**{**summary.__dict__, "experiments": {}})
    assert report.why_table(bare) == ""
    assert report.premises_figure(bare, tmp_path / "p.png") is None
    assert report.premises_figure(summary, tmp_path / "p.png") == tmp_path / "p.png"
    assert np.isfinite((tmp_path / "p.png").stat().st_size)
