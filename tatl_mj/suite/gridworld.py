"""Grid world and windy grid world: walk from a start cell to a goal around obstacles.

The paper's first experiment (source: no wind, target: wind in part of the
grid), in pure numpy behind ``dm_env``, loaded through ``suite.load`` like the
physics tasks. The wind profile is Sutton & Barto's windy grid world's.

Layout (10 x 10; row 0 at the top, ``#`` obstacle, ``S`` start, ``G`` goal; the
last line is the wind, in cells pushed up per step, of each column)::

        col 0123456789
    row 0     ..........
        1     ....#.....
        2     ....#.....
        3     ....#..#..
        4     ....#..#..
        5     S......#G.
        6     ....#..#..
        7     ....#.###.
        8     ....#.....
        9     ..........
    wind      0001112210

Without wind the shortest route (14 steps) goes through the gap in column 4
and over the top of the wall around the goal; with wind that route is blown
off course (followed greedily it never reaches the goal) and the best route
(16 steps) goes round the bottom and enters the goal from the right, out of the
wind. ``tests/test_gridworld.py`` checks both by Q-iteration.

=================  ==========================================================
State              ``[row, col]`` (float64, integer-valued), rows 0..9 from
                   the top, columns 0..9 from the left.
Actions            ``ACTIONS = np.arange(4)``: 0 up (row - 1), 1 down
                   (row + 1), 2 left (col - 1), 3 right (col + 1); action spec
                   ``DiscreteArray(4)``.
Dynamics           The agent moves one cell unless the move would leave the
                   grid or enter an obstacle, then it stays. In the windy task
                   the wind of the column it started the step in then pushes
                   it up that many cells, one at a time, stopping at the edge
                   or an obstacle. With ``stochastic_wind=True`` that push is
                   the column's wind -1, +0 or +1 with probability 1/3 each in
                   the columns that have wind (Sutton & Barto, exercise 6.10).
Reward             +10 when the step ends on the goal; -1 when the agent's own
                   move is blocked (wall or obstacle); 0 otherwise. The two add.
Start state        the start cell S (5, 0), or with ``random_start=True`` a
                   cell drawn uniformly over the free cells other than the goal
                   from ``random``.
Episode end        goal, with discount 0; otherwise the time limit of
                   ``time_limit`` steps (default 100), which is not a failure.
Parameters         ``time_limit`` (steps), ``random`` (seed or
                   ``np.random.RandomState``), ``random_start``,
                   ``stochastic_wind`` (windy task only).
=================  ==========================================================

:func:`transition_model` gives the deterministic model as arrays for exact
Q-iteration; it runs the same step function as the environment.
"""

from __future__ import annotations

import collections
import functools
from typing import Any, Callable

import dm_env
import numpy as np
from dm_env import specs

from tatl_mj.description import TaskDescription
from tatl_mj.suite import common
from tatl_mj.validation import integer, is_integer

LAYOUT: tuple[str, ...] = (
    "..........",
    "....#.....",
    "....#.....",
    "....#..#..",
    "....#..#..",
    "S......#G.",
    "....#..#..",
    "....#.###.",
    "....#.....",
    "..........",
)
WIND = np.array([0, 0, 0, 1, 1, 1, 2, 2, 1, 0])  # cells pushed up per step, per column

ACTIONS = np.arange(4)
DYNAMICS_VERSION = 1  # of every task here; docs/versions.md says when it is bumped
ACTION_NAMES = ("up", "down", "left", "right")
MOVES = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]])  # (d_row, d_col) per action

GOAL_REWARD = 10.0
BUMP_REWARD = -1.0
DEFAULT_TIME_LIMIT = 100  # steps

_GRID = np.array([list(row) for row in LAYOUT])
N_ROWS, N_COLS = _GRID.shape
OBSTACLES = _GRID == "#"  # (rows, cols) bool
START = tuple(int(v) for v in np.argwhere(_GRID == "S")[0])
GOAL = tuple(int(v) for v in np.argwhere(_GRID == "G")[0])


def _free(row: int, col: int) -> bool:
    return 0 <= row < N_ROWS and 0 <= col < N_COLS and not OBSTACLES[row, col]


def _step_cell(cell: tuple[int, int], action: int, push: int) -> tuple[tuple[int, int], float]:
    """The cell after ``action`` and an upward push of ``push`` cells, and the reward."""
    row, col = cell
    d_row, d_col = MOVES[action]
    reward = 0.0
    if _free(row + d_row, col + d_col):
        row, col = row + d_row, col + d_col
    else:
        reward += BUMP_REWARD
    for _ in range(push):
        if not _free(row - 1, col):
            break
        row -= 1
    if (row, col) == GOAL:
        reward += GOAL_REWARD
    return (row, col), reward


@functools.lru_cache(maxsize=None)
def _cached_step(cell: tuple[int, int], action: int, push: int) -> tuple[tuple[int, int], float]:
    """:func:`_step_cell`, remembered: a pure function of at most 100 x 4 x 4 arguments,
    and the environment's step is the hot path of every loop over it."""
    return _step_cell(cell, action, push)


def free_cells() -> np.ndarray:
    """(S, 2) int64: every cell that is not an obstacle, row-major, the goal included."""
    return np.argwhere(~OBSTACLES).astype(np.int64)


def cell_indices(states: np.ndarray) -> np.ndarray:
    """(N, 2) states ``[row, col]`` -> (N,) their rows in :func:`free_cells`.

    Raises ValueError for a state that is off the grid, not integer-valued or
    an obstacle.
    """
    s = np.asarray(states, dtype=np.float64).reshape(-1, 2)
    cells = s.astype(np.int64)
    inside = np.all(cells == s, axis=1) & np.all((cells >= 0) & (cells < [N_ROWS, N_COLS]), axis=1)
    if not np.all(inside):
        raise ValueError(
            f"gridworld states must be integer cells inside the {N_ROWS}x{N_COLS} grid, got {s[~inside][0]}"
        )
    if np.any(OBSTACLES[cells[:, 0], cells[:, 1]]):
        raise ValueError(f"gridworld state {s[OBSTACLES[cells[:, 0], cells[:, 1]]][0]} is an obstacle")
    index = np.full((N_ROWS, N_COLS), -1, dtype=np.int64)
    free = free_cells()
    index[free[:, 0], free[:, 1]] = np.arange(len(free))
    return index[cells[:, 0], cells[:, 1]]


def transition_model(windy: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The deterministic model over the free cells, for exact Q-iteration.

    Returns ``(next_state, reward, absorbing, cells)``: ``next_state`` (S, A)
    int64 indices into ``cells``; ``reward`` (S, A) float64; ``absorbing``
    (S, A) bool, True where the step ends on the goal; ``cells`` (S, 2) int64
    ``[row, col]`` (:func:`free_cells`). The goal's own row stays on the goal
    with reward 0 and ``absorbing`` True (an episode never continues from it),
    so ``Q = reward + gamma * (~absorbing) * max(Q[next_state])`` is exact.
    """
    cells = free_cells()
    n_states, n_actions = len(cells), len(ACTIONS)
    next_cells = np.empty((n_states, n_actions, 2), dtype=np.int64)
    reward = np.zeros((n_states, n_actions))
    for i, (row, col) in enumerate(cells):
        for a in range(n_actions):
            if (row, col) == GOAL:
                next_cells[i, a] = GOAL
                continue
            push = int(WIND[col]) if windy else 0
            next_cells[i, a], reward[i, a] = _step_cell((int(row), int(col)), a, push)
    next_state = cell_indices(next_cells.reshape(-1, 2)).reshape(n_states, n_actions)
    goal_index = int(cell_indices(np.array([GOAL]))[0])
    absorbing = next_state == goal_index
    return next_state, reward, absorbing, cells


def _action_index(action: Any) -> int:
    if is_integer(action) and 0 <= action < len(ACTIONS):
        return int(action)  # the usual case, without the array checks below
    a = np.asarray(action)
    value = a.reshape(-1)[0] if a.size == 1 and np.issubdtype(a.dtype, np.number) else None
    if value is None or not np.isfinite(value) or value != int(value) or not 0 <= value < len(ACTIONS):
        raise ValueError(
            f"gridworld action must be one of {list(range(len(ACTIONS)))} ({', '.join(ACTION_NAMES)}), got {action!r}"
        )
    return int(value)


class GridWorld(dm_env.Environment):
    """The (windy) grid world as a ``dm_env.Environment``; see the module docstring."""

    def __init__(
        self,
        windy: bool,
        time_limit: int = DEFAULT_TIME_LIMIT,
        random: int | np.random.RandomState | None = None,
        random_start: bool = False,
        stochastic_wind: bool = False,
    ) -> None:
        integer("gridworld", "time_limit", time_limit, 1, unit=" (steps)")
        for name, flag in (("random_start", random_start), ("stochastic_wind", stochastic_wind)):
            if not isinstance(flag, (bool, np.bool_)):
                raise ValueError(f"gridworld {name} must be true or false, got {flag!r}")
        if stochastic_wind and not windy:
            raise ValueError("gridworld stochastic_wind needs windy=True (the plain task has no wind)")
        self.windy = bool(windy)
        self.time_limit = int(time_limit)
        self.random_start = bool(random_start)
        self.stochastic_wind = bool(stochastic_wind)
        # Same convention as dm_control's Task.random: a seed or a RandomState.
        self.random = random if isinstance(random, np.random.RandomState) else np.random.RandomState(random)
        self._cell = START
        self._steps = 0
        self._reset_next_step = True

    def _observation(self) -> collections.OrderedDict:
        return collections.OrderedDict(state=self.state_vector())

    def reset(self) -> dm_env.TimeStep:
        if self.random_start:
            cells = free_cells()
            cells = cells[~np.all(cells == GOAL, axis=1)]
            self._cell = tuple(int(v) for v in cells[self.random.randint(len(cells))])
        else:
            self._cell = START
        self._steps = 0
        self._reset_next_step = False
        return dm_env.restart(self._observation())

    def _push(self, col: int) -> int:
        push = int(WIND[col]) if self.windy else 0
        if self.stochastic_wind and push > 0:
            push += int(self.random.randint(-1, 2))
        return push

    def step(self, action: Any) -> dm_env.TimeStep:
        if self._reset_next_step:
            return self.reset()
        a = _action_index(action)
        self._cell, reward = _cached_step(self._cell, a, self._push(self._cell[1]))
        self._steps += 1
        if self._cell == GOAL:
            self._reset_next_step = True
            return dm_env.termination(reward, self._observation())
        if self._steps >= self.time_limit:
            self._reset_next_step = True
            return dm_env.truncation(reward, self._observation())
        return dm_env.transition(reward, self._observation())

    def observation_spec(self) -> collections.OrderedDict:
        return collections.OrderedDict(
            state=specs.BoundedArray(
                (2,), np.float64, minimum=[0.0, 0.0], maximum=[N_ROWS - 1.0, N_COLS - 1.0], name="state"
            )
        )

    def action_spec(self) -> specs.DiscreteArray:
        return specs.DiscreteArray(len(ACTIONS), name="action")

    def state_vector(self) -> np.ndarray:
        """``[row, col]`` of the agent (float64)."""
        return np.array(self._cell, dtype=np.float64)

    def set_state_vector(self, state: np.ndarray) -> None:
        """Puts the agent on a free cell other than the goal (call after ``reset``)."""
        s = common.as_state(state, 2, __name__)
        cell_indices(s[None])  # raises for an obstacle or a cell off the grid
        cell = (int(s[0]), int(s[1]))
        if cell == GOAL:
            raise ValueError(f"gridworld state {s} is the goal, which ends the episode; choose another free cell")
        self._cell = cell

    @property
    def title(self) -> str:
        """What the renderer labels this task."""
        return "windy grid world" if self.windy else "grid world"

    def painter(self, width: int, height: int) -> Callable[[np.ndarray], np.ndarray]:
        """A function drawing the grid with the agent at ``state`` as a (height, width, 3) uint8 image.

        Free cells, obstacles, the wind band (windy task, one chevron per cell of
        push), start, goal and the agent; the static part is drawn once.
        """
        from PIL import Image, ImageDraw, ImageFont

        band = max(11, round(height / 30)) + 2 * max(4, round(height / 90)) + 4  # room for label strips
        cell = max(2, min((width - 8) // N_COLS, (height - 2 * band) // N_ROWS))
        x0, y0 = (width - cell * N_COLS) // 2, (height - cell * N_ROWS) // 2
        canvas = Image.new("RGB", (width, height), (46, 56, 72))
        draw = ImageDraw.Draw(canvas)
        wind = WIND if self.windy else np.zeros(N_COLS, dtype=int)
        font = ImageFont.load_default(size=max(9, cell // 2))

        def box(row: int, col: int, inset: int = 0) -> tuple[int, int, int, int]:
            return (
                x0 + col * cell + inset,
                y0 + row * cell + inset,
                x0 + (col + 1) * cell - 1 - inset,
                y0 + (row + 1) * cell - 1 - inset,
            )

        for row in range(N_ROWS):
            for col in range(N_COLS):
                if OBSTACLES[row, col]:
                    fill = (70, 70, 78)
                elif wind[col] > 0:
                    fill = (205, 225, 250) if wind[col] == 1 else (160, 195, 240)
                else:
                    fill = (236, 236, 232)
                draw.rectangle(box(row, col), fill=fill, outline=(150, 150, 150))
                if wind[col] > 0 and not OBSTACLES[row, col]:
                    cx = x0 + col * cell + cell // 2
                    for i in range(int(wind[col])):
                        cy = y0 + row * cell + cell // 4 + i * cell // 4
                        half = max(2, cell // 8)
                        draw.line(
                            [(cx - half, cy + half), (cx, cy), (cx + half, cy + half)],
                            fill=(60, 100, 170),
                            width=max(1, cell // 20),
                        )
        for (row, col), fill, text in ((START, (255, 236, 170), "S"), (GOAL, (120, 200, 120), "G")):
            x_lo, y_lo, x_hi, y_hi = box(row, col)
            draw.rectangle((x_lo, y_lo, x_hi, y_hi), fill=fill, outline=(150, 150, 150))
            draw.text(((x_lo + x_hi) / 2, (y_lo + y_hi) / 2), text, font=font, fill=(40, 40, 40), anchor="mm")
        background = np.array(canvas)

        def show(state: np.ndarray) -> np.ndarray:
            row, col = (int(v) for v in free_cells()[cell_indices(np.asarray(state)[None])[0]])
            image = Image.fromarray(background)
            ImageDraw.Draw(image).ellipse(
                box(row, col, inset=max(1, cell // 6)), fill=(230, 90, 40), outline=(120, 40, 10)
            )
            return np.array(image)

        return show


def _check_environment_kwargs(environment_kwargs: dict[str, Any] | None) -> None:
    if environment_kwargs:
        raise ValueError(
            f"gridworld takes no environment_kwargs (it is not a dm_control environment), "
            f"got {sorted(environment_kwargs)}; valid: []"
        )


def plain(
    time_limit: int = DEFAULT_TIME_LIMIT,
    random: int | np.random.RandomState | None = None,
    environment_kwargs: dict[str, Any] | None = None,
    random_start: bool = False,
) -> GridWorld:
    """The grid world without wind (the paper's source task)."""
    _check_environment_kwargs(environment_kwargs)
    return GridWorld(windy=False, time_limit=time_limit, random=random, random_start=random_start)


def windy(
    time_limit: int = DEFAULT_TIME_LIMIT,
    random: int | np.random.RandomState | None = None,
    environment_kwargs: dict[str, Any] | None = None,
    random_start: bool = False,
    stochastic_wind: bool = False,
) -> GridWorld:
    """The windy grid world (the paper's target task)."""
    _check_environment_kwargs(environment_kwargs)
    return GridWorld(
        windy=True,
        time_limit=time_limit,
        random=random,
        random_start=random_start,
        stochastic_wind=stochastic_wind,
    )


TASKS = {"plain": plain, "windy": windy}


def describe(task: str, stochastic_wind: bool = False, **_: Any) -> TaskDescription:
    """The grid world's static facts (see ``tatl_mj.description``).

    Actions are indices; learners see each as its move [d_row, d_col]. The
    exact model is known unless the wind is stochastic.
    """
    windy = task == "windy"
    return TaskDescription(
        domain="gridworld",
        task=task,
        dynamics_version=DYNAMICS_VERSION,
        state_names=("row", "col"),
        periodic=(False, False),
        action_values=MOVES.astype(np.float64),
        discrete=True,
        control_timestep=None,
        state_low=np.zeros(2),
        state_high=np.array([N_ROWS - 1.0, N_COLS - 1.0]),
        known_model=None if stochastic_wind else functools.partial(transition_model, windy=windy),
        transition_reward=transition_reward,
        transition_absorbing=reached_goal,
    )


def transition_reward(states: np.ndarray, actions: np.ndarray, next_states: np.ndarray) -> np.ndarray:
    """(N,) rewards of steps ``states`` --``actions``--> ``next_states`` (cells, rounded):
    -1 where the agent's own move is blocked, +10 where the step ends on the goal."""
    cells = np.rint(np.asarray(states, dtype=np.float64)).astype(np.int64).reshape(-1, 2)
    moved = cells + MOVES[np.asarray(actions, dtype=np.int64)]
    row, col = moved[:, 0], moved[:, 1]
    inside = (row >= 0) & (row < N_ROWS) & (col >= 0) & (col < N_COLS)
    blocked = ~inside  # as _free, for all steps at once
    blocked[inside] = OBSTACLES[row[inside], col[inside]]
    return np.where(blocked, BUMP_REWARD, 0.0) + np.where(reached_goal(next_states), GOAL_REWARD, 0.0)


def reached_goal(states: np.ndarray) -> np.ndarray:
    """(N,) whether each state (rounded to its cell) is the goal."""
    return np.all(np.rint(np.asarray(states, dtype=np.float64)).reshape(-1, 2) == GOAL, axis=1)
