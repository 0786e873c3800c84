"""One side of an experiment (its source or target task) as data: its description, a
uniformly random policy, its random-policy and one-step transitions, and the reward and
end condition that score a step (``target_reward``)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from tatl_mj import sampling, suite
from tatl_mj.description import TaskDescription
from tatl_mj.experiments.spec import Side
from tatl_mj.transitions import Transitions


def random_transitions(side: Side, n: int, seed: int) -> Transitions:
    """``n`` random-policy transitions of one side, as its spec's ``data`` says."""
    if side.data.sampling == "episodes":
        return sampling.collect(
            side.domain,
            side.task,
            n,
            seed,
            task_kwargs=side.task_kwargs,
            max_episode_steps=side.data.episode_steps,
        )
    rng = np.random.default_rng(seed)
    low, high = np.asarray(side.data.state_low), np.asarray(side.data.state_high)
    states = rng.uniform(low, high, size=(n, len(low)))
    return one_step(side, states, rng.integers(description_of(side).n_actions, size=n))


def one_step(side: Side, states: np.ndarray, actions: np.ndarray, reward: Callable | None = None) -> Transitions:
    """One-step transitions of one side's real simulator from ``states`` under action indices
    ``actions``, scored by its own reward and end condition (``reward``: ``target_reward(side)``)."""
    reward = target_reward(side) if reward is None else reward
    if reward is None:
        raise ValueError(f"{side.domain}/{side.task} has no reward to score one-step transitions with")
    next_states = sampling.step_from(side.domain, side.task, states, actions, task_kwargs=side.task_kwargs)
    rewards, absorbing = reward(states, actions, next_states)
    return Transitions(states, actions, rewards, next_states, absorbing, np.ones(len(states), dtype=bool))


def description_of(side: Side) -> TaskDescription:
    """The description of one side's task (``suite.describe``)."""
    return suite.describe(side.domain, side.task, side.task_kwargs)


def random_policy(side: Side, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """A uniformly random policy over the task's discrete action set (batched):
    actuator values, or indices for a task that takes indices."""
    description = description_of(side)
    actions = np.arange(description.n_actions) if description.discrete else description.action_values
    rng = np.random.default_rng(seed)
    return lambda states: actions[rng.integers(len(actions), size=len(states))]


def target_reward(target: Side) -> Callable | None:
    """The target task's reward and end condition of a step, (s, a, s') -> (rewards, absorbing), or None.

    The description's ``transition_reward`` where the reward depends on the step
    (the grid world's bumps), else the task's ``batch_reward`` of the next state.
    """
    description = description_of(target)
    if description.transition_reward is not None and description.transition_absorbing is not None:
        step_reward, absorbing = description.transition_reward, description.transition_absorbing
    else:
        task = getattr(suite.load(target.domain, target.task, task_kwargs=target.task_kwargs), "task", None)
        if not hasattr(task, "batch_reward"):
            return None
        step_reward = lambda states, actions, next_states: task.batch_reward(next_states)  # noqa: E731
        absorbing = task.batch_absorbing

    def reward(states: np.ndarray, actions: np.ndarray, next_states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.asarray(step_reward(states, actions, next_states), dtype=np.float64),
            np.asarray(absorbing(next_states), dtype=bool),
        )

    return reward
