"""The placebo source: an untrained source Q of the trained one's shape, per seed."""

import tomllib

import numpy as np
import pytest
from conftest import ROOT, TINY

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.results import pairs
from tatl_mj.experiments.run import determinism, method_unit, problems, source_unit
from tatl_mj.transfer import registry
from tatl_mj.transfer.features import make_features
from tatl_mj.transfer.fqi import LinearQ, TreeQ
from tatl_mj.transfer.placebo import placebo_q
from tatl_mj.transfer.tabular_q import TabularQ


def _trained() -> LinearQ:
    features = make_features({"kind": "rbf", "centers": 9, "low": [-1, -1], "high": [1, 1], "sigma": [0.5, 0.5]}, 2)
    weights = np.random.default_rng(0).normal(2.0, 3.0, size=(3, features.size(2)))
    return LinearQ(features, weights)


def test_placebo_is_reproducible_from_its_seed_and_differs_from_the_trained_source():
    trained = _trained()
    one, again, other = placebo_q(trained, 7), placebo_q(trained, 7), placebo_q(trained, 8)
    np.testing.assert_array_equal(one.weights, again.weights)
    assert not np.allclose(one.weights, other.weights)
    # The trained one's shape and basis, not its content.
    assert one.features is trained.features and one.weights.shape == trained.weights.shape
    probe = np.random.default_rng(1).uniform(-1, 1, size=(500, 2))
    assert np.mean(one.greedy(probe) == trained.greedy(probe)) < 0.6
    # On the trained parameters' scale: the draws are N(mean, sd) of the trained weights.
    np.testing.assert_array_equal(
        one.weights,
        trained.weights.mean()
        + trained.weights.std() * np.random.default_rng(7).standard_normal((3, trained.weights.shape[1])),
    )


def test_tabular_placebo_keeps_the_cells():
    trained = TabularQ(np.arange(12.0).reshape(4, 3), cells=np.array([[0, 0], [0, 1], [1, 0], [1, 1]]))
    placebo = placebo_q(trained, 0)
    assert placebo.q.shape == (4, 3) and np.array_equal(placebo.cells, trained.cells)
    assert not np.allclose(placebo.q, trained.q)


def test_placebo_of_an_unsupported_source_names_what_works():
    with pytest.raises(ValueError, match="needs a linear or tabular source Q, got TreeQ"):
        placebo_q(TreeQ(forest=None, n_actions=3, state_dim=2), 0)


def test_placebo_setting_is_checked_at_construction():
    assert registry.build("ta-tl-placebo", {"method": "ta-tl", "source": "placebo"}).source == "placebo"
    assert registry.build("uma-tl-placebo", {"method": "uma-tl", "source": "placebo"}).source == "placebo"
    with pytest.raises(ValueError, match=r"TATL.source must be one of \['trained', 'placebo'\], got 'random'"):
        registry.build("ta-tl-x", {"method": "ta-tl", "source": "random"})
    with pytest.raises(ValueError, match="needs a learner that uses the source Q; RL uses none"):
        registry.build("rl-x", {"method": "rl", "source": "placebo"})
    with pytest.raises(ValueError, match="source = 'placebo' needs reference = 'source'"):
        registry.build("upright-x", {"method": "apprentice-upright", "source": "placebo"})


def test_placebo_pairs_match_the_same_settings_but_the_source():
    methods = {
        "ta-tl": {},
        "ta-tl-placebo": {"method": "ta-tl", "source": "placebo"},
        "ta-tl-h": {"horizon": 20},
        "ta-tl-h-placebo": {"method": "ta-tl-h", "horizon": 20, "source": "placebo"},
        "ta-tl-h-short": {"method": "ta-tl-h", "horizon": 5},
        "rl": {},
    }
    assert pairs.placebo_pairs(methods) == [("ta-tl", "ta-tl-placebo"), ("ta-tl-h", "ta-tl-h-placebo")]


def test_a_placebo_variant_runs_in_a_batch_on_its_own_source():
    table = tomllib.loads((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text())
    table["presets"] = {"tiny": {**TINY, "target_budgets": [100], "evaluation_steps": 60}}
    table["source_learning"]["iterations"] = 5
    table["methods"] = {"ta-tl": table["methods"]["ta-tl"], "ta-tl-placebo": {**table["methods"]["ta-tl"]}}
    table.pop("best_baseline", None)  # names methods this test leaves out
    table["methods"]["ta-tl-placebo"].update(method="ta-tl", source="placebo")
    spec = spec_mod.parse_spec(table, "ip_to_flipped_ip.toml")
    preset = spec.preset("tiny")
    artifacts = source_unit.learn_source(spec, preset, 0)
    problem = problems.transfer_problem(spec, preset, artifacts, 0, placebo=True)
    expected = placebo_q(artifacts.source_q, determinism.derive_seed(0, spec.name, "placebo"))
    np.testing.assert_array_equal(problem.source_q.weights, expected.weights)
    trained = method_unit.run_method(spec, preset, 0, "ta-tl", artifacts)
    placebo = method_unit.run_method(spec, preset, 0, "ta-tl-placebo", artifacts)
    assert placebo["curve"][0]["returns"] != trained["curve"][0]["returns"]
    again = method_unit.run_method(spec, preset, 0, "ta-tl-placebo", artifacts)
    assert again["curve"][0]["returns"] == placebo["curve"][0]["returns"]  # the same placebo from the same seed
