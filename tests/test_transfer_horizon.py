"""Known answers for horizon-matched TA-TL (tatl_mj.transfer.methods.horizon, horizon_policy, linearisation).

1. With H = 1, rho = 1 and W = I it is Algorithm 1 (algorithm1.TATLPolicy) up to rounding, on
   the fixture of test_transfer_tatl (double integrator seen through an affine map) and on
   an apprentice with a periodic coordinate near the wrap.
2. A double integrator whose action moves only the velocity, asked to follow a source
   that only has a position: one-step TA-TL never moves it, the horizon brings it home.
3. The zero reference regulates an open-loop unstable linear system to 0.
4. The oracle (the true model) and an exact apprentice give the same actions.
"""

import dataclasses

import numpy as np
import pytest
from test_transfer_tatl import CHI, SOURCE_ACTIONS, OneStepLQRQ, source_step
from test_transfer_tatl import target_step as tatl_target_step

from tatl_mj.transfer.algorithm1 import TATLPolicy
from tatl_mj.transfer.apprentice import Apprentice, fit_apprentice
from tatl_mj.transfer.features import LinearFeatures, wrap_angle
from tatl_mj.transfer.intertask_mapping import AffineMapping
from tatl_mj.transfer.methods.horizon_policy import HorizonTATLPolicy

# --- The fixture of test_transfer_tatl ------------------------------------------------


def target_step(s_T, a_T, gain=2.5, kappa=np.array([0.8, -0.3]), c=0.4):
    return tatl_target_step(s_T, a_T, gain, kappa, c)


def _noisy_apprentice(seed=0):
    rng = np.random.default_rng(seed)
    s = CHI.chi(rng.uniform(-2, 2, size=(500, 2)))
    a = rng.uniform(-3, 3, size=(500, 1))
    return fit_apprentice(s, a, target_step(s, a) + 1e-4 * rng.normal(size=s.shape), LinearFeatures())


def _pair(apprentice, low=-50.0, high=50.0, **horizon_kwargs):
    common = dict(source_q=OneStepLQRQ(), mapping=CHI, source_step=source_step, target_actions=2.0 * SOURCE_ACTIONS)
    one_step = TATLPolicy(
        common["source_q"], CHI, source_step, apprentice, SOURCE_ACTIONS, common["target_actions"], [low], [high]
    )
    horizon = HorizonTATLPolicy(
        apprentice.predict, [low], [high], periodic=apprentice.periodic, **{**common, **horizon_kwargs}
    )
    return one_step, horizon


def test_one_step_horizon_is_algorithm_1():
    """H = 1, rho = 1, W = I: same references, nominal action, G_1 = B_hat and action as
    TATLPolicy (a_T + pinv(B_hat) pi_ad), to 1e-12 relative; clipping too."""
    apprentice = _noisy_apprentice()
    states = CHI.chi(np.random.default_rng(5).uniform(-2, 2, size=(60, 2)))
    for low, high in [(-50.0, 50.0), (-0.2, 0.3)]:
        one_step, horizon = _pair(apprentice, low, high, horizon=1, step_ratio=1, weights=np.ones(2))
        expected, got = one_step.step(states), horizon.step(states)
        np.testing.assert_array_equal(got.references[:, 0], expected.s_hat_T_next)
        np.testing.assert_array_equal(got.nominal, expected.a_T)
        np.testing.assert_array_equal(got.a_S, expected.a_S)
        np.testing.assert_allclose(got.control[:, 0], np.broadcast_to(apprentice.B, (60, 2, 1)), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(got.adaptive, expected.adaptive, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(got.action, expected.action, rtol=1e-10, atol=1e-12)
    assert np.any(expected.action == 0.3) and np.any(expected.action == -0.2)  # the last run clipped


def test_one_step_horizon_is_algorithm_1_across_the_wrap():
    """An apprentice with a periodic angle near +-pi: the wrapped gaps agree too."""
    apprentice = Apprentice(
        W=np.array([[0.1, 0.0, 0.0, 0.05], [0.0, 0.3, -0.2, 0.9]]),  # phi = [1, sin, cos, v]
        B=np.array([[0.02], [0.4]]),
        features=LinearFeatures(periodic=(True, False)),
        periodic=(True, False),
    )
    identity = AffineMapping(np.eye(2), np.zeros(2))

    def wrapped_source_step(x, a_idx):
        nxt = x + np.outer(SOURCE_ACTIONS[a_idx, 0], [0.1, 0.2]) + np.array([0.05, 0.0])
        nxt[:, 0] = wrap_angle(nxt[:, 0])
        return nxt

    states = np.column_stack([np.random.default_rng(7).uniform(2.9, 3.4, 40), np.linspace(-1, 1, 40)])
    states[:, 0] = wrap_angle(states[:, 0])
    kwargs = dict(source_q=_AngleQ(), mapping=identity, source_step=wrapped_source_step, target_actions=SOURCE_ACTIONS)
    one_step = TATLPolicy(
        kwargs["source_q"], identity, wrapped_source_step, apprentice, SOURCE_ACTIONS, SOURCE_ACTIONS, [-100.0], [100.0]
    )
    horizon = HorizonTATLPolicy(
        apprentice.predict, [-100.0], [100.0], weights=np.ones(2), periodic=apprentice.periodic, **kwargs
    )
    expected, got = one_step.step(states), horizon.step(states)
    raw = expected.s_hat_T_next[:, 0] - apprentice.predict(states, expected.a_T)[:, 0]
    assert np.abs(raw).max() > 6.0 and np.abs(expected.pi_ad[:, 0]).max() < 1.0  # gaps crossed the wrap
    np.testing.assert_allclose(got.action, expected.action, rtol=1e-10, atol=1e-12)


class _AngleQ:
    """Pushes the angle towards +pi (the wrap) so references cross it."""

    n_actions = 3

    def values(self, x):
        return SOURCE_ACTIONS[None, :, 0] * np.sign(np.sin(x[:, 0]))[:, None]

    def greedy(self, x):
        return np.argmax(self.values(x), axis=1)


# --- A double integrator following a position-only source -----------------------------

DT_T, DT_S = 0.1, 0.2  # rho = 2
A2 = np.array([[1.0, DT_T], [0.0, 1.0]])  # Euler: the action reaches the position after 2 steps
B2 = np.array([[0.0], [DT_T]])
GOAL = 1.0


class GoalQ:
    """Greedy one-step source policy towards GOAL for x' = x + (GOAL - x) / 2 + DT_S u."""

    n_actions = 3

    def values(self, x):
        nxt = x[:, None, 0] + 0.5 * (GOAL - x[:, None, 0]) + DT_S * SOURCE_ACTIONS[None, :, 0]
        return -((nxt - GOAL) ** 2)

    def greedy(self, x):
        return np.argmax(self.values(x), axis=1)


def goal_step(x, a_idx):
    return x + 0.5 * (GOAL - x) + DT_S * SOURCE_ACTIONS[a_idx]


def integrator_step(s, a):
    return s @ A2.T + a @ B2.T


POSITION = AffineMapping(np.array([[1.0], [0.0]]), np.zeros(2))  # chi(x) = [x, 0]


def _integrator_apprentice():
    rng = np.random.default_rng(1)
    s, a = rng.uniform(-2, 2, size=(200, 2)), rng.uniform(-3, 3, size=(200, 1))
    return fit_apprentice(s, a, integrator_step(s, a), LinearFeatures())


def _goal_policy(model, **kwargs):
    return HorizonTATLPolicy(
        model,
        [-5.0],
        [5.0],
        source_q=GoalQ(),
        mapping=POSITION,
        source_step=goal_step,
        target_actions=SOURCE_ACTIONS,
        **kwargs,
    )


def _closed_loop(policy, steps):
    s = np.array([[0.0, 0.0]])
    for _ in range(steps):
        s = integrator_step(s, policy(s))
    return s[0]


def test_horizon_recovers_an_output_unactuated_for_one_step():
    """Start at rest at 0, source goes to 1. Algorithm 1 (and H = 1, W = I) servo the
    velocity to the reference's 0 and never move (|p| < 1e-12 after 100 steps); H = 10
    with W on position, rho = 2, reaches the goal (measured |p - 1| = 2e-6 after 100
    steps, 4e-16 after 300)."""
    apprentice = _integrator_apprentice()
    one_step = TATLPolicy(GoalQ(), POSITION, goal_step, apprentice, SOURCE_ACTIONS, SOURCE_ACTIONS, [-5.0], [5.0])
    for policy in (one_step, _goal_policy(apprentice.predict, weights=np.ones(2))):
        assert np.all(np.abs(_closed_loop(policy, 100)) < 1e-12)
    horizon = _goal_policy(apprentice.predict, horizon=10, step_ratio=2, weights=np.array([1.0, 0.0]))
    p, v = _closed_loop(horizon, 100)
    assert abs(p - GOAL) < 1e-4 and abs(v) < 1e-4
    p, v = _closed_loop(horizon, 300)
    assert abs(p - GOAL) < 1e-10 and abs(v) < 1e-10


def test_responses_and_references_have_their_closed_forms():
    """G_j = sum_{i<j} A^i B and F_j = A^j s + G_j a_0 for the linear model; with the source
    far below the goal (u = +1 every step) rho = 2 gives r_2k = chi(x_k) and r_(2k+1) the
    midpoint of chi(x_k) and chi(x_(k+1))."""
    policy = _goal_policy(integrator_step, horizon=7, step_ratio=2.0, weights=np.array([1.0, 0.0]))
    states = np.array([[-9.0, 0.3], [-8.0, -1.0]])
    got = policy.step(states)
    assert got.source_states.shape == (2, 5, 1)  # K = ceil(7 / 2) = 4 source steps
    np.testing.assert_array_equal(got.a_S, [2, 2])
    for row, start in enumerate(states):
        x = [start[0]]
        for _ in range(4):
            x.append(x[-1] + 0.5 * (GOAL - x[-1]) + DT_S)
        np.testing.assert_allclose(got.source_states[row, :, 0], x, rtol=1e-14)
        positions = [x[j // 2] if j % 2 == 0 else 0.5 * (x[j // 2] + x[j // 2 + 1]) for j in range(1, 8)]
        np.testing.assert_allclose(got.references[row, :, 0], positions, rtol=1e-14)
        np.testing.assert_array_equal(got.references[row, :, 1], 0.0)
        g, power, s = np.zeros((2, 1)), np.eye(2), start
        for j in range(7):
            g, power = g + power @ B2, power @ A2
            s = A2 @ s + B2[:, 0] * got.nominal[row, 0]
            np.testing.assert_allclose(got.control[row, j], g, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(got.free[row, j], s, rtol=1e-12)


def test_oracle_and_exact_apprentice_agree():
    """The true linear model as ``model`` (oracle) and an apprentice fitted to it without
    noise give the same actions (to 1e-9), for several horizons and ratios."""
    apprentice = _integrator_apprentice()
    states = np.random.default_rng(3).uniform(-2, 2, size=(30, 2))
    for horizon, ratio in [(1, 1.0), (5, 2.0), (12, 0.5), (9, 3.0)]:
        kwargs = dict(horizon=horizon, step_ratio=ratio, weights=np.array([1.0, 0.05]))
        oracle, learned = _goal_policy(integrator_step, **kwargs), _goal_policy(apprentice.predict, **kwargs)
        np.testing.assert_allclose(learned(states), oracle(states), rtol=1e-9, atol=1e-9)


# --- The zero reference ---------------------------------------------------------------

UNSTABLE_A = np.array([[1.0, 0.05], [0.5, 1.0]])  # Euler x'' = 10 x: eigenvalues 1 +- 0.158
UNSTABLE_B = np.array([[0.0], [0.05]])


def test_zero_reference_regulates_an_unstable_system():
    """No source at all: the closed loop is linear a = -K s (nominal 0, no clipping), its
    spectral radius is < 0.9 (open loop 1.16), and it brings [0.2, 0] to within 1e-12 of 0
    in 300 steps."""

    def model(s, a):
        return s @ UNSTABLE_A.T + a @ UNSTABLE_B.T

    policy = HorizonTATLPolicy(model, [-100.0], [100.0], horizon=10, weights=np.array([1.0, 0.01]), reference="zero")
    gain = -policy(np.eye(2))  # rows: the action at each unit state
    states = np.random.default_rng(4).normal(size=(5, 2))
    np.testing.assert_allclose(policy(states), -states @ gain, rtol=1e-9, atol=1e-12)
    closed = UNSTABLE_A - UNSTABLE_B @ gain.T
    assert np.max(np.abs(np.linalg.eigvals(UNSTABLE_A))) > 1.1
    assert np.max(np.abs(np.linalg.eigvals(closed))) < 0.9  # measured 0.867
    s = np.array([[0.2, 0.0]])
    for _ in range(300):
        s = model(s, policy(s))
    assert np.linalg.norm(s) < 1e-12
    decision = policy.step(s)
    assert decision.a_S is None and decision.source_states is None
    np.testing.assert_array_equal(decision.references, 0.0)


# --- Bad input ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(reference="upright"), r"HorizonTATLPolicy.reference must be one of \['source', 'zero'\], got 'upright'"),
        (dict(horizon=0), "HorizonTATLPolicy.horizon must be an integer >= 1"),
        (dict(horizon=2.5), "HorizonTATLPolicy.horizon must be an integer >= 1"),
        (dict(step_ratio=-2.0), "HorizonTATLPolicy.step_ratio must be a finite number > 0"),
        (dict(weights=np.zeros(2)), "weights must be"),
        (dict(weights=np.array([1.0, -1.0])), "weights must be"),
        (dict(target_low=[1.0], target_high=[-1.0]), "target_low must be <= target_high"),
        (dict(delta=0.0), "delta must be"),
        (dict(source_q=None), "reference='source' needs source_q"),
        (dict(target_actions=np.zeros((2, 1))), "Assumption 1"),
    ],
)
def test_rejects_bad_settings(kwargs, match):
    base = dict(
        model=integrator_step,
        target_low=[-5.0],
        target_high=[5.0],
        source_q=GoalQ(),
        mapping=POSITION,
        source_step=goal_step,
        target_actions=SOURCE_ACTIONS,
    )
    with pytest.raises(ValueError, match=match):
        HorizonTATLPolicy(**{**base, **kwargs})


def test_rejects_mismatched_states():
    policy = _goal_policy(integrator_step, weights=np.ones(3))
    with pytest.raises(ValueError, match="weights has 3 entries"):
        policy(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="NaN"):
        _goal_policy(integrator_step)(np.array([[np.nan, 0.0]]))


def test_linearised_recovers_a_linear_model_and_cancels_fixed_seed_noise():
    from tatl_mj.transfer.methods.linearisation import linearised

    A = np.array([[1.0, 0.1], [-0.2, 0.95]])
    B = np.array([[0.0], [0.3]])

    def noisy_step(states, actions):  # noise drawn afresh from the same seed on every call
        noise = np.random.default_rng(0).normal(size=states.shape) * 1e-3
        return states @ A.T + actions @ B.T + noise

    model = linearised(noisy_step, 2, 1)
    s = np.array([[0.3, -0.1], [1.0, 2.0]])
    a = np.array([[0.5], [-1.0]])
    offset = np.random.default_rng(0).normal(size=(1, 2)) * 1e-3  # the first row's draw, constant
    np.testing.assert_allclose(model(s, a), s @ A.T + a @ B.T + offset, atol=1e-9)


def test_source_zero_starts_the_source_rollout_at_zero_on_those_coordinates():
    """source_zero = (0,) on the goal fixture: the rollout starts at x_0 = 0 whatever the
    target's position: u = +1, +1, 0 from 0 (0, 0.7, 1.05, 1.025), the same for both rows,
    and the references equal the plain policy's asked from a target state at position 0."""
    policy = _goal_policy(integrator_step, horizon=6, step_ratio=2.0, source_zero=(0,))
    states = np.array([[-3.0, 0.5], [2.0, -1.0]])
    got = policy.step(states)
    x = [0.0, 0.5 + DT_S, 0.35 + 0.5 + DT_S, 0.525 + 0.5]
    np.testing.assert_allclose(got.source_states[:, :, 0], [x, x], rtol=1e-14)
    plain = _goal_policy(integrator_step, horizon=6, step_ratio=2.0).step(np.array([[0.0, 0.5], [0.0, -1.0]]))
    np.testing.assert_allclose(got.references, plain.references, rtol=1e-14)
    # The target state itself still drives the free response: the actions differ from plain's.
    assert not np.allclose(got.action, plain.action)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(source_zero=(-1,)), "source_zero must be"),
        (dict(source_zero=(0,), reference="zero"), "source_zero must be"),
    ],
)
def test_source_zero_is_checked(kwargs, match):
    with pytest.raises(ValueError, match=match):
        _goal_policy(integrator_step, **kwargs)


def test_closed_form_responses_equal_the_model_rollouts():
    """An affine model given as (A, B, c): every intermediate of a decision equals the
    finite-difference path's (H model calls per decision) to rounding, for several
    horizons and ratios, with clipping in play, on the source and the zero reference."""
    rng = np.random.default_rng(11)
    a = np.array([[1.0, 0.12], [-0.3, 0.97]])
    b, c = np.array([[0.01], [0.2]]), np.array([0.05, -0.02])

    def model(s, u):
        return s @ a.T + u @ b.T + c

    states = rng.uniform(-2, 2, size=(25, 2))
    clipped = 0
    for horizon, ratio in [(1, 1.0), (7, 2.0), (20, 2.0), (9, 0.5)]:
        for reference in ("source", "zero"):
            kwargs = dict(horizon=horizon, step_ratio=ratio, weights=np.array([1.0, 0.1]), reference=reference)
            rolled = _goal_policy(model, **kwargs).step(states)
            closed = _goal_policy(model, affine=(a, b, c), **kwargs).step(states)
            for field in ("free", "control", "adaptive", "action"):
                np.testing.assert_allclose(
                    getattr(closed, field), getattr(rolled, field), rtol=1e-9, atol=1e-10, err_msg=field
                )
            clipped += int(np.sum(np.abs(closed.action) == 5.0))
    assert clipped > 0  # some actions hit the +-5 limit


def test_apprentice_affine_parts_predict_exactly():
    apprentice = _integrator_apprentice()
    a, b, c = apprentice.affine()
    s, u = np.random.default_rng(2).normal(size=(10, 2)), np.random.default_rng(3).normal(size=(10, 1))
    np.testing.assert_allclose(s @ a.T + u @ b.T + c, apprentice.predict(s, u), rtol=1e-12, atol=1e-12)
    periodic = fit_apprentice(s, u, integrator_step(s, u), LinearFeatures(), periodic=(True, False))
    assert periodic.affine() is None  # an angle wraps: no closed form
    with pytest.raises(ValueError, match="affine must be finite"):
        _goal_policy(integrator_step, affine=(a, b[:1], c))


@pytest.mark.parametrize("affine", [False, True])
@pytest.mark.parametrize("reference", ["source", "zero"])
def test_shared_decisions_decide_as_each_policy_alone(reference, affine):
    """Policies differing only in their apprentice decide together (one source rollout,
    one correction): each gets, bit for bit, the actions it computes alone; policies with
    another horizon are not grouped. The evaluation reaches it through the method
    contract's hook (``method.joint_decisions``), which gives the same decisions."""
    from tatl_mj.transfer.method import joint_decisions
    from tatl_mj.transfer.methods.horizon_policy import shared_decisions

    common = dict(source_q=OneStepLQRQ(), mapping=CHI, source_step=source_step, target_actions=2.0 * SOURCE_ACTIONS)
    if reference == "zero":
        common = dict(reference="zero")
    apprentices = [_noisy_apprentice(seed) for seed in range(3)]
    policies = [
        HorizonTATLPolicy(
            a.predict,
            [-1.0],
            [1.0],
            horizon=4,
            affine=a.affine() if affine else None,
            admissible=[[-1.0], [0.0], [1.0]] if seed == 0 else None,
            **common,
        )
        for seed, a in enumerate(apprentices)
    ]
    assert shared_decisions(policies) is None  # one snaps to a discrete set, the others do not
    policies = [dataclasses.replace(p, admissible=None) for p in policies]
    decide = shared_decisions(policies)
    assert decide is not None
    rng = np.random.default_rng(3)
    states = [CHI.chi(rng.uniform(-2, 2, size=(n, 2))) for n in (40, 1, 7)]
    got = decide([0, 2, 1], states)
    clipped = 0
    for b, s, actions in zip([0, 2, 1], states, got):
        np.testing.assert_array_equal(actions, policies[b](s))
        clipped += int(np.sum(np.abs(actions) == 1.0))
    assert clipped > 0  # the limits are in play
    through_the_contract = joint_decisions(policies)
    assert through_the_contract is not None
    for mine, theirs in zip(got, through_the_contract([0, 2, 1], states)):
        np.testing.assert_array_equal(mine, theirs)
    other = dataclasses.replace(policies[0], horizon=5)
    assert shared_decisions([policies[0], other]) is None
    assert shared_decisions(policies[:1]) is None
    assert joint_decisions([policies[0], other]) is None
    assert joint_decisions([lambda s: s, policies[0]]) is None  # the first policy has no hook
    assert joint_decisions([]) is None
