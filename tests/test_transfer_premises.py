"""Known answers for the theorem's premises, measured (tatl_mj.transfer.premises).

A synthetic linear target s' = A s + B a, run under Algorithm 1's own policy
(tatl_mj.transfer.algorithm1) with an exact apprentice and the identity map:
delta = 0, alpha = 1, tracking = 0 and nothing clipped; B_hat = B / 2 gives
alpha = 2; a clip shows up in feasibility and tracking. Then each measure on
inputs whose answer is known by hand. The MuJoCo side (B(s) of a real task
against mujoco.mjd_transitionFD) is in tests/test_premises_replay.py.
"""

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from tatl_mj.transfer import premises
from tatl_mj.transfer.algorithm1 import TATLPolicy
from tatl_mj.transfer.apprentice import Apprentice
from tatl_mj.transfer.features import LinearFeatures
from tatl_mj.transfer.intertask_mapping import AffineMapping, IdentityMapping

DT = 0.1
A = np.array([[1.0, DT], [-0.3 * DT, 1.0]])
B = np.array([[0.5 * DT**2], [DT]])
ACTIONS = np.array([[-1.0], [0.0], [1.0]])
SCALE = np.array([0.05, 0.1])  # a stand-in for the stream's step std


class OneStepQ:
    """Q_S(x, a) = -|A x + B a|^2: a known greedy source policy."""

    n_actions = 3

    def __init__(self, b):
        self.b = b

    def values(self, x):
        nxt = (x @ A.T)[:, None, :] + ACTIONS[None, :, :] @ self.b.T
        return -np.sum(nxt**2, axis=2)

    def greedy(self, x):
        return np.argmax(self.values(x), axis=1)


def linear_step(b):
    def step(x, a):
        return x @ A.T + np.atleast_2d(a) @ b.T

    return step


def _policy(target_b, source_b=B, low=-50.0, high=50.0, adaptive_actions=None):
    """Algorithm 1 with source = A x + source_b a_S and an exact apprentice of A s + target_b a."""
    source = linear_step(source_b)
    return TATLPolicy(
        OneStepQ(source_b),
        IdentityMapping(),
        lambda x, idx: source(x, ACTIONS[idx]),
        Apprentice(W=A, B=target_b, features=LinearFeatures(bias=False)),
        ACTIONS,
        ACTIONS,
        [low],
        [high],
        adaptive_actions=adaptive_actions,
    )


def _episodes(policy, target_b, steps=20):
    """Runs 16 episodes of ``policy`` on s' = A s + target_b a; every decision's quantities."""
    target = linear_step(target_b)
    s = np.random.default_rng(0).uniform(-2.0, 2.0, size=(16, 2))
    rows = {k: [] for k in ("states", "requested", "applied", "projected", "next")}
    for _ in range(steps):
        decision = policy.step(s)
        s_next = target(s, decision.action)
        requested = decision.a_T + decision.adaptive  # before the clip
        for key, value in zip(rows, (s, requested, decision.action, decision.s_hat_T_next, s_next)):
            rows[key].append(value)
        s = s_next
    return {k: np.concatenate(v) for k, v in rows.items()}


def _B_of(target_b, states, actions):
    """Finite-difference B(s) of s' = A s + target_b a at each visited state and its action."""
    step = linear_step(target_b)
    return np.stack(
        [premises.finite_difference_B(lambda a, s=s: step(s[None], a)[0], u) for s, u in zip(states, actions)]
    )


@pytest.mark.parametrize("gain", [1.0, 2.0], ids=["source=target", "target-gain-2"])
def test_algorithm1_on_its_own_linear_target_meets_every_premise(gain):
    """Source = target (and a target of twice the gain, where the adaptive term does the work),
    identity map, exact apprentice, unclipped: delta = 0, alpha = 1, tracking = 0, nothing clipped."""
    target_b = gain * B
    policy = _policy(target_b)
    run = _episodes(policy, target_b)
    delta = premises.one_step_errors(policy.apprentice, run["states"], run["applied"], run["next"], SCALE, None)
    assert delta.rms < 1e-12 and delta.worst < 1e-12 and delta.n == len(run["states"])
    track = premises.tracking(run["next"], run["projected"], SCALE, None)
    assert track.rms < 1e-12
    feasible = premises.feasibility(run["requested"], run["applied"], [-50.0], [50.0])
    assert (feasible.clipped, feasible.snapped, feasible.infeasible) == (0.0, 0.0, 0.0)
    Bs = _B_of(target_b, run["states"][::40], run["applied"][::40])
    np.testing.assert_allclose(Bs, np.broadcast_to(target_b, Bs.shape), rtol=1e-9)
    found = premises.alpha(policy.apprentice.B, Bs)
    np.testing.assert_allclose(found.value, 1.0, rtol=1e-9)
    assert found.max_error < 1e-9
    assert premises.b_spread(Bs, SCALE) < 1e-9
    trip = premises.round_trip(policy.mapping, run["states"], SCALE, None)
    assert trip.rms == 0.0
    if gain != 1.0:  # the adaptive term is what makes it track: the mapped action alone does not
        assert np.abs(run["requested"] - policy.step(run["states"]).a_T).max() > 0.1
    measured = premises.PremiseMeasurements(
        delta=delta.rms, alpha=found.mean_error, b_spread=0.0, infeasible=0.0, tracking=track.rms, round_trip=0.0
    )
    assert premises.failed(measured) == ()


def test_half_the_control_gain_in_the_apprentice_gives_alpha_two():
    """B_hat = B / 2: alpha = pinv(B_hat) B = 2 at every state; as a matrix for two actions."""
    found = premises.alpha(B / 2.0, np.stack([B, B, B]))
    np.testing.assert_allclose(found.value[:, 0, 0], 2.0)
    np.testing.assert_allclose(found.error, 1.0)
    assert premises.failed(premises.PremiseMeasurements(alpha=found.mean_error)) == ("alpha",)
    two = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])
    mix = np.array([[2.0, 1.0], [0.0, 0.5]])
    np.testing.assert_allclose(premises.alpha(two @ mix, two).value[0], np.linalg.inv(mix), atol=1e-12)


def test_clipped_policy_is_infeasible_and_misses_the_projected_state():
    """Target of half the source's gain and an actuator of +-0.6: requests beyond it are clipped,
    feasibility counts them and tracking is no longer 0; snapping to a coarse admissible set
    counts as snapped, by as much as it moved the request."""
    target_b = 0.5 * B
    run = _episodes(_policy(target_b, low=-0.6, high=0.6), target_b)
    feasible = premises.feasibility(run["requested"], run["applied"], [-0.6], [0.6])
    assert feasible.clipped > 0.2 and feasible.snapped == 0.0
    assert feasible.max_excess > 0.1
    assert premises.tracking(run["next"], run["projected"], SCALE, None).rms > 1e-3
    # Twice the gain: requests of +-0.5 and 0, within the limits, each snapped to a coarse set.
    coarse = np.array([[-0.6], [-0.1], [0.3], [0.6]])
    run = _episodes(_policy(2.0 * B, low=-0.6, high=0.6, adaptive_actions=coarse), 2.0 * B)
    snapped = premises.feasibility(run["requested"], run["applied"], [-0.6], [0.6])
    assert (snapped.clipped, snapped.snapped) == (0.0, 1.0)
    assert snapped.max_excess == pytest.approx(0.1 / 1.2)


def test_feasibility_counts_a_clip_and_a_snap_by_how_much():
    """Actuator +-4 (range 8): 5 -> 4 is clipped (excess 1/8), 1.3 -> 0 snapped (1.3/8),
    0.2 -> 0 snapped within the tolerance (0.2/8 < 0.1), -2 applied as asked."""
    requested = np.array([[5.0], [1.3], [0.2], [-2.0]])
    applied = np.array([[4.0], [0.0], [0.0], [-2.0]])
    found = premises.feasibility(requested, applied, [-4.0], [4.0])
    assert found.clipped == 0.25 and found.snapped == 0.5 and found.infeasible == 0.5
    assert found.max_excess == pytest.approx(1.3 / 8) and found.mean_excess == pytest.approx((1 + 1.3 + 0.2) / 32)
    assert found.n == 4 and found.tolerance == premises.FEASIBILITY_TOLERANCE
    with pytest.raises(ValueError, match="low < high"):
        premises.feasibility(requested, applied, [4.0], [-4.0])


def test_control_affinity_of_an_affine_and_a_quadratic_step():
    """s' = s + M a is affine (unexplained 0, slope M); s' = s + a^2 over symmetric limits
    is not at all (a line through a parabola's symmetric samples explains none of it)."""
    s = np.array([0.3, -1.0])
    m = np.array([[0.2], [-1.5]])
    affine = premises.control_affinity(lambda a: s + m @ a, [-2.0], [2.0], scale=SCALE)
    assert affine.unexplained < 1e-20
    np.testing.assert_allclose(affine.b, m, rtol=1e-12)
    quadratic = premises.control_affinity(lambda a: s + a[0] ** 2, [-1.0], [1.0])
    assert quadratic.unexplained == pytest.approx(1.0)
    assert premises.failed(premises.PremiseMeasurements(unexplained=quadratic.unexplained)) == ("unexplained",)
    still = premises.control_affinity(lambda a: s.copy(), [-1.0], [1.0])
    assert still.unexplained == 0.0 and np.isnan(still.per_coordinate).all()
    assert premises.spanning_actions([-1.0, 0.0], [1.0, 4.0], 5).shape == (9, 2)


def test_control_affinity_wraps_angles():
    """A next angle crossing +-pi as the action varies is one line, not a jump of 2 pi."""
    step = lambda a: np.array([(math.pi - 0.01 + 0.1 * a[0] + math.pi) % (2 * math.pi) - math.pi])  # noqa: E731
    assert premises.control_affinity(step, [-1.0], [1.0], periodic=[True]).unexplained < 1e-20
    assert premises.control_affinity(step, [-1.0], [1.0]).unexplained > 0.1
    B_fd = premises.finite_difference_B(step, [0.1], eps=1e-3, periodic=[True])
    np.testing.assert_allclose(B_fd, [[0.1]], rtol=1e-9)


def test_finite_differences_stay_inside_the_actuator():
    """At the limit the centre moves in by eps, so neither side crosses the clip."""
    step = lambda a: np.array([np.clip(a[0], -1.0, 1.0) * 3.0])  # noqa: E731
    np.testing.assert_allclose(premises.finite_difference_B(step, [1.0], 1e-3, low=[-1.0], high=[1.0]), [[3.0]])
    np.testing.assert_allclose(premises.finite_difference_B(step, [1.0], 1e-3), [[1.5]])


def test_b_spread_is_the_relative_spread_of_B():
    Bs = np.stack([B * 0.8, B * 1.2])
    assert premises.b_spread(Bs) == pytest.approx(0.2)
    assert premises.b_spread(np.stack([B, B])) == 0.0
    assert premises.b_spread(np.stack([B, -B])) == math.inf


def test_round_trip_of_an_invertible_map_and_a_projection():
    """Identity and an invertible affine map return every state; a 1-D source seen in a 2-D
    target (chi = [1, 1] x) loses the direction across the line: residual |s1 - s2| / 2 each way."""
    states = np.random.default_rng(1).normal(size=(50, 2))
    assert premises.round_trip(IdentityMapping(), states, SCALE, None).rms == 0.0
    invertible = AffineMapping(np.array([[2.0, 1.0], [0.0, -1.0]]), np.array([0.5, 1.0]))
    assert premises.round_trip(invertible, states, SCALE, None).rms < 1e-12
    projection = premises.round_trip(AffineMapping(np.array([[1.0], [1.0]]), np.zeros(2)), states, [1.0, 1.0], None)
    expected = np.abs(states[:, 0] - states[:, 1]) / 2.0
    assert projection.rms == pytest.approx(np.sqrt(np.mean(expected**2)))
    assert premises.failed(premises.PremiseMeasurements(round_trip=projection.rms)) == ("round_trip",)


def test_errors_are_in_step_stds_and_wrapped():
    """The stream's step std wraps angles: a hanging pendulum crossing +-pi steps by 0.02, not
    2 pi; an error is in those units, the shorter way round."""
    states = np.array([[math.pi - 0.01, 0.0], [-math.pi + 0.01, 1.0], [math.pi - 0.05, 3.0]])
    next_states = np.array([[-math.pi + 0.01, 1.0], [-math.pi + 0.03, 3.0], [math.pi - 0.01, 4.0]])
    scale = premises.step_scale(states, next_states, [True, False])
    np.testing.assert_allclose(scale, [np.std([0.02, 0.02, 0.04]), np.std([1.0, 2.0, 1.0])])
    errors = premises.normalised_errors([[math.pi - 0.01, 0.0]], [[-math.pi + 0.01, 0.0]], [0.02, 1.0], [True, False])
    np.testing.assert_allclose(errors.per_coordinate, [1.0, 0.0])
    assert errors.rms == pytest.approx(math.sqrt(0.5))
    with pytest.raises(ValueError, match="no spread"):
        premises.step_scale(states, states, None)


def test_misprediction_rate_on_cells():
    """A grid apprentice that moves every cell right by 1: wrong wherever the real move was not."""
    apprentice = Apprentice(W=np.eye(2), B=np.eye(2), features=LinearFeatures(bias=False))
    states = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    moves = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 0.0]])
    real = states + np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [1.0, 0.0]])  # the second hit a wall
    assert premises.misprediction_rate(apprentice, states, moves, real, None) == 0.25
    snapped = premises.misprediction_rate(apprentice, states, moves + 0.3, real, np.rint)
    assert snapped == 0.25


def test_failed_judges_what_was_measured():
    """None is not judged, NaN fails, a threshold is a bound (at it passes); thresholds must be positive."""
    t = premises.THRESHOLDS
    at = premises.PremiseMeasurements(**{f.name: getattr(t, f.name) for f in dataclasses.fields(t)})
    assert premises.failed(at) == ()
    assert premises.failed(premises.PremiseMeasurements()) == ()
    worst = premises.PremiseMeasurements(delta=math.nan, delta_stream=99.0, tracking=1.5, infeasible=0.2)
    assert premises.failed(worst) == ("delta", "tracking")
    with pytest.raises(ValueError, match="alpha"):
        premises.PremiseThresholds(alpha=0.0)
    with pytest.raises(ValueError, match="PremiseMeasurements"):
        premises.failed({"delta": 1.0})


def test_the_protocol_declares_the_thresholds_the_code_applies():
    """docs/protocol.md's table of premises names every threshold of PremiseThresholds, at its value."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "protocol.md").read_text()
    section = text.split("## The theorem's premises, measured", 1)[1].split("\n## ", 1)[0]
    declared = {
        name: float(value) for name, value in re.findall(r"^\| `(\w+)`[^|]*\|[^|]*\| ([\d.]+) \|", section, re.M)
    }
    expected = {f.name: getattr(premises.THRESHOLDS, f.name) for f in dataclasses.fields(premises.PremiseThresholds)}
    assert declared == expected


def test_a_diverged_prediction_or_step_is_measured_as_nan_and_fails():
    """NaN (an apprentice or a step that diverged) is carried, not refused, and fails its premise;
    in the rates it counts against: a missed cell, an infeasible decision."""
    errors = premises.normalised_errors([[math.nan, 0.0]], [[0.0, 0.0]], [1.0, 1.0], None)
    assert math.isnan(errors.rms) and math.isnan(errors.worst)
    assert premises.failed(premises.PremiseMeasurements(delta=errors.rms)) == ("delta",)
    fit = premises.control_affinity(lambda a: np.array([math.nan, a[0]]), [-1.0], [1.0])
    assert math.isnan(fit.unexplained)
    found = premises.feasibility([[math.nan], [0.0]], [[0.0], [0.0]], [-1.0], [1.0])
    assert found.infeasible == 0.5
    wild = Apprentice(W=np.eye(1), B=np.eye(1), features=LinearFeatures(bias=False))
    cells = np.array([[1.0], [2.0]])
    assert premises.misprediction_rate(wild, cells, [[0.0], [0.0]], cells, lambda p: p * [[1.0], [math.nan]]) == 0.5
