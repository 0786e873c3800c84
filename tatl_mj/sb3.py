"""Stable-Baselines3 over the native vector env: ``pip install 'tatl-mj[sb3]'``.

>>> from stable_baselines3 import SAC
>>> from stable_baselines3.common.vec_env import VecMonitor
>>> from tatl_mj import sb3
>>> envs = VecMonitor(sb3.vec_env("tatl_mj/PendulumSwingup-v2", num_envs=8))
>>> SAC("MlpPolicy", envs).learn(3_000)

SB3 cannot consume a Gymnasium ``VectorEnv``; :class:`Sb3VecEnv` is its
``VecEnv`` over :class:`tatl_mj.vector.TatlVectorEnv`, so all N simulations
step in one batched MuJoCo call. SB3's conventions, as its ``DummyVecEnv``
gives them over ``gym.make`` envs (tested equal, bit for bit): an env whose
episode ends is reset in the same step (``AutoresetMode.SAME_STEP``), its last
observation in ``info["terminal_observation"]`` and
``info["TimeLimit.truncated"]`` true where the time limit, not a terminal state,
ended it; rewards are float32; ``seed(s)`` seeds env i with ``s + i`` at the
next ``reset()``. Contexts pass through to the vector env
(``vec_env(id, n, contexts=[...])`` or ``contexts=ContextSampler(...)``,
``context_in_observation=True``); each env's ``info["context"]`` holds its own
(that of the observation returned, so a new episode's after an autoreset).
The N envs are one batch, not N objects: ``get_attr``, ``set_attr`` and
``env_method`` reach the vector env, once for every index asked. Wrap it in SB3's ``VecMonitor`` for episode statistics.

A saved model scored on a spec's conditions (``tatl evaluate SPEC --policy model.zip``):
:func:`load_model` reads it back with the algorithm its policy belongs to, and
:func:`model_policy` turns its ``predict(observations, deterministic=True)`` into a
tatl policy, its actions mapped to actuator values as the ids' ``step`` maps them
(``tatl_mj.gym.batch_actuator_values``).

Stable-Baselines3 and torch are optional (the ``sb3`` extra); only ``tatl evaluate``,
given a model file, imports this module.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

try:
    import torch
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
    from stable_baselines3.common.vec_env import VecEnv
except ImportError as error:  # the optional extra
    raise ImportError(f"tatl_mj.sb3 needs Stable-Baselines3: pip install 'tatl-mj[sb3]' ({error})") from None

import gymnasium
from gymnasium.vector import AutoresetMode

from tatl_mj import gym as tatl_gym  # registers the ids

ALGORITHMS = ("SAC", "TD3", "PPO", "A2C", "DDPG", "DQN")
"""Stable-Baselines3's algorithms a model file is read back with: the first whose policy classes
hold the model's (TD3 and DDPG, PPO and A2C share theirs, and predict alike)."""


def vec_env(env_id: str, num_envs: int, **kwargs: Any) -> Sb3VecEnv:
    """SB3's ``VecEnv`` of ``num_envs`` copies of ``env_id`` (a ``tatl_mj/...-v2`` id) in one batch;
    ``kwargs`` go to ``gym.make_vec`` (``task_kwargs``, ``contexts``, ``context_in_observation``,
    ``render_mode``, ``n_threads``, ...)."""
    if "autoreset_mode" in kwargs:
        raise ValueError("vec_env sets autoreset_mode itself (SB3 resets an ended env in the same step)")
    envs = gymnasium.make_vec(
        env_id,
        num_envs=num_envs,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.SAME_STEP,
        **kwargs,
    )
    return Sb3VecEnv(envs)


class Sb3VecEnv(VecEnv):
    """SB3's ``VecEnv`` over a Gymnasium vector env with ``SAME_STEP`` autoreset (see the module docstring)."""

    def __init__(self, envs: gymnasium.vector.VectorEnv) -> None:
        mode = envs.metadata.get("autoreset_mode")
        if mode is not AutoresetMode.SAME_STEP:
            raise ValueError(f"envs must reset an ended env in the same step (AutoresetMode.SAME_STEP), got {mode}")
        self.envs = envs
        self._actions: np.ndarray | None = None
        self._next_seeds: list[int | None] | None = None
        self._next_options: dict[str, Any] | None = None
        super().__init__(envs.num_envs, envs.single_observation_space, envs.single_action_space)

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seeds env i with ``seed + i`` at the next :meth:`reset`; returns those seeds."""
        if seed is None:
            return [None] * self.num_envs
        self._next_seeds = [int(seed) + i for i in range(self.num_envs)]
        return self._next_seeds

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """Options of the next :meth:`reset` (the vector env takes one dict for all envs)."""
        if isinstance(options, list):
            if any(o != options[0] for o in options):
                raise ValueError("options must be the same for every env: they reset as one batch")
            options = options[0] if options else None
        self._next_options = options or None

    def reset(self) -> np.ndarray:
        observations, info = self.envs.reset(seed=self._next_seeds, options=self._next_options)
        self._next_seeds, self._next_options = None, None
        self.reset_infos = [{} for _ in range(self.num_envs)]
        _add_contexts(self.reset_infos, info)
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        observations, rewards, terminated, truncated, info = self.envs.step(self._actions)
        dones = terminated | truncated
        cut = truncated & ~terminated  # ended by the time limit, not by a terminal state
        infos: list[dict[str, Any]] = [{"TimeLimit.truncated": bool(c)} for c in cut]
        for i in np.flatnonzero(dones):
            infos[i]["terminal_observation"] = info["final_obs"][i]
        if "diverged" in info:
            for i in np.flatnonzero(info["_diverged"]):
                infos[i]["diverged"] = info["diverged"][i]
        _add_contexts(infos, info)
        return observations, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        self.envs.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.envs.render()
        return [None] * self.num_envs if frames is None else list(frames)

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.envs, attr_name)] * self._count(indices)

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.envs, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        result = getattr(self.envs, method_name)(*method_args, **method_kwargs)
        return [result] * self._count(indices)

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        # The batched envs are simulations, not Gymnasium envs: no wrapper wraps one of them.
        return [False] * self._count(indices)

    def _count(self, indices: Any) -> int:
        """How many envs ``indices`` (None: all, an int, or a sequence) names."""
        if indices is None:
            return self.num_envs
        return 1 if isinstance(indices, (int, np.integer)) else len(list(indices))


def _add_contexts(infos: list[dict[str, Any]], info: dict[str, Any]) -> None:
    """Each env's context (key -> value) from the vector env's ``info["context"]`` (key -> values)."""
    if "context" in info:
        for i, env_info in enumerate(infos):
            env_info["context"] = {key: float(values[i]) for key, values in info["context"].items()}


class PeriodicFeatures(BaseFeaturesExtractor):
    """SB3's features extractor: each periodic coordinate of the observation (an angle, which jumps
    from pi to -pi) as its cosine and sine, the others as they are. It sits in the network, so a
    saved model takes the raw observation, the one ``tatl evaluate`` gives it:
    ``policy_kwargs={"features_extractor_class": PeriodicFeatures, "features_extractor_kwargs":
    {"periodic": suite.describe(domain, task).periodic}}``; the coordinates past ``periodic``'s
    end (an appended context) are not periodic."""

    def __init__(self, observation_space: gymnasium.spaces.Box, periodic: Sequence[bool]) -> None:
        (size,) = observation_space.shape
        mask = np.zeros(size, dtype=bool)
        mask[: len(periodic)] = np.asarray(periodic, dtype=bool)
        super().__init__(observation_space, features_dim=int(size + mask.sum()))
        self.angles, self.others = np.flatnonzero(mask).tolist(), np.flatnonzero(~mask).tolist()

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        angles = observations[:, self.angles]
        return torch.cat([torch.cos(angles), torch.sin(angles), observations[:, self.others]], dim=1)


def file_sha256(path: str | Path) -> str:
    """The SHA-256 of a file's bytes (what ``tatl evaluate`` records of a model file)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def load_model(path: str | Path) -> Any:
    """The Stable-Baselines3 model saved at ``path`` (``model.save``), on the CPU; ValueError in
    one line for a file that is not one, or whose policy no algorithm of ``ALGORITHMS`` has."""
    import stable_baselines3
    from stable_baselines3.common.save_util import load_from_zip_file

    try:
        data, _, _ = load_from_zip_file(path, device="cpu")
    except Exception as error:  # noqa: BLE001 - a file that is not a model fails in many ways
        raise ValueError(f"{path}: not a Stable-Baselines3 model file ({type(error).__name__}: {error})") from None
    policy_class = (data or {}).get("policy_class")
    for name in ALGORITHMS:
        algorithm = getattr(stable_baselines3, name)
        if policy_class in algorithm.policy_aliases.values():
            return algorithm.load(path, device="cpu")
    raise ValueError(f"{path}: its policy {policy_class!r} is none of Stable-Baselines3's {', '.join(ALGORITHMS)}")


def model_policy(
    model: Any, domain: str, task: str, task_kwargs: dict[str, Any] | None, observation_size: int
) -> Callable[[np.ndarray], np.ndarray]:
    """``model``'s deterministic actions as a tatl policy of ``domain/task``: states (N, d) ->
    actuator values (N, m). Its observations must be ``observation_size`` long (the state, or the
    state and context); its action space one of the ids' (:func:`tatl_mj.gym.action_scale`).
    ValueError in one line before any episode otherwise."""
    from tatl_mj import suite

    shape = tuple(model.observation_space.shape or ())
    if shape != (observation_size,):
        raise ValueError(
            f"the model observes shape {shape}, but {domain}/{task} gives ({observation_size},) here "
            "(--context-in-observation appends the condition's context to the state)"
        )
    space = model.action_space
    if not isinstance(space, gymnasium.spaces.Box):
        raise ValueError(f"the model acts in {space}; {domain}/{task} takes a Box of actuator values")
    env = suite.load(domain, task, task_kwargs=task_kwargs)
    scale = tatl_gym.action_scale(space, tatl_gym.actuator_limit(env, f"{domain}/{task}"))

    def decide(states: np.ndarray) -> np.ndarray:
        actions, _ = model.predict(np.asarray(states, dtype=np.float64), deterministic=True)
        return tatl_gym.batch_actuator_values(actions, space, scale)

    return decide
