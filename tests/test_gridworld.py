"""Grid world: layout, hand-checked moves, the model agrees with ``step``, and the wind
changes the optimal route (checked by exact Q-iteration)."""

import dm_env
import numpy as np
import pytest
from scipy import stats

from tatl_mj import suite
from tatl_mj.suite import gridworld as gw

UP, DOWN, LEFT, RIGHT = gw.ACTIONS
GAMMA = 0.95


def _env(task="plain", **kwargs):
    env = suite.load("gridworld", task, task_kwargs={"random": 0, **kwargs})
    env.reset()
    return env


def _step_from(env, cell, action):
    env.set_state_vector(np.array(cell, dtype=float))
    return env.step(action)


def _q_iteration(next_state, reward, absorbing, n_iter=500):
    q = np.zeros(reward.shape)
    for _ in range(n_iter):
        q = reward + GAMMA * ~absorbing * q.max(axis=1)[next_state]
    return q


def _greedy_steps(next_state, absorbing, policy, start, limit=gw.DEFAULT_TIME_LIMIT):
    """Steps the greedy policy takes to the goal in a model, or None within ``limit``."""
    s = start
    for t in range(limit):
        a = policy[s]
        if absorbing[s, a]:
            return t + 1
        s = next_state[s, a]
    return None


def test_layout_matches_the_docstring_map():
    assert (gw.N_ROWS, gw.N_COLS) == (10, 10) and len(gw.WIND) == gw.N_COLS
    assert gw.START == (5, 0) and gw.GOAL == (5, 8)
    for row, line in enumerate(gw.LAYOUT):
        assert f"{row}     {line}" in gw.__doc__
    assert "wind      " + "".join(str(w) for w in gw.WIND) in gw.__doc__


@pytest.mark.parametrize(
    "task, cell, action, expected, reward",
    [
        ("plain", (5, 0), RIGHT, (5, 1), 0.0),
        ("plain", (0, 0), UP, (0, 0), -1.0),  # grid edge
        ("plain", (2, 3), RIGHT, (2, 3), -1.0),  # obstacle at (2, 4)
        ("plain", (5, 9), LEFT, (5, 8), 10.0),  # goal
        ("windy", (5, 2), RIGHT, (5, 3), 0.0),  # wind of column 2 is 0
        ("windy", (5, 3), RIGHT, (5, 4), 0.0),  # pushed up into the obstacle (4, 4): stays
        ("windy", (5, 5), DOWN, (5, 5), 0.0),  # down 1, wind 1 up
        ("windy", (5, 6), RIGHT, (3, 6), -1.0),  # blocked by (5, 7), then wind 2
        ("windy", (1, 6), LEFT, (0, 5), 0.0),  # wind 2 stopped by the top edge after 1
        ("windy", (8, 5), RIGHT, (8, 6), 0.0),  # wind 1 blocked by the obstacle (7, 6)
        ("windy", (6, 8), UP, (4, 8), 0.0),  # crosses the goal, pushed past it: no reward
        ("windy", (5, 9), LEFT, (5, 8), 10.0),  # enters the goal from the calm column
    ],
)
def test_hand_checked_moves(task, cell, action, expected, reward):
    timestep = _step_from(_env(task), cell, action)
    assert tuple(timestep.observation["state"]) == expected
    assert timestep.reward == reward
    assert timestep.discount == (0.0 if expected == gw.GOAL else 1.0)
    assert timestep.last() == (expected == gw.GOAL)


@pytest.mark.parametrize("windy", [False, True])
def test_transition_model_agrees_with_step(windy):
    next_state, reward, absorbing, cells = gw.transition_model(windy)
    n_states = len(cells)
    assert next_state.shape == reward.shape == absorbing.shape == (n_states, 4)
    assert cells.shape == (n_states, 2) and n_states == gw.N_ROWS * gw.N_COLS - gw.OBSTACLES.sum()
    np.testing.assert_array_equal(gw.cell_indices(cells), np.arange(n_states))
    env = _env("windy" if windy else "plain")
    for i, cell in enumerate(cells):
        if tuple(cell) == gw.GOAL:
            assert np.all(absorbing[i]) and np.all(reward[i] == 0) and np.all(next_state[i] == i)
            continue
        for a in gw.ACTIONS:
            timestep = _step_from(env, cell, a)
            np.testing.assert_array_equal(timestep.observation["state"], cells[next_state[i, a]])
            assert timestep.reward == reward[i, a]
            assert (timestep.discount == 0.0) == absorbing[i, a]
            if timestep.last():
                env.reset()


def test_wind_changes_the_optimal_route():
    plain = gw.transition_model(windy=False)
    windy = gw.transition_model(windy=True)
    start = int(gw.cell_indices(np.array([gw.START]))[0])
    plain_policy = _q_iteration(*plain[:3]).argmax(axis=1)
    q_windy = _q_iteration(*windy[:3])
    windy_policy = q_windy.argmax(axis=1)

    assert _greedy_steps(plain[0], plain[2], plain_policy, start) == 14
    assert _greedy_steps(windy[0], windy[2], windy_policy, start) == 16
    # The plain route, followed in the wind, is blown off course for good.
    assert _greedy_steps(windy[0], windy[2], plain_policy, start) is None
    # Every cell can still reach the goal in the wind.
    goal = int(gw.cell_indices(np.array([gw.GOAL]))[0])
    assert np.all(np.delete(q_windy.max(axis=1), goal) > 0)


def test_time_limit_truncates():
    env = suite.load("gridworld", "plain", task_kwargs={"time_limit": 7})
    env.reset()
    for _ in range(6):
        assert env.step(LEFT).mid()  # bumping the left edge
    timestep = env.step(LEFT)
    assert timestep.last() and timestep.discount == 1.0 and timestep.reward == -1.0
    assert env.step(LEFT).first()


def test_random_start_is_seeded_and_uniform_over_free_cells():
    cells = gw.free_cells()
    candidates = cells[~np.all(cells == gw.GOAL, axis=1)]
    env = suite.load("gridworld", "windy", task_kwargs={"random": 1, "random_start": True})
    draws = np.array([env.reset().observation["state"] for _ in range(40 * len(candidates))])
    counts = np.bincount(gw.cell_indices(draws), minlength=len(cells))
    goal = int(gw.cell_indices(np.array([gw.GOAL]))[0])
    assert counts[goal] == 0
    assert stats.chisquare(np.delete(counts, goal)).pvalue > 1e-3
    again = suite.load("gridworld", "windy", task_kwargs={"random": 1, "random_start": True})
    np.testing.assert_array_equal(draws[:20], [again.reset().observation["state"] for _ in range(20)])
    assert tuple(_env().reset().observation["state"]) == gw.START


def test_stochastic_wind_is_seeded_and_spreads_by_one():
    ends = []
    for seed in (5, 5, 6):
        env = _env("windy", random=seed, stochastic_wind=True)
        rows = []
        for _ in range(300):
            rows.append(_step_from(env, (6, 5), RIGHT).observation["state"][0])  # wind 1 in col 5
        ends.append(np.array(rows))
    np.testing.assert_array_equal(ends[0], ends[1])
    assert not np.array_equal(ends[0], ends[2])
    counts = {row: np.sum(ends[0] == row) for row in (4.0, 5.0, 6.0)}  # pushed 2, 1, 0 cells
    assert sum(counts.values()) == 300 and min(counts.values()) > 60


def test_specs_and_state_access():
    env = _env("windy")
    assert env.action_spec() == dm_env.specs.DiscreteArray(4, name="action")
    spec = env.observation_spec()["state"]
    assert spec.shape == (2,) and spec.dtype == np.float64
    env.set_state_vector([9.0, 9.0])
    state = env.state_vector()
    assert state.dtype == np.float64 and tuple(state) == (9.0, 9.0)
    spec.validate(state)


@pytest.mark.parametrize("bad", [[4.0, 4.0], [5.0, 8.0], [-1.0, 0.0], [0.0, 10.0], [1.5, 0.0], [0.0]])
def test_bad_states_raise(bad):
    with pytest.raises(ValueError, match="gridworld"):
        _env().set_state_vector(bad)


@pytest.mark.parametrize("bad", [4, -1, 1.5, "up", [0, 1], True, np.nan])
def test_bad_actions_raise(bad):
    env = _env()
    with pytest.raises(ValueError, match="gridworld action"):
        env.step(bad)


def test_bad_task_arguments_raise():
    with pytest.raises(ValueError, match="time_limit"):
        gw.plain(time_limit=0)
    with pytest.raises(ValueError, match="environment_kwargs"):
        gw.windy(environment_kwargs={"flat_observation": True})
    with pytest.raises(ValueError, match="stochastic_wind"):
        suite.load("gridworld", "plain", task_kwargs={"stochastic_wind": True})
    assert _env().step(np.int32(3)).observation["state"][1] == 1.0  # numpy integers are fine


def test_transition_reward_is_the_environments_reward_for_every_step():
    """Algorithm 2 scores a grid model with the description's step reward: it must equal the
    task's own reward (bumps and the goal) on every (cell, action) of both tasks."""
    from tatl_mj import suite

    for task in ("plain", "windy"):
        description = suite.describe("gridworld", task)
        next_state, reward, absorbing, cells = description.known_model()
        s = np.repeat(cells, 4, axis=0).astype(float)
        a = np.tile(np.arange(4), len(cells))
        s_next = cells[next_state.ravel()].astype(float)
        not_goal = ~description.transition_absorbing(s)  # the goal's own row is a formality
        np.testing.assert_array_equal(description.transition_reward(s, a, s_next)[not_goal], reward.ravel()[not_goal])
        np.testing.assert_array_equal(description.transition_absorbing(s_next), absorbing.ravel())


def test_algorithm_2_runs_on_the_grid():
    import tomllib

    from conftest import ROOT

    from tatl_mj.experiments import spec as spec_mod
    from tatl_mj.experiments.run import problems, source_unit

    table = tomllib.loads((ROOT / "tasks" / "grid_to_windy.toml").read_text())
    experiment = spec_mod.parse_spec(table, "grid_to_windy.toml")
    preset = experiment.preset("smoke")
    artifacts = source_unit.learn_source(experiment, preset, 0)
    problem = problems.transfer_problem(experiment, preset, artifacts, 0)
    assert problem.has_utility_gap

    class TableModel:  # a known tabular model as an apprentice-like model
        def __init__(self, description):
            self.next_state, _, _, self.cells = description.known_model()
            self.moves = description.action_values

        def predict(self, states, values):
            from tatl_mj.description import CellMap

            index = np.argmin(np.linalg.norm(values[:, None] - self.moves[None], axis=2), axis=1)
            return self.cells[self.next_state[CellMap(self.cells).index(states), index]].astype(float)

    # The windy grid itself stands in for the target exactly (U_M and U_Mhat start from the
    # same cells); the windless one does not.
    assert problem.utility_gap(TableModel(problem.target)) == 0.0
    assert problem.utility_gap(TableModel(problem.target), kind="relative") == 0.0
    assert problem.utility_gap(TableModel(problem.source), kind="relative") > 0.2
