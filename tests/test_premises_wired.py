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
from tatl_mj.experiments.run.determinism import derive_seed
from tatl_mj.experiments.run.evaluation import evaluate_curve
from tatl_mj.experiments.run.premises import fd_budgets
from tatl_mj.experiments.run.problems import transfer_problem
from tatl_mj.transfer import method, premises


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
    # Only the methods and experiments asked for (the README's: the same-actions reading).
    assert report.why_table(summary, ("ta-tl",), ["e"]).splitlines()[2:] == [
        "| e | ta-tl | 2 | infeasible 0.97 > 0.5 |"
    ]
    assert report.why_table(summary, ("ta-tl",), []) == ""


def test_no_premises_no_table_and_no_figure(tmp_path):
    summary = _summary({})
    bare = Summary(**{**summary.__dict__, "experiments": {}})
    assert report.why_table(bare) == ""
    assert report.premises_figure(bare, tmp_path / "p.png") is None
    assert report.premises_figure(summary, tmp_path / "p.png") == tmp_path / "p.png"
    assert np.isfinite((tmp_path / "p.png").stat().st_size)


# --- ta-tl-h and ta-tl-replan: delta (misprediction), feasibility, round trip only ------


def _smoke_unit(task: str, names: tuple[str, ...]) -> dict:
    """Each method's smoke-preset record on seed 0, and what the plain path (no observer) gives."""
    spec = spec_mod.parse_spec(tomllib.loads((ROOT / "tasks" / f"{task}.toml").read_text()), f"{task}.toml")
    preset = spec.preset("smoke")
    artifacts = source_unit.learn_source(spec, preset, 0)
    out = {}
    for name in names:
        record = method_unit.run_method(spec, preset, 0, name, artifacts)
        transfer = spec_mod.methods_from_spec(spec, preset, [name])[name]
        uses_source = method.contract(transfer).uses_source
        problem = transfer_problem(spec, preset, artifacts, 0, uses_source=uses_source)  # one, as run_method's
        learn = method_unit.learned_policy
        policies = [learn(spec, preset, 0, transfer, artifacts, b, problem) for b in preset.target_budgets]
        plain = evaluate_curve(spec, preset, policies, derive_seed(0, spec.stream_name, "evaluation"), False)
        out[name] = (record, policies, plain, artifacts.target_stream.states[:12])
    return out


@pytest.fixture(scope="module")
def horizon():
    return _smoke_unit("cartpole_to_bicycle", ("ta-tl-h", "apprentice-upright"))


@pytest.fixture(scope="module")
def grid():
    return _smoke_unit("grid_to_windy", ("ta-tl-replan", "replan-no-source"))


@pytest.mark.parametrize(
    "unit, name, carried",
    [
        ("horizon", "ta-tl-h", ("delta", "infeasible", "round_trip")),
        ("grid", "ta-tl-replan", ("misprediction", "infeasible", "round_trip")),
    ],
)
def test_horizon_and_replan_points_carry_delta_feasibility_and_round_trip_only(request, unit, name, carried):
    record = request.getfixturevalue(unit)[name][0]
    assert len(record["curve"]) > 1
    for point in record["curve"]:
        found = point["premises"]
        assert set(found) == set(report.MEASURES)
        for key in report.MEASURES:
            if key in carried:
                assert found[key] is not None and math.isfinite(found[key]), (name, key)
            else:
                assert found[key] is None, (name, key)  # alpha, unexplained, b_spread, tracking, ...


def test_a_planner_asks_only_for_the_grids_actions_and_its_mapping_inverts(grid):
    record = grid["ta-tl-replan"][0]
    for point in record["curve"]:
        assert point["premises"]["infeasible"] == 0.0  # an index of the target's own action set
        assert point["premises"]["round_trip"] < 1e-9  # the grid's mapping is invertible
        assert 0.0 <= point["premises"]["misprediction"] <= 1.0


@pytest.mark.parametrize("unit, name", [("horizon", "apprentice-upright"), ("grid", "replan-no-source")])
def test_their_source_free_ablations_carry_no_premises(request, unit, name):
    record = request.getfixturevalue(unit)[name][0]
    assert all(point["premises"] is None for point in record["curve"])


@pytest.mark.parametrize("unit, name", [("horizon", "ta-tl-h"), ("grid", "ta-tl-replan")])
def test_observed_returns_are_the_plain_paths(request, unit, name):
    record, policies, plain, _ = request.getfixturevalue(unit)[name]
    if unit == "horizon":  # the budgets decide together: the observer answers through that path
        assert method.joint_decisions(policies) is not None and method.joint_premises(policies) is not None
    for point, (returns, lengths, _) in zip(record["curve"], plain):
        assert point["returns"] == [float(r) for r in returns]
        assert point["steps"] == [int(n) for n in lengths]


def test_premise_step_is_the_decision_bit_for_bit(horizon, grid):
    _, policies, _, stream = horizon["ta-tl-h"]
    together, steps = method.joint_decisions(policies), method.joint_premises(policies)
    assert together is not None and steps is not None
    states = [stream[k : k + 6] for k in range(len(policies))]
    blocks = list(range(len(policies)))
    for a, step, policy, s in zip(together(blocks, states), steps(blocks, states), policies, states):
        assert np.array_equal(step.action, a)  # the joint path's decision, bit for bit
        assert np.array_equal(step.predicted, policy.model(s, a))
        single = policy.premise_step(s)
        assert np.array_equal(single.action, policy(s))
        assert np.array_equal(single.action, np.clip(single.requested, policy.target_low, policy.target_high))
    replan = grid["ta-tl-replan"][1][-1]
    cells = grid["ta-tl-replan"][3]
    step = replan.premise_step(cells)
    assert np.array_equal(step.action, replan(cells))
    assert np.array_equal(step.requested[:, 0], step.action)
    assert np.array_equal(
        step.predicted, replan.cell_map.cells[replan.model.next_state[replan.cell_map.index(cells), step.action]]
    )
