"""Batched transitions at MuJoCo's speed: many episodes stepped in lockstep in C threads.

Learners eat batches of transitions; a Python loop over ``env.step`` spends most
of its time outside the physics. Here every parallel episode is one simulation
of a ``mujoco.batch.Batch`` (:mod:`.simulator`), and task logic runs
vectorised through the domain contract (``states_from``, ``batch_reward``,
``batch_absorbing``, ``controls``), so the transitions are bit-identical to
stepping the dm_control environment.

- :func:`collect`: transitions of whole episodes (:mod:`.collection`, scheduled
  by :mod:`.schedule`); :func:`policy_transitions`: the same loop on a given
  environment.
- :func:`evaluate`, :func:`evaluate_policies`, :func:`start_states`: a policy's returns,
  or several policies' in one lockstep batch (:mod:`.evaluation`).
- :func:`step_from`, :func:`step_values_from`: one-step queries (:mod:`.queries`).
- :func:`is_batched`, :func:`physics_substeps`: which path a task takes, and
  the MuJoCo substeps taken so far; :func:`mujoco_threads`: how many threads
  the calls not given ``n_threads`` step on.

Seeding: ``collect``/``evaluate`` with ``seed`` draw start states from the
successive resets of the task created with ``task_kwargs["random"] = seed``.
``collect``'s random actions and their controls' noise are each episode's own
draws from ``np.random.default_rng(seed)`` and generators derived from it;
so is ``evaluate``'s controls' noise. In ``collect`` with a policy, the task's
``random`` feeds ``Task.controls`` (rider noise) in lockstep order. Without
control noise, a collection is exactly a plain loop over that environment with
its actions.
"""

from tatl_mj.policy import StatePolicy
from tatl_mj.sampling.checks import IndexPolicy, ValuePolicy
from tatl_mj.sampling.collection import collect, policy_transitions
from tatl_mj.sampling.evaluation import Joint, Visitor, evaluate, evaluate_policies, one_by_one, start_states
from tatl_mj.sampling.queries import step_from, step_values_from
from tatl_mj.sampling.schedule import DEFAULT_PARALLEL
from tatl_mj.sampling.simulator import is_batched, mujoco_threads, physics_substeps
from tatl_mj.sampling.timing import time_rollout

__all__ = [
    "DEFAULT_PARALLEL",
    "IndexPolicy",
    "StatePolicy",
    "ValuePolicy",
    "collect",
    "evaluate",
    "evaluate_policies",
    "Joint",
    "Visitor",
    "is_batched",
    "mujoco_threads",
    "one_by_one",
    "physics_substeps",
    "policy_transitions",
    "start_states",
    "step_from",
    "step_values_from",
    "time_rollout",
]
