"""Known answers for Fitted Q-Iteration (tatl_mj.transfer.fqi)."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg

from tatl_mj.transfer.features import RBF, LinearFeatures, OneHot, make_features
from tatl_mj.transfer.fqi import (
    ExtraTrees,
    LinearQ,
    LinearRegressor,
    _blocked_pass,
    _gathered_columns,
    fitted_q_iteration,
    make_regressor,
)
from tatl_mj.transfer.methods.target_fqi import RL
from tatl_mj.transfer.tabular_q import q_iteration
from tatl_mj.transitions import Transitions
from tatl_mj.validation import InvalidSetting


def _transitions(s, a, r, s_next, absorbing=None):
    n = len(s)
    absorbing = np.zeros(n, dtype=bool) if absorbing is None else absorbing
    return Transitions(s, a, r, s_next, absorbing, absorbing.copy())


def test_fqi_converges_to_value_iteration_on_a_small_discrete_mdp():
    """A random deterministic 3 x 4 grid MDP with 3 actions, one sample per (s, a), one-hot basis.

    FQI is then exact Bellman backups, so after 300 iterations (gamma^300 ~ 2e-14) it must
    equal Q-iteration. Measured max |Q_FQI - Q_VI| ~ 1e-11.
    """
    rng = np.random.default_rng(3)
    rows, cols, n_actions, gamma = 3, 4, 3, 0.9
    n_states = rows * cols
    next_state = rng.integers(n_states, size=(n_states, n_actions))
    reward = rng.normal(size=(n_states, n_actions))
    absorbing = rng.random((n_states, n_actions)) < 0.1
    cells = np.stack(np.divmod(np.arange(n_states), cols), axis=1).astype(float)
    exact = q_iteration(next_state, reward, absorbing, gamma, cells=cells)

    s = np.repeat(np.arange(n_states), n_actions)
    a = np.tile(np.arange(n_actions), n_states)
    data = _transitions(cells[s], a, reward[s, a], cells[next_state[s, a]], absorbing[s, a])
    fqi = fitted_q_iteration(data, n_actions, LinearRegressor(OneHot(rows, cols), ridge=0.0), gamma, 300)
    err = np.abs(fqi.values(cells) - exact.values(cells)).max()
    assert err < 1e-8, err
    np.testing.assert_array_equal(fqi.greedy(cells), exact.greedy(cells))


def _double_integrator(n, seed, dt=0.4):
    """x' = A x + b u, reward -(x^T Qc x + Rc u^2), u in {-1, 0, 1}; and the LQR gain K (u = -K x)."""
    a_mat = np.array([[1.0, dt], [0.0, 1.0]])
    b = np.array([0.5 * dt**2, dt])
    qc, rc = np.diag([1.0, 0.1]), 0.01
    p = scipy.linalg.solve_discrete_are(a_mat, b[:, None], qc, np.array([[rc]]))
    gain = (b @ p @ a_mat) / (rc + b @ p @ b)
    rng = np.random.default_rng(seed)
    actions = np.array([-1.0, 0.0, 1.0])
    s = rng.uniform(-1, 1, size=(n, 2))
    a = rng.integers(3, size=n)
    s_next = s @ a_mat.T + np.outer(actions[a], b)
    r = -(np.einsum("ij,jk,ik->i", s, qc, s) + rc * actions[a] ** 2)
    return _transitions(s, a, r, s_next), gain, actions


@pytest.mark.parametrize("which", ["rbf", "extra_trees"])
def test_fqi_greedy_policy_has_the_lqr_sign_pattern(which):
    """Discrete-action double integrator: where the LQR action -K x is clearly non-zero
    (|u| > 0.5), the FQI greedy action has its sign. Measured agreement: 95.9% (RBF 7x7,
    20k samples) and 97.4% (extra-trees, 3k samples, 10 trees); required 90%.
    """
    if which == "rbf":
        data, gain, actions = _double_integrator(20_000, seed=0)
        regressor = LinearRegressor(RBF.grid([-1, -1], [1, 1], [7, 7], [0.35, 0.35]))
        q = fitted_q_iteration(data, 3, regressor, 0.9, 40)
        required = 0.9
    else:
        data, gain, actions = _double_integrator(3_000, seed=0)
        q = fitted_q_iteration(data, 3, ExtraTrees(n_estimators=10, seed=0), 0.9, 20)
        required = 0.9
    grid = np.stack(np.meshgrid(np.linspace(-0.8, 0.8, 31), np.linspace(-0.8, 0.8, 31)), -1).reshape(-1, 2)
    u_lqr = -grid @ gain
    clear = np.abs(u_lqr) > 0.5
    agree = np.mean(np.sign(actions[q.greedy(grid)][clear]) == np.sign(u_lqr[clear]))
    print(f"{which}: sign agreement with LQR {agree:.3f}")
    assert agree >= required, agree


def test_absorbing_transitions_bootstrap_nothing_and_initial_q_is_the_first_bootstrap():
    """One state, one action: r = 1, s' = s. Non-absorbing with Q_0 = c gives Q_1 = 1 + gamma c;
    absorbing gives Q_1 = 1 whatever Q_0 is."""
    s = np.zeros((4, 1))

    class Constant:
        n_actions = 1

        def values(self, states):
            return np.full((len(states), 1), 5.0)

        def greedy(self, states):
            return np.zeros(len(states), dtype=np.int64)

    # [1, s] on a constant state is rank-deficient; a tiny ridge picks the bias alone.
    reg = LinearRegressor(LinearFeatures(bias=True), ridge=1e-12)
    open_ = _transitions(s, np.zeros(4, int), np.ones(4), s)
    closed = _transitions(s, np.zeros(4, int), np.ones(4), s, np.ones(4, bool))
    q_open = fitted_q_iteration(open_, 1, reg, 0.5, 1, initial_q=Constant())
    q_closed = fitted_q_iteration(closed, 1, reg, 0.5, 1, initial_q=Constant())
    np.testing.assert_allclose(q_open.values(s[:1]), [[1.0 + 0.5 * 5.0]], rtol=1e-9)
    np.testing.assert_allclose(q_closed.values(s[:1]), [[1.0]], rtol=1e-9)
    # Many iterations: the fixed point 1 / (1 - gamma) = 2.
    np.testing.assert_allclose(fitted_q_iteration(open_, 1, reg, 0.5, 60).values(s[:1]), [[2.0]], rtol=1e-9)


def test_degenerate_input_raises_clear_errors():
    data, _, _ = _double_integrator(50, seed=1)
    reg = LinearRegressor(LinearFeatures())
    with pytest.raises(ValueError, match="gamma"):
        fitted_q_iteration(data, 3, reg, 1.0, 5)
    with pytest.raises(ValueError, match="iterations"):
        fitted_q_iteration(data, 3, reg, 0.9, 0)
    with pytest.raises(ValueError, match="actions must be indices"):
        fitted_q_iteration(data, 2, reg, 0.9, 5)
    only_two = data.head(50)
    only_two = _transitions(only_two.states, np.minimum(only_two.actions, 1), only_two.rewards, only_two.next_states)
    with pytest.raises(ValueError, match="no sample of action 2"):
        fitted_q_iteration(only_two, 3, reg, 0.9, 5)
    flat = _transitions(np.zeros((30, 2)), np.arange(30) % 3, np.ones(30), np.zeros((30, 2)))
    with pytest.raises(ValueError, match="rank-deficient"):
        fitted_q_iteration(flat, 3, LinearRegressor(LinearFeatures(), ridge=0.0), 0.9, 5)
    with pytest.raises(ValueError, match="NaN"):
        _transitions(np.full((3, 2), np.nan), np.zeros(3, int), np.zeros(3), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="valid kinds"):
        make_regressor({"kind": "mlp"}, 2)
    with pytest.raises(ValueError, match="min_samples_leaf"):
        ExtraTrees(min_samples_leaf=0)


def test_make_regressor_from_spec():
    reg = make_regressor(
        {
            "kind": "linear",
            "features": {"kind": "rbf", "centers": 20, "low": [-1, -1], "high": [1, 1], "sigma": [1.2, 1.2]},
            "ridge": 1e-4,
        },
        2,
    )
    assert isinstance(reg, LinearRegressor) and reg.ridge == 1e-4 and reg.features.size(2) == 21
    trees = make_regressor({"kind": "extra_trees", "seed": 3}, 2)
    assert trees == ExtraTrees(50, 5, 2, 3)


def test_make_regressor_accepts_a_learner_section_with_both_seed_and_features():
    features = {"kind": "linear"}
    assert isinstance(make_regressor({"kind": "linear", "features": features, "seed": 4}, 2), LinearRegressor)
    assert make_regressor({"kind": "extra_trees", "features": features, "seed": 4}, 2).seed == 4


def _reference_linear_fqi(t, n_actions, features, ridge, gamma, iterations, initial_q=None):
    """Linear FQI as first written (one least-squares solve per action on the raw samples
    every iteration): the fast paths must reproduce it."""
    phi, phi_next = features(t.states), features(t.next_states)
    k = phi.shape[1]
    continues = gamma * (~t.absorbing)
    rows = [np.flatnonzero(t.actions == a) for a in range(n_actions)]
    factors = [scipy.linalg.cho_factor(phi[i].T @ phi[i] + ridge * np.eye(k)) for i in rows]
    next_values = initial_q.values(t.next_states) if initial_q is not None else np.zeros((len(t), n_actions))
    weights = np.zeros((n_actions, k))
    for _ in range(iterations):
        y = t.rewards + continues * next_values.max(axis=1)
        for a, idx in enumerate(rows):
            weights[a] = scipy.linalg.cho_solve(factors[a], phi[idx].T @ y[idx])
        next_values = phi_next @ weights.T
    return weights


def _random_grid_data(n, seed, rows=4, cols=5, n_actions=4):
    """Random transitions on a rows x cols grid: moves with slip, absorbing corner, noisy rewards."""
    rng = np.random.default_rng(seed)
    s = np.stack([rng.integers(rows, size=n), rng.integers(cols, size=n)], axis=1)
    a = rng.integers(n_actions, size=n)
    moves = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]])[:n_actions]
    slip = rng.random(n) < 0.2
    step = np.where(slip[:, None], moves[rng.integers(n_actions, size=n)], moves[a])
    s_next = np.clip(s + step, 0, [rows - 1, cols - 1])
    absorbing = (s_next == [rows - 1, cols - 1]).all(axis=1)
    r = np.where(absorbing, 1.0, -0.1) + 0.05 * rng.normal(size=n)
    return _transitions(s.astype(float), a, r, s_next.astype(float), absorbing)


def _relative_error(new, old):
    return np.abs(new - old).max() / np.abs(old).max()


def test_linear_fqi_on_samples_reproduces_the_per_iteration_least_squares():
    """Continuous states (no repeats): the sample path. RBF 6x6, ridge 1, 300 iterations of
    gamma 0.99 from a non-zero Q_0; measured relative difference 3e-13."""
    data, _, _ = _double_integrator(3_000, seed=2)
    basis = RBF.grid([-1, -1], [1, 1], [6, 6], [0.35, 0.35])
    q0 = fitted_q_iteration(data, 3, LinearRegressor(basis, ridge=1.0), 0.9, 3)
    q = fitted_q_iteration(data, 3, LinearRegressor(basis, ridge=1.0), 0.99, 300, initial_q=q0)
    old = _reference_linear_fqi(data, 3, basis, 1.0, 0.99, 300, initial_q=q0)
    assert _relative_error(q.weights, old) < 1e-8, _relative_error(q.weights, old)


@pytest.mark.parametrize("ridge", [0.0, 1e-6, 1.0])
def test_one_hot_fqi_on_the_empirical_model_equals_the_sample_path(ridge):
    """Grid data with many repeats take the empirical-model path (Q-iteration on the
    count model); its weights equal the per-sample least squares. Measured <= 8e-16."""
    data = _random_grid_data(5_000, seed=4)
    basis = OneHot(4, 5)
    q = fitted_q_iteration(data, 4, LinearRegressor(basis, ridge=ridge), 0.95, 60)
    old = _reference_linear_fqi(data, 4, basis, ridge, 0.95, 60)
    assert _relative_error(q.weights, old) < 1e-8, _relative_error(q.weights, old)


@dataclasses.dataclass(frozen=True)
class _DenseIndicators:
    """OneHot's matrix, as a basis FQI does not know to be one-hot (it multiplies by it)."""

    basis: OneHot

    def __call__(self, states: np.ndarray) -> np.ndarray:
        return self.basis(states)

    def size(self, state_dim: int) -> int:
        return self.basis.size(state_dim)


@pytest.mark.parametrize("precision", ["double", "single"])
@pytest.mark.parametrize("n, with_prior", [(5_000, True), (60, False), (60, True)])
def test_one_hot_fqi_on_samples_picks_what_the_indicator_product_gives(n, with_prior, precision):
    """On the sample path (a prior, or too few samples for the counted model), a one-hot
    basis's next-state pass picks weight columns instead of multiplying by indicator
    columns: the same weights, bit for bit."""
    data, basis = _random_grid_data(n, seed=6), OneHot(4, 5)
    prior = LinearQ(basis, np.random.default_rng(2).normal(size=(4, 20))) if with_prior else None
    fits = [
        fitted_q_iteration(data, 4, LinearRegressor(b, 1e-6, precision), 0.95, 60, prior_q=prior)
        for b in (basis, _DenseIndicators(basis))
    ]
    picked, multiplied = [q.residual.weights if with_prior else q.weights for q in fits]
    assert np.abs(picked).max() > 0
    np.testing.assert_array_equal(picked, multiplied)


def test_one_hot_fqi_with_ridge_zero_is_q_iteration_on_the_empirical_model():
    """Known answer: with a one-hot basis and no ridge, FQI's fixed point solves
    Q(s,a) = mean r(s,a) + gamma sum_s' P(s'|s,a) max_b Q(s',b) with the sample frequencies;
    computed here by dense value iteration on the counted model."""
    data = _random_grid_data(4_000, seed=5)
    basis, gamma, n_states = OneHot(4, 5), 0.9, 20
    s, s2 = basis.index(data.states), basis.index(data.next_states)
    counts = np.zeros((n_states, 4))
    np.add.at(counts, (s, data.actions), 1)
    mean_r = np.zeros((n_states, 4))
    np.add.at(mean_r, (s, data.actions), data.rewards)
    mean_r /= counts
    p = np.zeros((n_states, 4, n_states))
    np.add.at(p, (s[~data.absorbing], data.actions[~data.absorbing], s2[~data.absorbing]), 1)
    p /= counts[:, :, None]
    exact = np.zeros((n_states, 4))
    for _ in range(600):  # gamma^600 ~ 1e-28
        exact = mean_r + gamma * p @ exact.max(axis=1)
    q = fitted_q_iteration(data, 4, LinearRegressor(basis, ridge=0.0), gamma, 600)
    cells = np.stack(np.divmod(np.arange(n_states), 5), axis=1).astype(float)
    np.testing.assert_allclose(q.values(cells), exact, rtol=0, atol=1e-9)


@pytest.mark.parametrize("n", [0, 1, 255, 256, 257, 5_001])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_gathered_columns_are_the_gathered_rows_transposed(n, dtype):
    # FQI's passes read the features gathered by sample order and transposed; the blocked
    # copy must give exactly what the one-shot gather and transpose give.
    rng = np.random.default_rng(n)
    matrix = rng.normal(size=(max(n, 3), 17))
    rows = rng.integers(len(matrix), size=n)
    got = _gathered_columns(matrix, rows, dtype)
    expected = np.ascontiguousarray(matrix[rows].T, dtype=dtype)
    assert got.dtype == dtype and got.flags.c_contiguous and got.shape == (17, n)
    np.testing.assert_array_equal(got, expected)


def test_one_hot_q_values_are_the_indicator_product_exactly():
    """LinearQ on a OneHot basis reads weight columns instead of multiplying by phi: the
    same numbers bit for bit, and the same refusal of a state off the grid."""
    basis = OneHot(3, 4)
    weights = np.random.default_rng(0).normal(size=(2, 12)) * 1e3
    q = LinearQ(basis, weights)
    cells = np.array([[0, 0], [2, 3], [1, 2], [1, 2]], float)
    np.testing.assert_array_equal(q.values(cells), basis(cells) @ weights.T)
    np.testing.assert_array_equal(q.greedy(cells), np.argmax(basis(cells) @ weights.T, axis=1))
    with pytest.raises(ValueError, match="3 x 4 grid"):
        q.values(np.array([[3.0, 0.0]]))


BASES = [
    {"kind": "rbf", "centers": 16, "low": [-1.0, -2.0], "high": [1.0, 2.0], "sigma": [0.5, 1.0]},
    {
        "kind": "rbf",
        "centers": 16,
        "low": [-3.0, -2.0],
        "high": [3.0, 2.0],
        "sigma": [0.5, 1.0],
        "periodic": [True, False],
    },
    {"kind": "linear"},
    {"kind": "linear", "periodic": [True, False]},
]


@pytest.mark.parametrize("spec", BASES, ids=lambda s: s["kind"] + ("-periodic" if "periodic" in s else ""))
def test_greedy_each_takes_each_rows_one_state_action(spec):
    from tatl_mj.transfer.fqi import greedy_each

    features = make_features(spec, 2)
    rng = np.random.default_rng(1)
    states = rng.uniform([-4.0, -3.0], [4.0, 3.0], size=(500, 2))
    if getattr(features, "row_exact", False):  # the claim greedy_each relies on
        np.testing.assert_array_equal(features(states), np.concatenate([features(s[None]) for s in states]))
    q = LinearQ(features, rng.normal(size=(3, features.size(2))))
    # Near ties, where a batched product's last bits could choose another action.
    q = LinearQ(features, np.concatenate([q.weights[:1], q.weights[:1] * (1 + 1e-15), q.weights[2:]]))
    one_by_one = np.array([q.greedy(s[None])[0] for s in states])
    np.testing.assert_array_equal(greedy_each(q, states), one_by_one)


def test_single_precision_passes_stay_within_float32_rounding_of_double():
    """precision="single" (ridge 1, so a fit moves by at most half the rounding of its
    targets, ~1e-7, and the iteration accumulates that over the 1 / (1 - gamma) = 100
    iterations its values look ahead): after 300 iterations of gamma 0.99 the weights
    stay within 1e-4 of the double-precision least squares (measured 5e-5), on the
    sample path, on the empirical-model path and with a prior; they are not the double
    weights, so the single passes ran."""
    data, _, _ = _double_integrator(3_000, seed=2)
    basis = RBF.grid([-1, -1], [1, 1], [6, 6], [0.35, 0.35])
    single = fitted_q_iteration(data, 3, LinearRegressor(basis, 1.0, "single"), 0.99, 300)
    old = _reference_linear_fqi(data, 3, basis, 1.0, 0.99, 300)
    assert 1e-12 < _relative_error(single.weights, old) < 1e-4, _relative_error(single.weights, old)
    states = np.random.default_rng(0).uniform(-1, 1, (2_000, 2))
    assert (single.greedy(states) == LinearQ(basis, old).greedy(states)).mean() > 0.99

    grid, cells = _random_grid_data(5_000, seed=4), OneHot(4, 5)
    on_model = fitted_q_iteration(grid, 4, LinearRegressor(cells, 1.0, "single"), 0.95, 60)
    old = _reference_linear_fqi(grid, 4, cells, 1.0, 0.95, 60)
    assert 1e-12 < _relative_error(on_model.weights, old) < 1e-4, _relative_error(on_model.weights, old)

    prior = LinearQ(basis, np.random.default_rng(1).normal(size=(3, basis.size(2))))
    with_prior = [
        fitted_q_iteration(data, 3, LinearRegressor(basis, 1.0, p), 0.99, 300, prior_q=prior)
        for p in ("single", "double")
    ]
    residuals = [q.residual.weights for q in with_prior]
    assert 1e-12 < _relative_error(*residuals) < 1e-4, _relative_error(*residuals)


def test_precision_is_checked_where_it_is_set():
    basis = LinearFeatures()
    message = r"LinearRegressor\.precision must be one of \['double', 'single'\], got 'half'"
    with pytest.raises(ValueError, match=message):
        LinearRegressor(basis, 1.0, "half")
    spec = {"kind": "linear", "features": {"kind": "linear"}, "precision": "single"}
    assert make_regressor(spec, 2).precision == "single"
    double = LinearRegressor(make_features({"kind": "linear"}, 2), 1e-6)
    assert make_regressor({**spec, "precision": "double"}, 2) == double
    with pytest.raises(ValueError, match="unknown keys"):
        make_regressor({"kind": "extra_trees", "precision": "single"}, 2)


def test_blocked_next_pass_is_the_matrix_product_summed_per_block():
    """Integer features and weights make every sum exact, whatever its order: the blocked
    pass then equals the matrix product bit for bit, over blocks that do not divide the
    samples (a width of 64 columns here, 1,000 samples)."""
    rng = np.random.default_rng(0)
    for dtype in (np.float64, np.float32):
        phi_t = rng.integers(-8, 9, size=(32, 1_000)).astype(dtype)
        weights = rng.integers(-8, 9, size=(3, 32)).astype(dtype)
        blocked = _blocked_pass(phi_t, cache_bytes=64 * 32 * phi_t.itemsize)(weights)
        assert blocked.dtype == dtype
        np.testing.assert_array_equal(blocked, weights @ phi_t)


@pytest.mark.parametrize("precision, tolerance", [("double", 1e-9), ("single", 1e-4)])
def test_blocked_next_pass_is_the_same_fqi_up_to_rounding(precision, tolerance):
    """The same fits as the matrix pass up to rounding (they sum in another order), with and
    without a prior; ridge 1 and 300 iterations of gamma 0.99 as above."""
    data, _, _ = _double_integrator(3_000, seed=2)
    basis = RBF.grid([-1, -1], [1, 1], [6, 6], [0.35, 0.35])
    prior = LinearQ(basis, np.random.default_rng(1).normal(size=(3, basis.size(2))))
    for prior_q in (None, prior):
        fits = [
            fitted_q_iteration(data, 3, LinearRegressor(basis, 1.0, precision, kind), 0.99, 300, prior_q=prior_q)
            for kind in ("matrix", "blocked")
        ]
        weights = [q.weights if prior_q is None else q.residual.weights for q in fits]
        assert _relative_error(*weights) < tolerance, _relative_error(*weights)


def test_next_pass_is_checked_where_it_is_set():
    with pytest.raises(ValueError, match=r"LinearRegressor\.next_pass must be one of \['matrix', 'blocked'\]"):
        LinearRegressor(LinearFeatures(), 1.0, "double", "gemv")
    spec = {"kind": "linear", "features": {"kind": "linear"}, "next_pass": "blocked"}
    assert make_regressor(spec, 2).next_pass == "blocked"
    with pytest.raises(ValueError, match="unknown keys"):
        make_regressor({"kind": "extra_trees", "next_pass": "blocked"}, 2)
    with pytest.raises(InvalidSetting, match=r"RL\.next_pass applies to regressor 'linear' only"):
        RL(regressor="extra_trees", next_pass="blocked")
