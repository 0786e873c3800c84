"""Known answers for the bases phi(s) of tatl_mj.transfer.features."""

import warnings

import numpy as np
import pytest

from tatl_mj.transfer.features import RBF, LinearFeatures, OneHot, make_features


def test_rbf_values_at_centre_and_one_bandwidth_away():
    rbf = RBF(centers=np.array([[0.0, 0.0], [1.0, -1.0]]), sigma=[0.5, 2.0], bias=True)
    phi = rbf(np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 2.0]]))
    assert phi.shape == (3, 3) and rbf.size(2) == 3
    np.testing.assert_allclose(phi[:, 0], 1.0)  # the bias
    # exp(-|L^-1 (s - c)|^2 / 2): 1 at the centre, exp(-1/2) one bandwidth away along an axis.
    np.testing.assert_allclose(phi[0, 1], 1.0)
    np.testing.assert_allclose(phi[1, 1], np.exp(-0.5))
    np.testing.assert_allclose(phi[2, 1], np.exp(-0.5))
    np.testing.assert_allclose(phi[0, 2], np.exp(-0.5 * (4.0 + 0.25)))


def test_rbf_full_bandwidth_matrix_equals_diagonal_vector():
    centers = np.random.default_rng(0).normal(size=(7, 2))
    states = np.random.default_rng(1).normal(size=(50, 2))
    np.testing.assert_allclose(RBF(centers, 1.2 * np.eye(2))(states), RBF(centers, [1.2, 1.2])(states))


def test_rbf_grid_20_centres_span_the_box():
    rbf = RBF.grid([-1.2, -0.07], [0.6, 0.07], 20, [0.3, 0.1], bias=False)
    assert rbf.centers.shape == (20, 2)
    # 1.8 / 0.3 = 6 widths along x against 0.14 / 0.1 = 1.4 along v: 5 centres along x, 4 along v.
    assert len(np.unique(rbf.centers[:, 0])) == 5 and len(np.unique(rbf.centers[:, 1])) == 4
    np.testing.assert_allclose(rbf.centers.min(axis=0), [-1.2, -0.07])
    np.testing.assert_allclose(rbf.centers.max(axis=0), [0.6, 0.07])
    assert RBF.grid([0, 0], [1, 1], [3, 2], 1.0).centers.shape == (6, 2)


def test_linear_and_onehot():
    s = np.array([[2.0, -3.0]])
    np.testing.assert_array_equal(LinearFeatures()(s), [[1.0, 2.0, -3.0]])
    np.testing.assert_array_equal(LinearFeatures(bias=False)(s), s)
    onehot = OneHot(3, 4)
    phi = onehot(np.array([[0, 0], [2, 3], [1, 2]]))
    assert phi.shape == (3, 12) and onehot.size(2) == 12
    np.testing.assert_array_equal(np.argmax(phi, axis=1), [0, 11, 6])
    np.testing.assert_array_equal(phi.sum(axis=1), 1.0)
    with pytest.raises(ValueError, match="grid"):
        onehot(np.array([[3, 0]]))
    with pytest.raises(ValueError, match="integer"):
        onehot(np.array([[0.5, 0]]))


def test_make_features_builds_each_kind_and_names_bad_input():
    rbf = make_features({"kind": "rbf", "centers": 20, "low": [-np.pi, -8], "high": [np.pi, 8], "sigma": [1.2, 1.2]}, 2)
    assert isinstance(rbf, RBF) and rbf.size(2) == 21
    assert isinstance(make_features({"kind": "linear"}, 4), LinearFeatures)
    assert make_features({"kind": "onehot", "n_rows": 6, "n_cols": 9}, 2).size(2) == 54
    with pytest.raises(ValueError, match="valid kinds"):
        make_features({"kind": "fourier"}, 2)
    with pytest.raises(ValueError, match="unknown keys \\['width'\\]"):
        make_features({"kind": "linear", "width": 3}, 2)
    with pytest.raises(ValueError, match="low"):
        make_features({"kind": "rbf", "centers": 20, "sigma": 1.0}, 2)


def test_bad_bandwidth_and_nan_states_raise():
    with pytest.raises(ValueError, match="sigma"):
        RBF(np.zeros((2, 2)), [1.0, 0.0])
    with pytest.raises(ValueError, match="sigma"):
        RBF(np.zeros((2, 2)), np.ones((2, 2)))  # singular bandwidth matrix
    with pytest.raises(ValueError, match="NaN"):
        LinearFeatures()(np.array([[np.nan, 0.0]]))
    with pytest.raises(ValueError, match="columns"):
        RBF(np.zeros((2, 2)), 1.0)(np.zeros((1, 3)))


@pytest.mark.parametrize(
    "sigma, message",
    [
        ([0.6, 0.0], r"RBF.sigma must be finite and > 0, got \[0.6 0. \]"),
        (0.0, r"RBF.sigma must be finite and > 0"),
        ([-0.5, 1.0], r"RBF.sigma must be finite and > 0"),
        ([[1.0, 1.0], [0.0, 0.0]], r"RBF.sigma must be a finite invertible matrix"),
        ([1.0, 2.0, 3.0], r"RBF.sigma must have shape \(2,\) or \(2, 2\), got \(3,\)"),
    ],
    ids=["zero-width", "zero-scalar", "negative", "zero-row", "wrong-size"],
)
def test_grid_with_a_centre_count_names_a_bad_bandwidth_without_dividing_by_zero(sigma, message):
    # The centre count is split by the box's width in bandwidths; a zero bandwidth used to divide by
    # zero there (a RuntimeWarning) before the basis refused it.
    spec = {"kind": "rbf", "centers": 20, "low": [0.0, 0.0], "high": [1.0, 1.0], "sigma": sigma}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=message):
            make_features(spec, 2)


def test_grid_splits_the_count_by_widths_of_a_full_bandwidth_matrix():
    # An invertible L with a zero diagonal entry: the widths are the rows' lengths (1 and 3 here),
    # so the wider dimension relative to them, x, gets more centres; no division by zero.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rbf = RBF.grid([0.0, 0.0], [6.0, 6.0], 20, [[0.0, 1.0], [3.0, 0.0]], bias=False)
    assert len(np.unique(rbf.centers[:, 0])) == 5 and len(np.unique(rbf.centers[:, 1])) == 4


# --- Periodic (angle) coordinates -------------------------------------------------------


def test_periodic_rbf_measures_the_wrapped_distance_across_pi():
    """A centre at theta = pi - 0.1 and a state at -pi + 0.2 are 0.3 apart on the circle:
    phi = exp(-0.3^2 / (2 sigma^2)) exactly; the plain RBF sees them 2 pi - 0.3 apart."""
    centers, sigma = np.array([[np.pi - 0.1, 0.0]]), [0.6, 1.5]
    periodic = RBF(centers, sigma, bias=False, periodic=(True, False))
    plain = RBF(centers, sigma, bias=False)
    s = np.array([[-np.pi + 0.2, 0.0]])
    np.testing.assert_allclose(periodic(s), [[np.exp(-0.5 * (0.3 / 0.6) ** 2)]], rtol=1e-12)
    np.testing.assert_allclose(plain(s), [[np.exp(-0.5 * ((2 * np.pi - 0.3) / 0.6) ** 2)]], rtol=1e-12)
    # The velocity coordinate is not wrapped: 8 rad/s stays 8 rad/s from the centre.
    np.testing.assert_allclose(periodic(np.array([[np.pi - 0.1, 8.0]])), [[np.exp(-0.5 * (8 / 1.5) ** 2)]])


def test_periodic_rbf_is_2pi_periodic_and_symmetric_about_the_wrap():
    rng = np.random.default_rng(3)
    rbf = RBF.grid([-np.pi, -8.0], [np.pi, 8.0], 100, [0.6, 1.5], periodic=[True, False])
    s = np.column_stack([rng.uniform(-np.pi, np.pi, 200), rng.uniform(-8, 8, 200)])
    for turns in (-2, 1, 3):
        np.testing.assert_allclose(rbf(s + [2 * np.pi * turns, 0.0]), rbf(s), atol=1e-12)
    # Hanging down: with a centre at the wrap (theta = -pi, the same point as +pi), the
    # points -pi + e and pi - e, symmetric about it, get the same feature; the plain RBF
    # sees them 2 pi - 2e apart (only the one at -pi + e is near its centre).
    e = np.array([1e-9, 0.01, 0.2, 1.0])
    left = np.column_stack([-np.pi + e, np.full(4, 2.0)])
    right = np.column_stack([np.pi - e, np.full(4, 2.0)])
    down = RBF(np.array([[-np.pi, 2.0]]), [0.6, 1.5], bias=False, periodic=(True, False))
    np.testing.assert_allclose(down(left), down(right), rtol=1e-12)
    np.testing.assert_allclose(down(left)[:, 0], np.exp(-0.5 * (e / 0.6) ** 2), rtol=1e-12)
    plain_down = RBF(np.array([[-np.pi, 2.0]]), [0.6, 1.5], bias=False)
    assert np.abs(plain_down(left) - plain_down(right)).max() > 0.5
    # The grid's theta centres are symmetric about 0 on the circle (-pi counts as +pi), so
    # mirrored states theta -> -theta have the same sorted feature values.
    np.testing.assert_allclose(np.sort(rbf(left), axis=1), np.sort(rbf(right), axis=1), atol=1e-12)
    # -pi + e and pi + e are one point.
    np.testing.assert_allclose(rbf(left), rbf(left + [2 * np.pi, 0.0]), atol=1e-12)
    # Continuity across the wrap: a jump of 2e-9 rad changes phi by < 1e-6 (the plain RBF jumps).
    across = np.array([[np.pi - 1e-9, 1.0], [-np.pi + 1e-9, 1.0]])
    assert np.abs(np.diff(rbf(across), axis=0)).max() < 1e-6
    plain = RBF.grid([-np.pi, -8.0], [np.pi, 8.0], 100, [0.6, 1.5])
    assert np.abs(np.diff(plain(across), axis=0)).max() > 0.1
    # A full bandwidth matrix gives the same features as the diagonal vector.
    full = RBF(rbf.centers, np.diag([0.6, 1.5]), periodic=(True, False))
    np.testing.assert_allclose(full(s), rbf(s), atol=1e-12)


def test_periodic_grid_puts_one_centre_per_angle_over_low_to_high_excluded():
    rbf = RBF.grid([-np.pi, -8.0], [np.pi, 8.0], [10, 5], [0.6, 1.5], periodic=[True, False])
    thetas = np.unique(rbf.centers[:, 0])
    np.testing.assert_allclose(thetas, -np.pi + 2 * np.pi * np.arange(10) / 10)  # -pi in, +pi out
    np.testing.assert_allclose(np.unique(rbf.centers[:, 1]), np.linspace(-8, 8, 5))  # ends in
    assert rbf.periodic == (True, False)
    # An all-False mask is the plain RBF.
    assert RBF.grid([0, 0], [1, 1], [2, 2], 1.0, periodic=[False, False]).periodic is None
    with pytest.raises(ValueError, match="span more than 2 pi"):
        RBF.grid([-4.0, 0.0], [4.0, 1.0], [4, 2], 1.0, periodic=[True, False])


def test_periodic_linear_features_use_sin_and_cos():
    s = np.array([[np.pi / 2, 3.0], [-np.pi, -1.0]])
    lin = LinearFeatures(periodic=[True, False])
    np.testing.assert_allclose(lin(s), [[1.0, 1.0, 0.0, 3.0], [1.0, 0.0, -1.0, -1.0]], atol=1e-15)
    assert lin.size(2) == 4 and LinearFeatures(bias=False, periodic=(False, True)).size(2) == 3
    np.testing.assert_allclose(lin(s + [2 * np.pi, 0.0]), lin(s), atol=1e-12)
    with pytest.raises(ValueError, match="periodic has 2 entries"):
        lin(np.zeros((1, 3)))


def test_make_features_accepts_periodic_and_names_bad_masks():
    spec = {
        "kind": "rbf",
        "centers": 100,
        "low": [-3.14159, -8],
        "high": [3.14159, 8],
        "sigma": [0.6, 1.5],
        "periodic": [True, False],
    }
    rbf = make_features(spec, 2)
    assert isinstance(rbf, RBF) and rbf.periodic == (True, False) and rbf.size(2) == 101
    assert not np.any(np.isclose(rbf.centers[:, 0], 3.14159))  # no duplicate of -pi at +pi
    explicit = make_features({"kind": "rbf", "centers": [[0.0, 0.0]], "sigma": 1.0, "periodic": [True, False]}, 2)
    assert explicit.periodic == (True, False)
    lin = make_features({"kind": "linear", "periodic": [True, False]}, 2)
    assert lin.size(2) == 4
    with pytest.raises(ValueError, match="one entry per state coordinate"):
        make_features({**spec, "periodic": [True]}, 2)
    with pytest.raises(ValueError, match="bools"):
        make_features({**spec, "periodic": [1, 0]}, 2)
    with pytest.raises(ValueError, match="RBF.periodic"):
        RBF(np.zeros((2, 3)), 1.0, periodic=(True, False))


def test_a_spec_with_a_zero_bandwidth_is_refused_without_a_warning():
    # What tests/test_spec_fuzz.py ran into: the spec loader builds the basis to validate it.
    import tomllib
    from pathlib import Path

    from tatl_mj.experiments import spec as spec_mod

    table = tomllib.loads((Path(__file__).resolve().parents[1] / "tasks" / "ip_to_flipped_ip.toml").read_text())
    table["source_learning"]["features"]["sigma"] = [0.6, 0.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(spec_mod.SpecError, match=r"source_learning.features': RBF.sigma must be finite and > 0"):
            spec_mod.parse_spec(table, "zero.toml")


@pytest.mark.parametrize("periodic", [(True,), (True, False), (False, True), (True, True)])
def test_periodic_rbf_coordinate_by_coordinate_equals_the_matrix_form_bit_for_bit(periodic):
    # With a diagonal bandwidth the distances are formed one coordinate at a time; they
    # must be the (N, k, d) matrix form's bits, or every pendulum record would move.
    rng = np.random.default_rng(3)
    d = len(periodic)
    # 700 centres: the 7,001 states are formed in three row blocks.
    rbf = RBF(rng.uniform(-4, 4, size=(700, d)), rng.uniform(0.1, 2.0, size=d), periodic=periodic)
    states = rng.uniform(-9, 9, size=(7001, d))
    fast = rbf(states)
    matrix_form = RBF(rbf.centers, np.diag(rbf.sigma), periodic=periodic)
    matrix_form.__dict__["_diagonal"] = None  # the general path
    assert rbf._diagonal is not None
    np.testing.assert_array_equal(fast, matrix_form(states))
    np.testing.assert_array_equal(fast[5:6], rbf(states[5:6]))  # row-exact: one state alone


@pytest.mark.parametrize("periodic", [(True,), (True, False), (False, True), (True, True)])
def test_periodic_rbf_on_a_grid_equals_the_matrix_form_bit_for_bit(periodic):
    # On a grid of centres each coordinate's term is formed once per distinct value and
    # spread by broadcasting; shuffled, the same centres take the per-centre path.
    rng = np.random.default_rng(5)
    d = len(periodic)
    counts = [9] if d == 1 else [7, 6]
    low, high = [-np.pi, -3.0][:d], [np.pi, 3.0][:d]
    rbf = RBF.grid(low, high, counts, rng.uniform(0.1, 2.0, size=d), periodic=list(periodic))
    assert rbf._grid_values is not None and [len(v) for v in rbf._grid_values] == counts
    states = rng.uniform(-9, 9, size=(3001, d))
    fast = rbf(states)
    matrix_form = RBF(rbf.centers, np.diag(rbf.sigma), periodic=periodic)
    matrix_form.__dict__["_diagonal"] = None
    np.testing.assert_array_equal(fast, matrix_form(states))
    order = rng.permutation(len(rbf.centers))
    shuffled = RBF(rbf.centers[order], np.diag(rbf.sigma).copy(), periodic=periodic)
    assert shuffled._grid_values is None
    np.testing.assert_array_equal(fast[:, 1:][:, order], shuffled(states)[:, 1:])
    np.testing.assert_array_equal(fast[7:8], rbf(states[7:8]))


@pytest.mark.parametrize("n", [1, 7, 300, 20_000])
@pytest.mark.parametrize("bias", [True, False])
def test_rbf_matrix_form_in_place_equals_the_expression_bit_for_bit(n, bias):
    # The plain (non-periodic) basis forms |s|^2 - 2 s.c + |c|^2 in its output, step by
    # step; the numbers must be those of the expression with temporaries, or every
    # bicycle and cart-pole record would move. 4-D like the bicycle's 256-centre basis.
    rng = np.random.default_rng(11)
    rbf = RBF.grid([-0.5, -1.5, -0.2, -1.5], [0.5, 1.5, 0.2, 1.5], 256, [0.25, 0.7, 0.1, 0.7], bias=bias)
    states = rng.uniform(-1.0, 1.0, size=(n, 4))
    s = states @ rbf._inverse.T
    sq = np.einsum("ij,ij->i", s, s)[:, None] - 2.0 * s @ rbf._scaled_centers.T + rbf._center_norms
    expected = np.exp(-0.5 * np.maximum(sq, 0.0))
    got = rbf(states)
    np.testing.assert_array_equal(got[:, 1:] if bias else got, expected)
    if bias:
        np.testing.assert_array_equal(got[:, 0], 1.0)


def test_rbf_pickled_without_derived_fields_evaluates_the_same():
    # A run's source cache may hold a basis pickled before a derived field existed.
    import pickle

    rbf = RBF.grid([-np.pi, -8.0], [np.pi, 8.0], 100, [0.6, 1.5], periodic=[True, False])
    states = np.random.default_rng(4).uniform(-4, 4, size=(20, 2))
    expected = rbf(states)
    old = pickle.loads(pickle.dumps(rbf))
    for name in ("_diagonal", "_center_norms", "_grid_values"):
        old.__dict__.pop(name, None)
    np.testing.assert_array_equal(old(states), expected)
