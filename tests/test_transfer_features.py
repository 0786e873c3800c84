"""Known answers for the bases phi(s) of tatl_mj.transfer.features."""

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
