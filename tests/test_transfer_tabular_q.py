"""Known answers for exact Q-iteration and its Q table (tatl_mj.transfer.tabular_q)."""

import numpy as np
import pytest

from tatl_mj.transfer.tabular_q import TabularQ, q_iteration


def test_q_iteration_on_a_chain_matches_the_closed_form():
    """Chain of 6 cells, goal at the right end (absorbing), reward -1 a step, actions left/right.

    From a cell k steps from the goal the optimal return is -(1 - gamma^k) / (1 - gamma).
    """
    n, gamma = 6, 0.9
    states = np.arange(n)
    next_state = np.stack([np.maximum(states - 1, 0), np.minimum(states + 1, n - 1)], axis=1)
    reward = -np.ones((n, 2))
    absorbing = next_state == n - 1
    cells = np.stack([np.zeros(n), states], axis=1)
    q = q_iteration(next_state, reward, absorbing, gamma, cells=cells)
    steps = (n - 1) - states[:-1]
    np.testing.assert_allclose(q.values(states[:-1])[:, 1], -(1 - gamma**steps) / (1 - gamma), atol=1e-9)
    np.testing.assert_array_equal(q.greedy(cells[:-1]), 1)  # always move right, also via [row, col]
    with pytest.raises(ValueError, match="cells of the grid"):
        TabularQ(q.q[:5], cells[:5]).values(np.array([[0.0, 5.0]]))


def test_tabular_q_indexes_one_cell_as_it_indexes_many_and_refuses_non_cells():
    cells = np.array([[r, c] for r in range(3) for c in range(4) if (r, c) != (1, 2)])  # a wall at (1, 2)
    q = TabularQ(np.arange(len(cells) * 2.0).reshape(-1, 2), cells=cells)
    many = q.index(cells.astype(float))
    assert [int(q.index(cell[None].astype(float))[0]) for cell in cells] == many.tolist() == list(range(len(cells)))
    assert q.index(np.array([[2.0 + 1e-12, 3.0]])).tolist() == [len(cells) - 1]
    for bad in ([[1.0, 2.0]], [[0.5, 0.0]], [[3.0, 0.0]], [[-1.0, 0.0]]):
        with pytest.raises(ValueError, match="cells of the grid"):
            q.index(np.array(bad))


def test_tabular_q_takes_a_float64_table():
    with pytest.raises(ValueError, match="float64"):
        TabularQ(np.zeros((3, 2), dtype=int))
    with pytest.raises(ValueError, match="float64"):
        TabularQ([[0.0, 1.0]])


def test_q_iteration_refuses_a_next_state_that_is_no_state():
    with pytest.raises(ValueError, match="state indices"):
        q_iteration(np.array([[5]]), np.zeros((1, 1)), np.zeros((1, 1), bool), 0.9)
