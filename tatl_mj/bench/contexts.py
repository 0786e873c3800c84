"""``tatl bench --contexts distinct|resample``: the native vector env with a context per env,
beside raw ``mujoco.rollout`` over the same per-env models.

- ``distinct``: each env its own context, drawn once from :data:`RANGES`;
- ``resample``: a ``ContextSampler`` over :data:`RANGES` draws a new context at
  each env's reset (domain randomisation).

The raw figure runs ``mujoco.rollout`` with one model per rollout: env i's
model as the vector env holds it after its first reset (for the time-varying
pendulum, the model of its first step), from its start state, with the
controls of random actions from the action set under its context.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tatl_mj.sampling.timing import timed_rollouts

RANGES: dict[str, dict[str, tuple[float, float]]] = {
    # The conditions the sweeps vary (tasks/sweeps/*.toml), and the masses and lengths about them.
    "cartpole/balance": {"pole_mass": (0.05, 0.3), "pole_half_length": (0.3, 0.8)},
    "mountain_car/climb": {"car_mass": (0.8, 1.2), "force": (4.5, 6.0)},
    "pendulum/swingup": {"mass": (0.5, 1.5), "length": (0.5, 1.5)},
    "pendulum/swingup_timevarying": {"amplitude": (0.0, 0.75), "mass": (1.0, 1.5), "length": (1.0, 1.5)},
    "pendulum/swingup_flipped": {"gain": (0.5, 2.0), "mass": (0.5, 1.5)},
    "bicycle/balance": {"cg_noise": (0.02, 0.25), "speed": (1.5, 2.778)},
}
MODES = ("distinct", "resample")


def contexts_for(domain: str, task: str, mode: str, num_envs: int, seed: int = 0) -> Any:
    """The ``contexts`` argument of ``mode``: ``num_envs`` drawn contexts, or the sampler."""
    from tatl_mj.suite import ContextSampler

    sampler = ContextSampler(RANGES[f"{domain}/{task}"], seed=seed)
    if mode == "resample":
        return sampler
    generator = np.random.default_rng(seed)
    return [sampler.sample(generator) for _ in range(num_envs)]


def time_rollout_contexts(
    domain: str, task: str, seconds: float, threads: int, num_envs: int, mode: str, seed: int = 0
) -> dict[str, Any]:
    """Raw ``mujoco.rollout`` over the per-env models of a vector env with ``mode``'s contexts."""
    import mujoco

    from tatl_mj import suite, vector

    envs = vector.TatlVectorEnv(domain, task, num_envs, contexts=contexts_for(domain, task, mode, num_envs, seed))
    envs.reset(seed=seed)
    batch, env = envs._batch, envs._env  # this package's own env: its per-simulation models and task
    models = [batch.get_model(i) for i in range(num_envs)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    starts = np.empty((num_envs, mujoco.mj_stateSize(models[0], spec)))
    actions = np.asarray(suite.action_set(domain), np.float64)
    controls = []
    for i, model in enumerate(models):
        data = batch.get_data(i)
        mujoco.mj_getState(model, data, starts[i], spec)
        envs._contexts.lend(i)  # type: ignore[union-attr]  # env i's task keys (e.g. the bicycle's speed)
        controls.append(env.task.controls(actions, env.task.random))
    table = np.stack(controls)  # (env, action, nu)
    n_sub = int(round(env.control_timestep() / env.physics.timestep()))
    timed = timed_rollouts(models, starts, table, n_sub, seconds, threads, np.random.default_rng(seed))
    envs.close()
    return {**timed, "contexts": mode}
