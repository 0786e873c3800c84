"""The extension methods as methods: built from settings, learned through a TransferProblem."""

import numpy as np
import pytest
from test_transfer_method import _problem, _samples
from test_transfer_tabular import GAMMA, one_visit_per_pair

from tatl_mj import suite
from tatl_mj.transfer import registry
from tatl_mj.transfer.intertask_mapping import IdentityMapping
from tatl_mj.transfer.method import TransferProblem
from tatl_mj.transfer.methods.horizon import HorizonTATL
from tatl_mj.transfer.methods.horizon_policy import HorizonTATLPolicy
from tatl_mj.transfer.methods.projected import ProjectedSource
from tatl_mj.transfer.methods.replan import OneStepOracle, ReplanPolicy, ReplanTATL
from tatl_mj.transfer.methods.tatl import TATL
from tatl_mj.transfer.tabular_q import q_iteration


def test_horizon_method_with_one_step_is_the_papers_rule():
    """H = 1, step ratio 1, W = I: ta-tl-h's action is Algorithm 1's (same apprentice, no Algorithm 2)."""
    problem, samples = _problem(), _samples()
    states = samples.states[:20]
    one_step = TATL(zeta=None).learn(problem, samples)
    horizon = HorizonTATL(zeta=None, horizon=1, step_ratio=1.0).learn(problem, samples)
    assert isinstance(horizon, HorizonTATLPolicy)
    np.testing.assert_allclose(horizon(states), one_step(states), rtol=1e-9, atol=1e-12)


def test_registered_ablations_fix_their_settings():
    upright = registry.build("apprentice-upright", {"horizon": 5, "weights": [1.0, 0.0]})
    assert upright.reference == "zero" and upright.name == "apprentice-upright"
    with pytest.raises(ValueError, match="unknown setting 'reference'"):
        registry.build("apprentice-upright", {"reference": "source"})

    # The zero reference never queries the source: a problem whose source parts fail still works.
    def no_source(*_):
        raise AssertionError("the source was queried")

    problem = _problem(source_step=no_source)
    action = upright.learn(problem, _samples())(np.zeros((3, 2)))
    assert action.shape == (3, 1)
    assert registry.build("ta-tl-h-oracle").model == "oracle"
    assert not registry.build("ta-tl-h-oracle").uses_samples and not ProjectedSource().uses_samples


def test_extension_settings_are_checked():
    """What a declaration cannot say (each declared constraint: tests/test_method_constraints.py)."""
    with pytest.raises(ValueError, match="adaptive_actions is not supported"):
        HorizonTATL(adaptive_actions=(1.0,))


def test_horizon_weights_must_match_the_target():
    description = suite.describe("bicycle", "balance")
    with pytest.raises(ValueError, match="weights must have 4 entries .steer, steer_rate, roll, roll_rate."):
        HorizonTATL(weights=(1.0, 0.0)).check(suite.describe("cartpole", "balance"), description)


def _grid_problem(**hooks):
    plain, windy = suite.describe("gridworld", "plain"), suite.describe("gridworld", "windy")
    next_state, reward, absorbing, cells = plain.known_model()
    source_q = q_iteration(next_state, reward, absorbing, GAMMA, cells=cells)

    def source_step(states, actions):
        from tatl_mj import sampling

        return sampling.step_from("gridworld", "plain", states, actions)

    return TransferProblem(
        source_q=source_q, mapping=IdentityMapping(), source_step=source_step, source=plain, target=windy, **hooks
    )


def test_replan_through_the_problem_is_optimal_with_full_data():
    problem = _grid_problem()
    policy = ReplanTATL(gamma=GAMMA).learn(problem, one_visit_per_pair())
    assert isinstance(policy, ReplanPolicy)
    next_state, reward, absorbing, cells = problem.target.known_model()
    exact = q_iteration(next_state, reward, absorbing, GAMMA, cells=cells)
    np.testing.assert_allclose(policy.values(cells.astype(float)), exact.values(cells.astype(float)), atol=1e-8)
    # The oracle one-step rule reads the exact model and loops (it never reaches the goal from the start).
    oracle = OneStepOracle().learn(problem, one_visit_per_pair())
    env = suite.load("gridworld", "windy", task_kwargs={"random": 0})
    timestep, total = env.reset(), 0.0
    while not timestep.last():
        timestep = env.step(int(oracle(timestep.observation["state"][None])[0]))
        total += timestep.reward
    assert total < 10.0


def test_replan_with_the_papers_protocol_spends_its_budget_on_policy_samples():
    calls = []

    def policy_samples(policy, n):
        calls.append(n)
        return one_visit_per_pair()

    problem = _grid_problem(policy_samples=policy_samples)
    policy = ReplanTATL(data="source-policy").learn(problem, one_visit_per_pair().head(100))
    assert calls == [100] and policy.samples_used == len(one_visit_per_pair())
    with pytest.raises(ValueError, match="policy_samples"):
        ReplanTATL(data="source-policy").learn(_grid_problem(), one_visit_per_pair())


def test_a_variant_is_a_built_in_under_its_own_name():
    variant = registry.build("ta-tl-h-no-cart", {"method": "ta-tl-h", "source_zero": ["x", "x_dot"], "horizon": 5})
    assert isinstance(variant, HorizonTATL) and variant.name == "ta-tl-h-no-cart"
    assert variant.source_zero == ("x", "x_dot") and variant.horizon == 5 and variant.reference == "source"
    upright = registry.build("upright-short", {"method": "apprentice-upright", "horizon": 3})
    assert upright.reference == "zero" and upright.name == "upright-short"
    with pytest.raises(ValueError, match="method 'ta-tl' is a built-in; a variant of 'ta-tl-h' needs a name"):
        registry.build("ta-tl", {"method": "ta-tl-h"})
    with pytest.raises(ValueError, match=r"unknown method 'ta-tl-hh'; valid methods: .* \(or a variant"):
        registry.build("mine", {"method": "ta-tl-hh"})
    with pytest.raises(ValueError, match="unknown method 'mine'; valid methods"):
        registry.build("mine", {})
    with pytest.raises(ValueError, match="'method' of method 'mine' must name a built-in method"):
        registry.build("mine", {"method": 3})


def test_source_zero_names_source_coordinates():
    cartpole, bicycle = suite.describe("cartpole", "balance"), suite.describe("bicycle", "balance")
    HorizonTATL(source_zero=("x", "x_dot")).check(cartpole, bicycle)
    with pytest.raises(ValueError, match=r"source_zero names 'cart'; valid choices: \['x', 'x_dot', 'theta'"):
        HorizonTATL(source_zero=("cart",)).check(cartpole, bicycle)
    with pytest.raises(ValueError, match="source_zero needs reference = 'source'"):
        HorizonTATL(source_zero=("x",), reference="zero")
    with pytest.raises(ValueError, match=r"source_zero must be a list, each entry a source state name, got \(0,\)"):
        HorizonTATL(source_zero=(0,))
