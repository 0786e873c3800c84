"""``apprentice-fqi-samples``: model-based RL on the counted samples alone (issue 68).

Known answers: where the apprentice and the reward are exactly representable, its reward model
predicts held-out samples exactly and its FQI is FQI on the true transitions from the same
states; it learns with every privileged hook of the problem raising (no reward function, no
reset box, no simulator, no episodes); its rounds of rollouts leave the samples' states.
"""

import dataclasses

import numpy as np
import pytest

from tatl_mj.description import TaskDescription
from tatl_mj.experiments.results import pairs
from tatl_mj.suite import gridworld
from tatl_mj.transfer import registry
from tatl_mj.transfer.features import make_features
from tatl_mj.transfer.fqi import LinearRegressor, fitted_q_iteration
from tatl_mj.transfer.method import TransferProblem, Withheld, contract
from tatl_mj.transfer.methods.sample_model import ApprenticeFQISamples, SampleModelPolicy
from tatl_mj.transfer.reward_model import fit_reward_model, reward_bases
from tatl_mj.transitions import Transitions
from tatl_mj.validation import InvalidSetting

ACTIONS = np.array([[-1.0], [0.0], [1.0]])
A = np.array([[1.0, 0.1], [0.0, 0.95]])
B = np.array([[0.0], [0.1]])
REWARD = np.array([1.0, -0.5])  # r = REWARD . s' + 0.25: linear in the state reached


class NoResets(TaskDescription):
    """A target description whose reset box cannot be drawn from."""

    def reset_states(self, n, rng):
        raise AssertionError("the method drew states from the target's reset box")


def _refuse(what):
    def hook(*args, **kwargs):
        raise AssertionError(f"the method called problem.{what}")

    return hook


def _private(description: TaskDescription, **changes) -> NoResets:
    """``description`` without a reset box, whose known model and reward functions raise."""
    fields = {f.name: getattr(description, f.name) for f in dataclasses.fields(description)}
    fields.update(reset_low=None, reset_high=None, **changes)
    for name in ("known_model", "transition_reward", "transition_absorbing"):
        if fields[name] is not None:
            fields[name] = _refuse(f"target.{name}")
    return NoResets(**fields)


def _problem(target: TaskDescription) -> TransferProblem:
    """A problem that hands out nothing but the samples: every hook and the source raise."""
    hooks = ("target_return", "model_return", "model_returns", "target_step", "policy_samples")
    hooks += ("target_reward", "reset_samples", "episode_samples", "charge")
    return TransferProblem(
        source_q=Withheld("source_q"),
        mapping=Withheld("mapping"),
        source_step=Withheld("source_step"),
        source=target,
        target=target,
        seed=3,
        **{name: _refuse(name) for name in hooks},
    )


def _linear_target() -> NoResets:
    description = TaskDescription(
        domain="linear",
        task="drift",
        state_names=("x", "v"),
        periodic=(False, False),
        action_values=ACTIONS,
        discrete=False,
        control_timestep=0.1,
        action_low=np.array([-1.0]),
        action_high=np.array([1.0]),
        reset_low=np.array([-1.0, -1.0]),
        reset_high=np.array([1.0, 1.0]),
    )
    return _private(description)


def _true_step(states, actions):
    after = states @ A.T + ACTIONS[actions] @ B.T
    return after, after @ REWARD + 0.25


def _linear_samples(n=300, seed=0, scale=1.0):
    rng = np.random.default_rng(seed)
    states = rng.uniform(-scale, scale, size=(n, 2))
    actions = rng.integers(3, size=n)
    after, rewards = _true_step(states, actions)
    return Transitions(states, actions, rewards, after, np.zeros(n, bool), np.zeros(n, bool))


LINEAR = dict(
    apprentice={"kind": "linear"},
    features={"kind": "linear"},
    gamma=0.9,
    iterations=30,
    model_samples=10**6,
)


def test_exact_models_give_fqi_on_the_true_transitions_and_no_reward_error():
    problem, data = _problem(_linear_target()), _linear_samples()
    method = ApprenticeFQISamples(**LINEAR, rounds=0, holdout=0.25, reward_ridge=0.0)
    policy = method.learn(problem, data)
    assert isinstance(policy, SampleModelPolicy) and policy.samples_used == len(data)
    assert policy.reward_errors.samples == 75 and policy.reward_errors.reward_scale > 0.1
    assert policy.reward_error < 1e-9 and policy.end_error == 0.0
    # FQI on the samples and on every action's true transition from the same states.
    states = np.unique(np.vstack([data.states, data.next_states]), axis=0)
    assert policy.model_states == len(states)
    actions = np.tile(np.arange(3), len(states))
    after, rewards = _true_step(np.repeat(states, 3, axis=0), actions)
    n = len(actions)
    true = Transitions(np.repeat(states, 3, axis=0), actions, rewards, after, np.zeros(n, bool), np.ones(n, bool))
    regressor = LinearRegressor(make_features({"kind": "linear"}, 2), 1e-6)
    reference = fitted_q_iteration(Transitions.concatenate([data, true]), 3, regressor, 0.9, 30)
    probe = np.random.default_rng(1).uniform(-1, 1, size=(500, 2))
    np.testing.assert_allclose(policy.q.values(probe), reference.values(probe), rtol=1e-7, atol=1e-7)
    np.testing.assert_array_equal(policy(probe), ACTIONS[reference.greedy(probe)])


def _windy_steps(n: int):
    """The windy grid's description and ``n`` uniformly random one-step transitions of it, drawn
    from its known model (the test's simulator, never the method's)."""
    target = gridworld.describe("windy")
    next_state, reward, absorbing, cells = target.known_model()
    rng = np.random.default_rng(0)
    rows, moves = rng.integers(len(cells), size=n), rng.integers(4, size=n)
    ends = absorbing[rows, moves]
    return target, Transitions(cells[rows], moves, reward[rows, moves], cells[next_state[rows, moves]], ends, ends)


def test_the_reward_model_learns_a_step_reward_and_its_ends():
    # The grid's bump depends on the cell and the move, its goal (an end) on the cell reached.
    target, data = _windy_steps(4000)
    onehot = reward_bases({"kind": "onehot", "n_rows": 10, "n_cols": 10}, 2)
    exact = fit_reward_model(data, onehot, "transition", 4, 1e-9)
    predicted, ends = exact.predict(data.states, data.actions, data.next_states)
    np.testing.assert_allclose(predicted, data.rewards, atol=1e-6)
    np.testing.assert_array_equal(ends, data.absorbing)
    # The state reached alone cannot say where a move was blocked.
    after_only = fit_reward_model(data, onehot, "next", 4, 1e-9)
    assert np.abs(after_only.predict(data.states, data.actions, data.next_states)[0] - data.rewards).max() > 0.1


def test_it_learns_the_grid_with_every_privileged_hook_raising():
    target, data = _windy_steps(3000)
    next_state, _, absorbing, cells = target.known_model()  # the test's simulator, not the method's
    onehot = {"kind": "onehot", "n_rows": 10, "n_cols": 10}
    method = ApprenticeFQISamples(
        apprentice=onehot, apprentice_ridge=1e-3, features=onehot, gamma=0.95, iterations=60,
        reward_inputs="transition", rounds=2, horizon=20, starts=50,
    )  # fmt: skip
    policy = method.learn(_problem(_private(target)), data)
    assert policy.reward_error < 1e-3 and policy.end_error == 0.0
    cell = int(np.flatnonzero(np.all(cells == gridworld.START, axis=1))[0])
    for _ in range(40):  # the greedy policy walks the true windy grid to its goal
        move = int(policy(cells[cell][None].astype(float))[0])
        if absorbing[cell, move]:
            break
        cell = next_state[cell, move]
    else:
        pytest.fail("the greedy policy did not reach the goal in 40 steps")


def test_rounds_roll_the_policy_out_beyond_the_samples():
    # Samples near the origin; the reward grows with x, so the greedy policy drives away from them.
    problem, data = _problem(_linear_target()), _linear_samples(scale=0.2)
    seen = np.abs(np.vstack([data.states, data.next_states])).max(axis=0)
    spread = {}
    for rounds in (0, 1, 3):
        method = ApprenticeFQISamples(**LINEAR, rounds=rounds, horizon=30, starts=40, epsilon=0.0)
        apprentice = method.fit_apprentice(problem, data)
        rewards = fit_reward_model(data, reward_bases({"kind": "linear"}, 2), "next", 3, 1e-6)
        _, states = method.plan(problem, data, apprentice, rewards, np.random.default_rng(0))
        outside = np.any(np.abs(states) > seen + 1e-9, axis=1)
        spread[rounds] = (len(states), int(outside.sum()), float(np.abs(states[:, 0]).max()))
    assert spread[0][1] == 0 and spread[0][0] <= 2 * len(data)  # the samples' own states only
    assert spread[1][0] > spread[0][0] and spread[1][1] > 0
    assert spread[3][0] > spread[1][0] and spread[3][2] > 2 * seen[0]


def _recorded_plan(monkeypatch, **settings):
    """``plan``'s fits in order, each as (kind, iterations, the Q it started from, the Q it gave)."""
    calls, cold, warm = [], ApprenticeFQISamples.fqi, ApprenticeFQISamples.refit

    def fqi(self, problem, data, rng):
        calls.append(("cold", self.iterations, None, cold(self, problem, data, rng)))
        return calls[-1][3]

    def refit(self, data, start, iterations, rng):
        calls.append(("warm", iterations, start, warm(self, data, start, iterations, rng)))
        return calls[-1][3]

    monkeypatch.setattr(ApprenticeFQISamples, "fqi", fqi)
    monkeypatch.setattr(ApprenticeFQISamples, "refit", refit)
    problem, data = _problem(_linear_target()), _linear_samples(scale=0.2)
    method = ApprenticeFQISamples(**LINEAR, rounds=3, horizon=30, starts=40, **settings)
    rewards = fit_reward_model(data, reward_bases({"kind": "linear"}, 2), "next", 3, 1e-6)
    q, _ = method.plan(problem, data, method.fit_apprentice(problem, data), rewards, np.random.default_rng(0))
    return q, calls


def test_warm_rounds_refit_from_the_previous_q_and_the_policy_gets_every_iteration(monkeypatch):
    q, calls = _recorded_plan(monkeypatch, round_iterations=5)
    assert [c[:2] for c in calls] == [("cold", 30), ("warm", 5), ("warm", 5), ("warm", 30)]
    assert all(calls[i][2] is calls[i - 1][3] for i in range(1, 4)) and q is calls[-1][3]
    # Without round_iterations every fit starts from zero with every iteration, as before.
    q, calls = _recorded_plan(monkeypatch, round_iterations=None)
    assert [c[:2] for c in calls] == [("cold", 30)] * 4 and q is calls[-1][3]


def test_a_warm_refit_starts_where_it_is_told():
    # From Q_0 = the converged Q of the same data one more iteration stays there; from zero one
    # iteration is a one-step Q, far from it: the start is used, not reset.
    problem, data = _problem(_linear_target()), _linear_samples()
    method = ApprenticeFQISamples(**{**LINEAR, "iterations": 400})
    converged = method.fqi(problem, data, np.random.default_rng(0))
    again = method.refit(data, converged, 1, np.random.default_rng(0))
    np.testing.assert_allclose(again.weights, converged.weights, rtol=1e-9, atol=1e-12)
    cold_one = dataclasses.replace(method, iterations=1).fqi(problem, data, np.random.default_rng(0))
    assert np.abs(cold_one.weights - converged.weights).max() > 0.5


def test_roles_and_pairs():
    held = contract(registry.build("apprentice-fqi-samples"))
    assert not held.uses_source and not held.privileged and not held.baseline and held.ablation_of == ("ta-tl",)
    no_alg2 = {"method": "ta-tl", "zeta": "none"}
    tables = {"ta-tl": {}, "ta-tl-no-alg2": no_alg2, "apprentice-fqi-samples": {}, "rl": {}}
    assert sorted(pairs.ablation_pairs(tables)) == [
        ("ta-tl", "apprentice-fqi-samples"),
        ("ta-tl-no-alg2", "apprentice-fqi-samples"),
    ]
    # Beside the privileged apprentice-fqi, each transfer method is judged against both.
    both = {**tables, "apprentice-fqi": {}}
    assert sorted(pairs.ablation_pairs(both)) == [
        ("ta-tl", "apprentice-fqi"),
        ("ta-tl", "apprentice-fqi-samples"),
        ("ta-tl-no-alg2", "apprentice-fqi"),
        ("ta-tl-no-alg2", "apprentice-fqi-samples"),
    ]


def test_settings_it_cannot_take_are_refused_in_one_line():
    with pytest.raises(InvalidSetting, match=r"ApprenticeFQISamples.data must be one of \['shared'\]"):
        ApprenticeFQISamples(data="reset")
    target = _linear_target()
    with pytest.raises(InvalidSetting, match="ApprenticeFQISamples.reward_features: "):
        ApprenticeFQISamples(
            reward_features={"kind": "rbf", "centers": 4, "low": [0], "high": [1], "sigma": [1]}
        ).check(target, target)
    with pytest.raises(InvalidSetting, match="ApprenticeFQISamples.round_iterations"):
        ApprenticeFQISamples(round_iterations=0)
    with pytest.raises(InvalidSetting, match="model_samples .2. must cover one state's 3 actions"):
        ApprenticeFQISamples(model_samples=2).check(target, target)
    wide = {"kind": "rbf", "centers": [[0.0, 0.0]], "sigma": [1.0, 1.0], "periodic": [False, False]}
    both = ({"kind": "linear"}, wide)
    built = registry.build("apprentice-fqi-samples", {"reward_features": list(both), "starts": "all"})
    assert built.reward_features == both and built.starts == "all"
    built.check(target, target)


def test_the_reward_error_script_gives_what_the_unit_measures():
    # scripts/reward_errors.py recomputes each unit's held-out reward error without learning a
    # policy; it must be the very number the learned policy reports.
    import importlib.util
    from pathlib import Path

    from conftest import tiny_spec

    from tatl_mj.experiments.run import method_unit, source_unit

    path = Path(__file__).resolve().parents[1] / "scripts" / "reward_errors.py"
    loader = importlib.util.spec_from_file_location("reward_errors", path)
    script = importlib.util.module_from_spec(loader)
    loader.loader.exec_module(script)
    spec = tiny_spec()
    preset = spec.preset("tiny")
    artifacts = source_unit.learn_source(spec, preset, 3)
    recomputed = script.reward_errors(spec, "tiny", "apprentice-fqi-samples", 3)
    for budget, errors in zip(preset.target_budgets, recomputed):
        learner = dataclasses.replace(
            registry.resolve("apprentice-fqi-samples", dict(spec.methods["apprentice-fqi-samples"])), rounds=0
        )
        policy = method_unit.learned_policy(spec, preset, 3, learner, artifacts, budget)
        assert policy.reward_errors == errors and errors.reward_rmse is not None
