"""The plug-in interface and the built-in methods (tatl_mj.transfer.method, methods.tatl, methods.target_fqi)."""

import types

import numpy as np
import pytest

from tatl_mj.description import TaskDescription
from tatl_mj.transfer.algorithm1 import TATLPolicy
from tatl_mj.transfer.features import LinearFeatures
from tatl_mj.transfer.fqi import LinearRegressor, fitted_q_iteration
from tatl_mj.transfer.intertask_mapping import IdentityMapping
from tatl_mj.transfer.method import TransferMethod, TransferProblem
from tatl_mj.transfer.methods.target_fqi import RL, UMATL, MappedQ
from tatl_mj.transfer.methods.tatl import TATL
from tatl_mj.transfer.registry import METHODS, build
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


def _description(actions, discrete=False, low=-3.0, high=3.0):
    return TaskDescription(
        domain="toy",
        task="t",
        state_names=("x", "v"),
        periodic=(False, False),
        action_values=actions,
        discrete=discrete,
        control_timestep=0.1,
        action_low=None if discrete else [low],
        action_high=None if discrete else [high],
    )


def _problem(target_discrete=False, **overrides):
    kwargs = dict(
        source_q=SourceQ(),
        mapping=IdentityMapping(),
        source_step=lambda x, i: x + 0.1 * np.stack([x[:, 1], ACTIONS[i, 0]], axis=1),
        source=_description(ACTIONS),
        target=_description(2 * ACTIONS, discrete=target_discrete),
        seed=0,
    )
    kwargs.update(overrides)
    return TransferProblem(**kwargs)


def test_registry_and_protocol():
    assert {"ta-tl", "uma-tl", "rl"} <= set(METHODS)
    for name in METHODS:
        method = build(name)
        assert isinstance(method, TransferMethod) and method.name == name
    assert build("ta-tl", {"zeta": 0.3, "adaptive_actions": [-1, 1]}) == TATL(zeta=0.3, adaptive_actions=(-1, 1))
    with pytest.raises(ValueError, match="unknown setting 'zeeta' for method 'ta-tl'; valid settings: .*zeta"):
        build("ta-tl", {"zeeta": 0.3})
    with pytest.raises(ValueError, match="unknown method 'ta-tll'; valid methods"):
        build("ta-tll")

    class MyMethod:
        name = "always-zero"

        def learn(self, problem, target_samples):
            return lambda states: np.zeros((len(states), 1))

    assert isinstance(MyMethod(), TransferMethod)


@pytest.mark.parametrize(
    "make, message",
    [
        # One refused value per declared constraint is tests/test_method_constraints.py's; here what
        # a declaration cannot say: why a features table is refused, and cross-setting rules.
        (lambda: TATL(apprentice={"kind": "polynomial"}), "features kind 'polynomial' is unknown; valid kinds"),
        (lambda: TATL(apprentice={"kind": "rbf", "centres": 100, "sigma": [1.0]}), "unknown keys \\['centres'\\]"),
        (lambda: RL(regressor="extra_trees", ridge=1.0), "RL.ridge applies to regressor 'linear' only"),
        (lambda: RL(regressor="extra_trees", features={"kind": "linear"}), "RL.features applies to regressor 'linear'"),
        (lambda: RL(n_estimators=10), "RL.n_estimators applies to regressor 'extra_trees' only"),
    ],
)
def test_settings_are_checked_in_the_constructor(make, message):
    with pytest.raises(ValueError, match=message):
        make()


def test_builtin_methods_return_batched_policies():
    problem, samples = _problem(), _samples()
    states = samples.states[:7]
    tatl = TATL(actions="continuous").learn(problem, samples)
    assert isinstance(tatl, TATLPolicy) and tatl.samples_used == len(samples)
    # Target: the action acts with gain -2 on the velocity (0.1 * -2 * a_T with a_T = 2 a_S): the
    # apprentice finds B < 0, so TA-TL reverses the source's push.
    step = tatl.step(states)
    assert tatl.apprentice.B[1, 0] < 0
    continuous = np.clip(-0.5 * step.a_T, -3, 3)
    np.testing.assert_allclose(tatl(states), continuous, atol=1e-6)
    # By default the same rule snaps to the target's discrete actions, the baselines' set.
    values = problem.target.action_values[:, 0]
    snapped = TATL().learn(problem, samples)(states)
    assert set(snapped[:, 0]) <= set(values)
    gaps = np.abs(tatl.step(states).action - values[None, :])  # the unsnapped rule's action
    np.testing.assert_allclose(np.abs(snapped - tatl(states))[:, 0], gaps.min(axis=1), atol=1e-9)
    for method in (UMATL(gamma=0.9, iterations=10), RL(gamma=0.9, iterations=10)):
        actions = method.learn(problem, samples)(states)
        assert actions.shape == (7, 1) and set(actions[:, 0]) <= {-2.0, 0.0, 2.0}
    discrete = RL().learn(_problem(target_discrete=True), samples)(states)
    assert discrete.shape == (7,) and discrete.dtype == np.int64


def test_tatl_uses_algorithm_2_through_the_problem_hooks():
    """U_M = -10 for the projected policy; the 'model' return is -20 until the apprentice
    has 100 samples, then -10.5: relative gaps 1.0 then 0.05 <= zeta = 0.1."""
    seen = []

    def model_return(apprentice, policy):
        seen.append(apprentice)
        return -20.0 if len(seen) < 2 else -10.5

    problem = _problem(target_return=lambda policy: -10.0, model_return=model_return)
    policy = TATL(zeta=0.1, gap="relative", batch=50).learn(problem, _samples())
    assert policy.samples_used == 100 and len(seen) == 2
    assert problem.utility_gap(seen[0], kind="relative") == pytest.approx(0.05)
    # The paper's rule is absolute and one-sided: U_M - U_Mhat = -10 + 10.5 = 0.5 > 0.1 at 100
    # samples, so it goes on; a model that overrates the policy (U_Mhat = -9) stops it at once.
    seen.clear()
    with pytest.warns(RuntimeWarning, match="stopping rule .* not met with all 400 samples"):
        assert TATL(zeta=0.1, batch=50).learn(problem, _samples()).samples_used == 400
    assert problem.utility_gap(seen[0]) == pytest.approx(0.5)
    optimistic = _problem(target_return=lambda policy: -10.0, model_return=lambda apprentice, policy: -9.0)
    assert TATL(zeta=0.1, batch=50).learn(optimistic, _samples()).samples_used == 50
    # Without the hooks (or zeta None) the apprentice uses every sample.
    assert TATL(zeta=0.1, batch=50).learn(_problem(), _samples()).samples_used == 400
    assert TATL(zeta=None, batch=50).learn(problem, _samples()).samples_used == 400


def test_tatl_returns_the_same_policy_for_budgets_that_keep_the_same_samples():
    """Algorithm 2 stops at 50 samples at every budget here, so budgets 200 and 400 of one
    stream learn one policy, returned as the same object (evaluated once); another stream's
    first 50 samples make another."""
    problem = _problem(target_return=lambda policy: -10.0, model_return=lambda apprentice, policy: -9.0)
    method, stream = TATL(zeta=0.1, batch=50), _samples()
    small, large = method.learn(problem, stream.head(200)), method.learn(problem, stream.head(400))
    assert small is large and small.samples_used == 50
    other = method.learn(problem, _samples(seed=1))
    assert other is not small and other.samples_used == 50
    # Another method object (another setting) learns its own.
    assert TATL(zeta=0.1, batch=50, actions="continuous").learn(problem, stream) is not small


def test_uma_tl_starts_from_the_mapped_source_q():
    """Zero target rewards and one iteration: Q_1(., a) is the least-squares fit of
    gamma * max_b Q_S(chi_plus(s'), b) (= gamma |s'_0|) on action a's samples."""
    samples = _samples()
    zero = Transitions(
        samples.states, samples.actions, np.zeros(len(samples)), samples.next_states, samples.absorbing, samples.last
    )
    reg = LinearRegressor(LinearFeatures(), ridge=0.0)
    mapped = MappedQ(SourceQ(), IdentityMapping())
    q = fitted_q_iteration(zero, 3, reg, 0.5, 1, initial_q=mapped)
    target = 0.5 * mapped.values(zero.next_states).max(axis=1)
    for a in range(3):
        rows = zero.actions == a
        design = np.hstack([np.ones((rows.sum(), 1)), zero.states[rows]])
        expected = np.linalg.lstsq(design, target[rows], rcond=None)[0]
        np.testing.assert_allclose(q.weights[a], expected, atol=1e-10)
    # From scratch, zero rewards give Q = 0.
    np.testing.assert_allclose(fitted_q_iteration(zero, 3, reg, 0.5, 3).values(zero.states), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="actions"):
        fitted_q_iteration(zero, 2, reg, 0.5, 1, initial_q=mapped)


def test_problem_validation():
    with pytest.raises(ValueError, match="Assumption 1"):
        _problem(target=_description(np.array([[1.0], [2.0]])))
    with pytest.raises(ValueError, match="action_low/action_high are required"):
        TaskDescription(
            domain="toy",
            task="t",
            state_names=("x",),
            periodic=(False,),
            action_values=ACTIONS,
            discrete=False,
            control_timestep=0.1,
        )


def test_the_method_contract_fills_in_its_defaults_and_reads_what_a_method_declares():
    from tatl_mj.transfer import method as method_mod
    from tatl_mj.transfer.registry import build

    class Bare:
        name = "bare"

        def learn(self, problem, target_samples):
            return lambda states: states[:, :1] * 0

    bare = method_mod.contract(Bare())
    assert (bare.uses_samples, bare.data, bare.source, bare.check) == (True, "shared", "trained", None)
    online = method_mod.contract(build("rl-online"))
    assert online.data == "online" and online.check is not None
    assert method_mod.contract(build("projected-source")).uses_samples is False
    assert method_mod.contract(build("ta-tl-x", {"method": "ta-tl", "source": "placebo"})).source == "placebo"
    assert method_mod.samples_used(lambda s: s, 300) == 300
    assert method_mod.samples_used(types.SimpleNamespace(samples_used=120), 300) == 120


def test_tatl_keeps_algorithm_2s_gaps_for_a_later_budget_and_still_counts_u_m():
    """Budgets 200 then 400 of one stream, batch 50: the larger budget rolls out only its new
    sizes (250-400) and learns the apprentice a fresh problem learns; where every gap is known
    (met at 50 samples) it rolls out none, yet asks U_M, which the runner counts per budget."""
    u_hats, u_trues = [], []

    def model_return(apprentice, policy):
        u_hats.append(1)
        return -11.0 - float(np.abs(apprentice.B).sum())  # never within zeta = 0.1 of U_M

    def target_return(policy):
        u_trues.append(1)
        return -10.0

    method, stream = TATL(zeta=0.1, batch=50), _samples()
    problem = _problem(target_return=target_return, model_return=model_return)
    with pytest.warns(RuntimeWarning, match="not met"):
        method.learn(problem, stream.head(200))
    assert len(u_hats) == 4
    u_hats.clear(), u_trues.clear()
    with pytest.warns(RuntimeWarning, match="not met"):
        kept = method.learn(problem, stream.head(400))
    assert len(u_hats) == 4 and len(u_trues) >= 1
    with pytest.warns(RuntimeWarning, match="not met"):
        fresh = method.learn(_problem(target_return=target_return, model_return=model_return), stream.head(400))
    assert kept.samples_used == fresh.samples_used == 400
    assert np.array_equal(kept.apprentice.B, fresh.apprentice.B)
    assert np.array_equal(kept.apprentice.W, fresh.apprentice.W)
    met = _problem(target_return=target_return, model_return=lambda apprentice, policy: -9.0)
    method.learn(met, stream.head(200))
    u_trues.clear()
    assert method.learn(met, stream.head(400)).samples_used == 50 and len(u_trues) == 1
