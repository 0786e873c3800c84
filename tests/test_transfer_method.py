"""The plug-in interface and the built-in methods (tatl_mj.transfer.method, baselines)."""

import numpy as np
import pytest

from tatl_mj.transfer.alignment import IdentityMapping
from tatl_mj.transfer.baselines import MappedQ, rl, uma_tl
from tatl_mj.transfer.features import LinearFeatures
from tatl_mj.transfer.fqi import LinearRegressor
from tatl_mj.transfer.method import METHODS, RL, TATL, UMATL, TransferMethod, TransferProblem
from tatl_mj.transfer.tatl import TATLPolicy
from tatl_mj.transitions import Transitions

ACTIONS = np.array([[-1.0], [0.0], [1.0]])


class SourceQ:
    """Q_S(x, a) = a * x_0: the greedy source action pushes towards +x_0 sign."""

    n_actions = 3

    def values(self, x):
        return np.asarray(x)[:, :1] * ACTIONS[:, 0][None, :]

    def greedy(self, x):
        return np.argmax(self.values(x), axis=1)


def _samples(n=400, seed=0):
    rng = np.random.default_rng(seed)
    s = rng.uniform(-1, 1, size=(n, 2))
    a = rng.integers(3, size=n)
    s_next = s + 0.1 * np.stack([s[:, 1], -2.0 * ACTIONS[a, 0]], axis=1)
    r = -np.abs(s_next[:, 0])
    return Transitions(s, a, r, s_next, np.zeros(n, bool), np.zeros(n, bool))


def _problem(**overrides):
    kwargs = dict(
        source_q=SourceQ(), mapping=IdentityMapping(),
        source_step=lambda x, i: x + 0.1 * np.stack([x[:, 1], ACTIONS[i, 0]], axis=1),
        source_actions=ACTIONS, target_actions=2 * ACTIONS, target_low=[-3.0], target_high=[3.0],
        target_discrete=False, apprentice_features=LinearFeatures(),
        regressor={"kind": "linear", "features": {"kind": "linear"}}, gamma=0.9, iterations=10, seed=0,
    )
    kwargs.update(overrides)
    return TransferProblem(**kwargs)


def test_methods_dict_and_protocol():
    assert set(METHODS) == {"ta-tl", "uma-tl", "rl"}
    assert all(isinstance(m, TransferMethod) and m.name == key for key, m in METHODS.items())

    class MyMethod:
        name = "always-zero"

        def learn(self, problem, target_samples):
            return lambda states: np.zeros((len(states), 1))

    assert isinstance(MyMethod(), TransferMethod)


def test_builtin_methods_return_batched_policies():
    problem, samples = _problem(), _samples()
    states = samples.states[:7]
    tatl = TATL().learn(problem, samples)
    assert isinstance(tatl, TATLPolicy) and tatl.samples_used == len(samples)
    # Target: the action acts with gain -2 on the velocity (0.1 * -2 * a_T with a_T = 2 a_S): the
    # apprentice finds B < 0, so TA-TL reverses the source's push.
    step = tatl.step(states)
    assert tatl.apprentice.B[1, 0] < 0
    np.testing.assert_allclose(tatl(states), np.clip(-0.5 * step.a_T, -3, 3), atol=1e-6)
    for method in (UMATL(), RL()):
        actions = method.learn(problem, samples)(states)
        assert actions.shape == (7, 1) and set(actions[:, 0]) <= {-2.0, 0.0, 2.0}
    discrete = RL().learn(_problem(target_discrete=True), samples)(states)
    assert discrete.shape == (7,) and discrete.dtype == np.int64


def test_tatl_uses_algorithm_2_when_given_a_utility_gap():
    calls = []

    def gap(apprentice):
        calls.append(apprentice)
        return 0.0 if len(calls) >= 2 else 1.0

    policy = TATL().learn(_problem(utility_gap=gap, zeta=0.1, apprentice_batch=50), _samples())
    assert policy.samples_used == 100 and len(calls) == 2


def test_uma_tl_starts_from_the_mapped_source_q():
    """Zero target rewards and one iteration: Q_1(., a) is the least-squares fit of
    gamma * max_b Q_S(chi_plus(s'), b) (= gamma |s'_0|) on action a's samples."""
    samples = _samples()
    zero = Transitions(samples.states, samples.actions, np.zeros(len(samples)), samples.next_states,
                       samples.absorbing, samples.last)
    reg = LinearRegressor(LinearFeatures(), ridge=0.0)
    q = uma_tl(SourceQ(), IdentityMapping(), zero, 3, reg, 0.5, 1)
    target = 0.5 * MappedQ(SourceQ(), IdentityMapping()).values(zero.next_states).max(axis=1)
    for a in range(3):
        rows = zero.actions == a
        design = np.hstack([np.ones((rows.sum(), 1)), zero.states[rows]])
        expected = np.linalg.lstsq(design, target[rows], rcond=None)[0]
        np.testing.assert_allclose(q.weights[a], expected, atol=1e-10)
    # From scratch, zero rewards give Q = 0.
    np.testing.assert_allclose(rl(zero, 3, reg, 0.5, 3).values(zero.states), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="actions"):
        uma_tl(SourceQ(), IdentityMapping(), zero, 2, reg, 0.5, 1)


def test_problem_validation():
    with pytest.raises(ValueError, match="target_low"):
        _problem(target_low=None)
    with pytest.raises(ValueError, match="gamma"):
        _problem(gamma=1.5)
