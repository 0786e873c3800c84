"""Mapping coordinates (transfer.coordinates): known answers and round trips."""

import numpy as np
import pytest

from tatl_mj.transfer.coordinates import Coordinates, InCoordinates, align_in_coordinates
from tatl_mj.transfer.intertask_mapping import AffineMapping, IdentityMapping, Mapping
from tatl_mj.transfer.transition_alignment import TransitionAlignment
from tatl_mj.transitions import Transitions

PI = np.pi
HANGING = Coordinates((True, False), (PI, 0.0))  # the pendulum's angle measured from hanging
# The energy-consistent map (car -> pendulum, in the pendulum's phi = wrap(theta - pi)):
# x = -pi/6 + phi/3 and v = 0.0094 theta_dot, i.e. phi = 3 x + pi/2, theta_dot = v / 0.0094.
ENERGY = AffineMapping(np.diag([3.0, 1.0 / 0.0094]), np.array([PI / 2.0, 0.0]))


def test_to_mapping_recentres_at_the_origin_and_wraps():
    states = np.array([[PI - 0.1, 1.0], [-PI + 0.1, -2.0], [0.0, 3.0], [-PI, 0.5]])
    np.testing.assert_allclose(
        HANGING.to_mapping(states), [[-0.1, 1.0], [0.1, -2.0], [-PI, 3.0], [0.0, 0.5]], atol=1e-12
    )
    np.testing.assert_allclose(
        HANGING.from_mapping([[-0.1, 1.0], [0.1, -2.0], [4.0, 0.0]]),
        [[PI - 0.1, 1.0], [-PI + 0.1, -2.0], [4.0 - PI, 0.0]],
        atol=1e-12,
    )
    np.testing.assert_array_equal(Coordinates.plain(2).to_mapping([[7.0, -9.0]]), [[7.0, -9.0]])


def test_round_trips_on_the_wrapped_range():
    rng = np.random.default_rng(0)
    s = np.column_stack([rng.uniform(-PI, PI, 500), rng.normal(0.0, 5.0, 500)])
    np.testing.assert_allclose(HANGING.from_mapping(HANGING.to_mapping(s)), s, atol=1e-12)
    np.testing.assert_allclose(HANGING.to_mapping(HANGING.from_mapping(s)), s, atol=1e-12)
    # Outside [-pi, pi) the round trip lands on the same angle, wrapped.
    far = s + [[6.0 * PI, 0.0]]
    np.testing.assert_allclose(HANGING.from_mapping(HANGING.to_mapping(far)), s, atol=1e-9)


def test_in_coordinates_maps_the_car_valley_to_hanging_and_round_trips():
    mapping = InCoordinates(ENERGY, Coordinates.plain(2), HANGING)
    assert isinstance(mapping, Mapping)
    car = np.array([[-PI / 6.0, 0.0], [-PI / 6.0 + 0.1, 0.0094], [-PI / 6.0 + PI / 3.0, 0.0]])
    # Valley bottom -> hanging at rest; 0.1 m right -> 0.3 rad past hanging; pi/3 -> upright.
    np.testing.assert_allclose(mapping.chi(car), [[-PI, 0.0], [-PI + 0.3, 1.0], [0.0, 0.0]], atol=1e-12)
    images = mapping.chi(np.column_stack([np.linspace(-1.2, 0.6, 200), np.linspace(-0.07, 0.07, 200)]))
    assert np.all((images[:, 0] >= -PI) & (images[:, 0] < PI))
    # Pendulum states either side of hanging land either side of the valley, not 2 pi apart.
    back = mapping.chi_plus([[PI - 0.15, 0.0], [-PI + 0.15, 0.0]])
    np.testing.assert_allclose(back[:, 0], [-PI / 6.0 - 0.05, -PI / 6.0 + 0.05], atol=1e-12)
    rng = np.random.default_rng(1)
    pendulum = np.column_stack([rng.uniform(-PI, PI, 300), rng.normal(0.0, 3.0, 300)])
    np.testing.assert_allclose(mapping.chi(mapping.chi_plus(pendulum)), pendulum, atol=1e-9)


def test_both_sides_periodic_round_trip():
    source = Coordinates((True, False), (0.5, 0.0))
    mapping = InCoordinates(IdentityMapping(), source, HANGING)
    np.testing.assert_allclose(mapping.chi([[0.5, 2.0]]), [[-PI, 2.0]], atol=1e-12)
    np.testing.assert_allclose(
        mapping.chi_plus(mapping.chi([[1.0, 2.0], [-3.0, 1.0]])), [[1.0, 2.0], [-3.0, 1.0]], atol=1e-12
    )


def test_step_and_transitions_in_mapping_coordinates():
    def step(states, actions):  # one domain step: the angle advances by 0.2 rad, wrapped
        out = states.copy()
        out[:, 0] = np.mod(out[:, 0] + 0.2 + PI, 2 * PI) - PI
        return out

    phi = HANGING.step(step)(np.array([[-0.1, 0.0], [PI - 0.1, 0.0]]), np.zeros(2, int))
    np.testing.assert_allclose(phi, [[0.1, 0.0], [-PI + 0.1, 0.0]], atol=1e-12)
    t = Transitions([[PI - 0.1, 1.0]], [0], [0.0], [[-PI + 0.1, 1.0]], [False], [False])
    moved = HANGING.transitions(t)
    np.testing.assert_allclose(moved.states, [[-0.1, 1.0]], atol=1e-12)
    np.testing.assert_allclose(moved.next_states, [[0.1, 1.0]], atol=1e-12)


def test_bad_coordinates_name_the_field():
    with pytest.raises(ValueError, match="Coordinates.origin must hold one number per state coordinate"):
        Coordinates((True, False), (PI,))
    with pytest.raises(ValueError, match="Coordinates.periodic must be one bool"):
        Coordinates((1, 0), (0.0, 0.0))
    with pytest.raises(ValueError, match="Coordinates.origin must be 0 on non-periodic"):
        Coordinates((True, False), (PI, 1.0))
    with pytest.raises(ValueError, match="Coordinates.origin must be finite"):
        Coordinates((True,), (np.nan,))
    with pytest.raises(ValueError, match="states must have 2 columns"):
        HANGING.to_mapping(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="InCoordinates.inner must be a Mapping"):
        InCoordinates(np.eye(2), HANGING, HANGING)
    with pytest.raises(ValueError, match="InCoordinates.target must be Coordinates"):
        InCoordinates(IdentityMapping(), HANGING, (True, False))


def test_align_in_coordinates_recovers_a_map_across_the_hanging_cut():
    """A linear oscillator (source) and the same system as a pendulum angle stored
    from upright (target, cut at hanging, where the data live): aligned in phi
    coordinates, the triplet alignment recovers the true map (measured largest
    error 2e-15); the record carries the coefficients and both coordinate systems."""
    rng = np.random.default_rng(7)
    dt, n = 0.05, 800
    a_s = np.eye(2) + dt * np.array([[0.0, 1.0], [-4.0, -0.2]])
    b_s = dt * np.array([[0.0], [1.0]])
    actions = np.array([[-1.0], [0.0], [1.0]])
    m, offset = np.array([[2.0, 0.3], [0.0, -0.5]]), np.array([0.2, 0.0])

    def batch(states, idx, to_stored):
        nxt = states @ a_s.T + actions[idx] @ b_s.T
        return Transitions(to_stored(states), idx, np.zeros(n), to_stored(nxt), np.zeros(n, bool), np.ones(n, bool))

    def pendulum(s):
        return HANGING.from_mapping(s @ m.T + offset)

    source = batch(rng.normal(size=(n, 2)) * [0.3, 1.5], rng.integers(3, size=n), lambda s: s)
    target = batch(rng.normal(size=(n, 2)) * [0.3, 1.5], rng.integers(3, size=n), pendulum)
    assert np.mean(np.abs(target.next_states[:, 0] - target.states[:, 0]) > PI) > 0.05
    mapping, record = align_in_coordinates(
        source,
        target,
        Coordinates.plain(2),
        HANGING,
        3,
        3,
        settings=TransitionAlignment(sign_flips=False),
    )
    x = rng.normal(size=(200, 2)) * [0.3, 1.5]
    np.testing.assert_allclose(mapping.chi(x), pendulum(x), atol=1e-9)
    np.testing.assert_allclose(record["matrix"], m, atol=1e-9)
    np.testing.assert_allclose(record["offset"], offset, atol=1e-9)
    assert record["target_coordinates"] == {"periodic": (True, False), "origin": (PI, 0.0)}
    with pytest.raises(ValueError, match="target_coordinates cover 1 coordinates but target states have 2"):
        align_in_coordinates(source, target, Coordinates.plain(2), Coordinates((True,), (PI,)), 3, 3)
