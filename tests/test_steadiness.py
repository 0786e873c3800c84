"""Steadiness: measures of how a policy holds a capped task that do not saturate (the bicycle's roll)."""

import tomllib

import numpy as np
import pytest
from conftest import ROOT, TINY

from tatl_mj import suite
from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.results import notes
from tatl_mj.experiments.run import evaluation, method_unit, source_unit
from tatl_mj.suite import bicycle


def test_per_episode_assigns_lockstep_rows_to_their_episodes():
    """Lengths (3, 1, 2): step 0 asks episodes 0, 1, 2; step 1 asks 0 and 2; step 2 asks 0."""
    calls = []
    for t, live in enumerate([[0, 1, 2], [0, 2], [0]]):
        states = np.array([[10.0 * i + t, 0.0] for i in live])
        calls.append((states, -states[:, :1]))
    states, values = evaluation.per_episode(calls, np.array([3, 1, 2]))
    assert [s[:, 0].tolist() for s in states] == [[0, 1, 2], [10], [20, 21]]
    assert [v[:, 0].tolist() for v in values] == [[0, -1, -2], [-10], [-20, -21]]


def test_steadiness_is_the_rms_of_the_declared_states_and_the_mean_clipped_action():
    description = suite.describe("bicycle", "balance")
    assert description.steadiness == ("roll",)
    states = [np.array([[0, 0, 0.3, 0], [0, 0, -0.4, 0]]), np.array([[0, 0, 0.1, 0]])]
    values = [np.array([[1.0], [-5.0]]), np.array([[0.5]])]  # -5 N m is clipped to the 2 N m limit
    out = evaluation.steadiness(description, states, values)
    assert out["roll_rms"] == pytest.approx([np.sqrt((0.09 + 0.16) / 2), 0.1])
    assert out["mean_abs_action"] == pytest.approx([1.5, 0.5])
    with pytest.raises(ValueError, match=r"steadiness names \['tilt'\], not states"):
        type(description)(**{**description.__dict__, "steadiness": ("tilt",)})


def test_bicycle_records_carry_each_episodes_steadiness_within_the_fall_limit():
    table = tomllib.loads((ROOT / "tasks" / "cartpole_to_bicycle.toml").read_text())
    table["presets"] = {"tiny": {**TINY, "target_budgets": [100], "evaluation_steps": 200}}
    table["source_learning"]["iterations"] = 5
    table["methods"] = {"projected-source": {}}
    table.pop("best_baseline", None)  # names methods this test leaves out
    spec = spec_mod.parse_spec(table, "cartpole_to_bicycle.toml")
    preset = spec.preset("tiny")
    record = method_unit.run_method(spec, preset, 0, "projected-source", source_unit.learn_source(spec, preset, 0))
    point = record["curve"][0]
    steady = point["steadiness"]
    assert len(steady["roll_rms"]) == len(steady["mean_abs_action"]) == preset.evaluation_episodes
    # Over the steps before a fall the roll stays inside the fall limit, so does its RMS.
    assert all(0 < r < bicycle.ROLL_LIMIT for r in steady["roll_rms"])
    assert all(0 <= a <= bicycle.TORQUE_LIMIT for a in steady["mean_abs_action"])


def test_summary_reports_the_iqm_over_seeds_of_each_seeds_mean():
    per_seed = {str(s): {"roll_rms": [0.01 * s, 0.01 * s + 0.002]} for s in range(4)}
    experiment = {
        "methods": {
            "m": {
                "seeds": [0, 1, 2, 3],
                "final_return": [1.0] * 4,
                "curve": {
                    "samples": [10],
                    "mean_return": [[1.0]] * 4,
                    "target_transitions": [[10]] * 4,
                    "rollout_transitions": [[0]] * 4,
                },
                "final_steadiness": per_seed,
            }
        },
        "source_seeds": [0, 1, 2, 3],
        "random_returns": [0.0] * 4,
    }
    notes.steadiness(experiment)
    result = experiment["methods"]["m"]["steadiness"]["roll_rms"]
    assert result["per_seed"] == pytest.approx([0.001, 0.011, 0.021, 0.031])
    assert result["value"] == pytest.approx(np.mean([0.011, 0.021]))  # the middle half of four seeds


def test_steadiness_uses_the_compared_seeds_whose_records_carry_it_and_survival_every_compared_seed():
    experiment = {
        "methods": {
            "m": {
                "seeds": [0, 1, 2],
                "final_return": [1.0] * 3,
                "curve": {
                    "samples": [10],
                    "mean_return": [[1.0]] * 3,
                    "target_transitions": [[10]] * 3,
                    "rollout_transitions": [[0]] * 3,
                },
                "final_steadiness": {"1": {"roll_rms": [0.02]}, "2": {"roll_rms": [0.04]}},  # seed 0's is older
                "final_steps": {"0": [10, 10], "1": [5, 10], "2": [10, 10]},
            }
        },
        "source_seeds": [0, 1, 2],
        "random_returns": [0.0] * 3,
    }
    notes.steadiness(experiment)
    notes.survival(experiment, cap=10)
    data = experiment["methods"]["m"]
    assert data["steadiness_seeds"] == [1, 2] and data["steadiness"]["roll_rms"]["per_seed"] == [0.02, 0.04]
    assert data["survival"]["seeds"] == [0, 1, 2] and data["survival"]["at_cap"] == pytest.approx(5 / 6)
