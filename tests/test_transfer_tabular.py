"""Known answers for the tabular apprentice and ta-tl-replan (tatl_mj.transfer.tabular, methods.replan).

The windy grid world is the target, the plain grid its source, the mapping the
identity; the exact models come from gridworld.transition_model, the data from
stepping the environment itself.
"""

import collections

import numpy as np
import pytest

from tatl_mj import sampling, suite
from tatl_mj.description import CellMap
from tatl_mj.suite import gridworld
from tatl_mj.transfer import tabular
from tatl_mj.transfer.intertask_mapping import AffineMapping, IdentityMapping
from tatl_mj.transfer.methods.replan import OneStepRule, replan
from tatl_mj.transfer.tabular_q import q_iteration
from tatl_mj.transitions import Transitions

GAMMA = 0.95
PLAIN = gridworld.transition_model(windy=False)
WINDY = gridworld.transition_model(windy=True)
CELLS = CellMap(PLAIN[3])
SOURCE = tabular.TabularModel(*PLAIN[:3])
TARGET = tabular.TabularModel(*WINDY[:3])
GOAL = int(CELLS.index(np.array([gridworld.GOAL], dtype=float))[0])


def one_visit_per_pair(windy: bool = True) -> Transitions:
    """Every (cell, action) but the goal's, stepped once in the environment itself."""
    env = suite.load("gridworld", "windy" if windy else "plain", task_kwargs={"random": 0})
    rows = collections.defaultdict(list)
    for cell in CELLS.cells:
        if tuple(cell) == gridworld.GOAL:
            continue
        for a in gridworld.ACTIONS:
            env.reset()
            env.set_state_vector(cell.astype(float))
            timestep = env.step(a)
            for key, value in (
                ("states", cell),
                ("actions", a),
                ("rewards", timestep.reward),
                ("next_states", timestep.observation["state"]),
                ("absorbing", timestep.discount == 0.0),
                ("last", timestep.last()),
            ):
                rows[key].append(value)
    return Transitions(**{k: np.asarray(v) for k, v in rows.items()})


def steps_to_goal(model: tabular.TabularModel) -> np.ndarray:
    """(S,) fewest steps from each cell to the goal under ``model`` (breadth-first, backwards)."""
    dist = np.full(model.n_cells, -1)
    dist[GOAL] = 0
    frontier = [GOAL]
    while frontier:
        nxt = []
        for cell in frontier:
            for prev, _ in zip(*np.nonzero(model.next_state == cell)):
                if dist[prev] < 0:
                    dist[prev] = dist[cell] + 1
                    nxt.append(prev)
        frontier = nxt
    return dist


def test_cell_map_round_trip_and_errors():
    assert np.array_equal(CELLS.index(CELLS.cells), np.arange(CELLS.n_cells))
    assert np.array_equal(CELLS.nearest(CELLS.cells + 0.3), np.arange(CELLS.n_cells))
    with pytest.raises(ValueError, match=r"state \[1.0, 4.0\] is not one of the 86 cells"):
        CELLS.index(np.array([[0.0, 0.0], [1.0, 4.0]]))  # (1, 4) is an obstacle
    with pytest.raises(ValueError, match="is not one of"):
        CELLS.index(np.array([[0.5, 0.0]]))
    with pytest.raises(ValueError, match="must not repeat"):
        CellMap(np.array([[0, 0], [0, 0]]))


def test_tabular_model_keeps_its_arrays_and_refuses_other_inputs():
    model = tabular.TabularModel(*PLAIN[:3])
    assert all(a is b for a, b in zip((model.next_state, model.reward, model.absorbing), PLAIN[:3]))
    with pytest.raises(ValueError, match="must be numpy arrays"):
        tabular.TabularModel([[0]], np.zeros((1, 1)), np.zeros((1, 1), bool))
    with pytest.raises(ValueError, match="reward must be numbers"):
        tabular.TabularModel(np.zeros((1, 1), int), np.array([["a"]]), np.zeros((1, 1), bool))


def test_apprentice_reproduces_the_windy_grid_after_one_visit_per_pair():
    data = one_visit_per_pair()
    apprentice = tabular.fit_tabular_apprentice(data, CELLS, SOURCE)
    model = apprentice.model()
    expected_visited = np.ones_like(apprentice.visited)
    expected_visited[GOAL] = False
    assert np.array_equal(apprentice.visited, expected_visited)
    assert np.array_equal(model.next_state, TARGET.next_state)
    assert np.array_equal(model.reward, TARGET.reward)
    assert np.array_equal(model.absorbing, TARGET.absorbing)
    cells, actions = np.nonzero(expected_visited)
    assert np.array_equal(apprentice.predict(cells, actions), TARGET.next_state[cells, actions])


def test_apprentice_mode_ties_and_fallback():
    cells = CellMap(np.arange(4)[:, None])
    prior = tabular.TabularModel(
        np.array([[3, 2], [1, 1], [2, 2], [3, 3]]), np.full((4, 2), 7.0), np.zeros((4, 2), bool)
    )
    # (0, 0) -> 1, 1, 2: the mode 1, its reward the mean of the two landings on 1, absorbing by majority.
    # (0, 1) -> 1, 2: a tie, resolved to the prior's 2; (1, 0) -> 0, 3: tie, prior 1 absent, lowest 0.
    # (2, 0) -> 2 with reward 7: what the prior says.
    s = np.array([[0], [0], [0], [0], [0], [1], [1], [2]])
    a = np.array([0, 0, 0, 1, 1, 0, 0, 0])
    s_next = np.array([[1], [1], [2], [1], [2], [3], [0], [2]])
    r = np.array([1.0, 3.0, 100.0, 5.0, 6.0, 0.0, 0.0, 7.0])
    absorbing = np.array([True, False, False, False, True, False, False, False])
    data = Transitions(s, a, r, s_next, absorbing, np.ones(8, bool))
    apprentice = tabular.fit_tabular_apprentice(data, cells, prior, prior_scope="unvisited")
    model = apprentice.model()
    assert model.next_state.tolist() == [[1, 2], [0, 1], [2, 2], [3, 3]]
    assert model.reward.tolist() == [[2.0, 6.0], [0.0, 7.0], [7.0, 7.0], [7.0, 7.0]]
    assert model.absorbing.tolist() == [[True, True], [False, False], [False, False], [False, False]]
    assert apprentice.visited.tolist() == [[True, True], [True, False], [True, False], [False, False]]
    # By default the prior is trusted only in cells whose data agree with it: cell 1's visited
    # pair contradicts it, so (1, 1) stays in place with reward 0; cell 2's agrees, so (2, 1) keeps it.
    model = tabular.fit_tabular_apprentice(data, cells, prior).model()
    assert model.next_state.tolist() == [[1, 2], [0, 1], [2, 2], [3, 3]]
    assert model.reward.tolist() == [[2.0, 6.0], [0.0, 0.0], [7.0, 7.0], [7.0, 7.0]]
    with pytest.raises(ValueError, match=r"prior_scope must be one of \('agreeing-cells', 'unvisited'\)"):
        tabular.fit_tabular_apprentice(data, cells, prior, prior_scope="everywhere")


def test_replanner_with_the_exact_model_is_optimal_from_every_start():
    apprentice = tabular.fit_tabular_apprentice(one_visit_per_pair(), CELLS, SOURCE)
    policy = replan(apprentice, CELLS, GAMMA)
    exact = q_iteration(*WINDY[:3], GAMMA)
    np.testing.assert_allclose(policy.q.q, exact.q, rtol=0, atol=1e-9)
    # Acting in the windy environment from every free cell: the goal without a bump
    # (undiscounted return 10), and a discounted return equal to the optimum max_a Q*(s, a).
    shortest = steps_to_goal(TARGET)
    env = suite.load("gridworld", "windy", task_kwargs={"random": 0})
    for cell in range(CELLS.n_cells):
        if cell == GOAL:
            continue
        env.reset()
        env.set_state_vector(CELLS.cells[cell].astype(float))
        timestep, ret, discounted, steps = None, 0.0, 0.0, 0
        while timestep is None or not timestep.last():
            timestep = env.step(policy(env.state_vector()[None])[0])
            ret, discounted = ret + timestep.reward, discounted + GAMMA**steps * timestep.reward
            steps += 1
        assert (ret, timestep.discount) == (gridworld.GOAL_REWARD, 0.0), CELLS.cells[cell]
        assert steps >= shortest[cell] and discounted == pytest.approx(exact.q[cell].max(), abs=1e-9)


def test_replanner_falls_back_to_the_prior_where_no_data_exist():
    data = one_visit_per_pair()
    seen = data.states[:, 1] >= 6  # target data only in columns 6..9
    part = Transitions(
        *(getattr(data, f)[seen] for f in ("states", "actions", "rewards", "next_states", "absorbing", "last"))
    )
    policy = replan(tabular.fit_tabular_apprentice(part, CELLS, SOURCE), CELLS, GAMMA, len(part))
    east = (CELLS.cells[:, 1] >= 6) & (np.arange(CELLS.n_cells) != GOAL)
    assert np.array_equal(policy.visited, np.repeat(east[:, None], 4, axis=1))
    for field in ("next_state", "reward", "absorbing"):
        merged, target, source = (getattr(m, field) for m in (policy.model, TARGET, SOURCE))
        assert np.array_equal(merged[east], target[east]) and np.array_equal(merged[~east], source[~east])
    step = policy.step(CELLS.cells[[0, 9]].astype(float))  # (0, 0) unvisited, (0, 9) visited
    assert step.from_target.tolist() == [False, True]
    # Without data at all the replanner is the source's Q-iteration; the uninformed prior gives 0.
    empty = part.head(0)
    np.testing.assert_allclose(
        replan(tabular.fit_tabular_apprentice(empty, CELLS, SOURCE), CELLS, GAMMA).q.q,
        q_iteration(*PLAIN[:3], GAMMA).q,
        atol=1e-9,
    )
    blank = tabular.fit_tabular_apprentice(empty, CELLS, tabular.uninformed_model(CELLS.n_cells, 4))
    assert np.array_equal(replan(blank, CELLS, GAMMA).q.q, np.zeros((CELLS.n_cells, 4)))


def test_mapped_model_translates_cells_through_the_mapping():
    assert all(
        np.array_equal(getattr(tabular.mapped_model(SOURCE, CELLS, CELLS, IdentityMapping()), f), getattr(SOURCE, f))
        for f in ("next_state", "reward", "absorbing")
    )
    # The target lists the same cells shifted by (10, 20) and in reverse order.
    order = np.arange(CELLS.n_cells)[::-1]
    shifted = CellMap(CELLS.cells[order] + [10, 20])
    mapped = tabular.mapped_model(SOURCE, CELLS, shifted, AffineMapping(np.eye(2), [10.0, 20.0]))
    position = np.argsort(order)  # target index of each source cell
    assert np.array_equal(mapped.next_state, position[SOURCE.next_state[order]])
    assert np.array_equal(mapped.reward, SOURCE.reward[order])


class TableQ:
    """The greedy source policy of a TabularModel, over states (for the one-step rule)."""

    def __init__(self, model: tabular.TabularModel, cells: CellMap, gamma: float):
        self.q, self.cells, self.n_actions = model.q(gamma), cells, model.n_actions

    def values(self, states):
        return self.q.q[self.cells.index(states)]

    def greedy(self, states):
        return np.argmax(self.values(states), axis=1)


def test_one_step_rule_with_the_exact_model_loops_between_two_cells():
    # A track of cells 0..3, goal 3, actions step -1 / +1 (clipped at the ends).
    # In the target a current adds +2 in cell 1 and -2 in cell 2.
    cells = CellMap(np.arange(4)[:, None])
    step, current = np.array([-1, 1]), np.array([0, 2, -2, 0])

    def track(cur):
        nxt = np.clip(np.arange(4)[:, None] + step[None, :] + cur[:, None], 0, 3)
        nxt[3] = 3  # the goal absorbs
        return tabular.TabularModel(nxt, 10.0 * (nxt == 3), nxt == 3)

    source, target = track(np.zeros(4, int)), track(current)
    rule = OneStepRule(
        TableQ(source, cells, 0.9),
        IdentityMapping(),
        lambda s, a: cells.cells[source.next_state[cells.index(s), a]].astype(float),
        target,
        cells,
    )
    decision = rule.step(np.array([[1.0], [2.0]]))
    # From 1 the source goes to 2; "left" lands exactly there (1 - 1 + 2), while "right" would
    # reach the goal (1 + 1 + 2, clipped). From 2 the source goes to 3; "right" lands on 1 (2 + 1 - 2),
    # nearer than "left" (0). So 1 -> 2 -> 1 -> ... forever.
    np.testing.assert_allclose(decision.s_hat_T_next[:, 0], [2.0, 3.0])
    np.testing.assert_allclose(decision.distances, [[0.0, 1.0], [3.0, 2.0]])
    assert decision.action.tolist() == [0, 1]
    assert target.next_state[[1, 2], decision.action].tolist() == [2, 1]
    # The replanner with the same exact model takes "right" at 1, to the goal.
    exact = tabular.fit_tabular_apprentice(
        Transitions(
            np.arange(3).repeat(2)[:, None],
            np.tile([0, 1], 3),
            target.reward[:3].ravel(),
            target.next_state[:3].ravel()[:, None],
            target.absorbing[:3].ravel(),
            np.ones(6, bool),
        ),
        cells,
        source,
    )
    assert replan(exact, cells, 0.9)(np.array([[1.0]])).tolist() == [1]


def test_one_step_rule_with_the_exact_windy_model_is_trapped_from_the_start():
    # The wind of column 6 (2 up) throws every move from (0, 6) back to (0, 6): a 1-cycle.
    rule = OneStepRule(
        TableQ(SOURCE, CELLS, GAMMA),
        IdentityMapping(),
        lambda s, a: sampling.step_from("gridworld", "plain", s, a),
        TARGET,
        CELLS,
    )
    cell, path = int(CELLS.index(np.array([gridworld.START], float))[0]), []
    for _ in range(gridworld.DEFAULT_TIME_LIMIT):
        path.append(tuple(CELLS.cells[cell]))
        cell = int(TARGET.next_state[cell, rule(CELLS.cells[[cell]].astype(float))[0]])
    assert path[-3:] == [(0, 6)] * 3 and (5, 8) not in path


def test_policy_transitions_follows_the_policy_from_random_starts():
    apprentice = tabular.fit_tabular_apprentice(one_visit_per_pair(), CELLS, SOURCE)
    policy = replan(apprentice, CELLS, GAMMA)

    def run(seed, n=200):
        env = suite.load("gridworld", "windy", task_kwargs={"random": seed, "random_start": True})
        return sampling.policy_transitions(env, policy, n, gridworld.ACTIONS)

    data = run(3)
    assert len(data) == 200 and data.last[-1]
    starts = np.flatnonzero(np.r_[True, data.last[:-1]])
    reference = suite.load("gridworld", "windy", task_kwargs={"random": 3, "random_start": True})
    assert np.array_equal(data.states[starts], [reference.reset().observation["state"] for _ in starts])
    s, s_next = CELLS.index(data.states), CELLS.index(data.next_states)
    assert np.array_equal(s_next, TARGET.next_state[s, data.actions])
    assert np.array_equal(data.actions, policy(data.states))
    # The optimal policy ends every whole episode on the goal, earning the optimum from its start
    # (the last episode is cut at n transitions).
    ends = np.r_[starts[1:], len(data)]
    for start, end in zip(starts[:-1], ends[:-1]):
        assert data.absorbing[end - 1] and s_next[end - 1] == GOAL
        discounted = np.sum(GAMMA ** np.arange(end - start) * data.rewards[start:end])
        assert discounted == pytest.approx(policy.q.q[s[start]].max(), abs=1e-9)
    assert np.array_equal(run(3).states, data.states)
    with pytest.raises(ValueError, match="n must be an integer >= 1"):
        run(3, n=0)
