"""``tatl bench``: how fast tatl-mj collects, learns and renders on this machine.

One process, one measurement after another, for the first task of every domain
with physics (cart-pole, pendulum, mountain car and bicycle today); each
stepping figure is the fastest of ``--repeats`` runs taken in turn with the
others, since a shared machine's speed drifts by up to 2x within seconds:

- ``dm_control``: a Python loop over the environment's ``step`` with random
  actions (resetting at episode ends), the way a hand-written collector works,
  also given as simulated seconds per wall-clock second (``real_time_factor``);
- ``dm_control_floor``: the same loop over the same physics with a task that
  does nothing: dm_control's own cost per step, the most any dm_control loop of
  this physics can reach here;
- ``sampler``: :func:`tatl_mj.sampling.collect`, whole random episodes in
  lockstep on ``--threads`` MuJoCo threads, task logic included;
- ``rollout``: raw ``mujoco.rollout`` of the bare model, open loop, no task
  logic and no episode ends: the physical limit here;
- ``gymnasium``: the peer a user would otherwise pick, Gymnasium's own Python
  loop (``gymnasium.make``, random actions, reset at episode ends) for
  CartPole-v1, Pendulum-v1 and MountainCar-v0; skipped with a note when
  gymnasium is not installed.

Then the Gymnasium vector envs of every physics task of those domains
(``--vector-tasks``), ``--vector-envs`` (64) copies stepped with random actions
(env-steps per second, autoreset included): ``vector``, the native one
(``gym.make_vec(..., vectorization_mode="vector_entry_point")``, on ``--threads``
MuJoCo threads), beside ``sync_vector`` (Gymnasium's ``SyncVectorEnv`` over the
same id) and ``rollout`` (raw ``mujoco.rollout`` of the same task, as above).

Then Fitted Q-Iteration on 100 000 cart-pole transitions, 640x480 frames per
second from the tracking camera (under the current ``MUJOCO_GL``), and the peak
memory of collecting 10^6 cart-pole transitions. ``--json`` prints one JSON
object per line; the last one is the summary.

The package splits the command by its jobs: ``command`` (the options, their
checks and the run), ``machine`` (what the figures were taken on), ``stepping``
(dm_control, the sampler, Gymnasium's loop), ``vector`` (the vector envs),
``work`` (FQI, rendering, memory), ``timing`` (the fastest of repeats) and
``report`` (the printed table).
"""

from __future__ import annotations

from tatl_mj.bench.command import add_arguments, run

__all__ = ["add_arguments", "run"]
