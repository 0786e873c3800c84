"""`tatl list`: the suite's tasks, with a random-policy episode of each on request."""

from __future__ import annotations

import argparse
from typing import Any


def add_list(sub: Any) -> None:
    p = sub.add_parser("list", help="list the suite's tasks")
    p.add_argument("--episode", action="store_true", help="also run one random-policy episode of each")
    p.add_argument("--max-steps", type=int, default=1000, help="cap on that episode's steps")
    p.set_defaults(func=_list)


def _list(args: argparse.Namespace) -> int:
    from tatl_mj import suite

    for domain, task in suite.ALL_TASKS:
        env = suite.load(domain, task, task_kwargs={"random": 0})
        state = env.reset().observation["state"]
        actions = suite.action_set(domain)
        line = f"{domain}/{task}: state dim {state.shape[0]}, actions {actions.ravel().tolist()}"
        if args.episode:
            import numpy as np

            rng = np.random.default_rng(0)
            total, steps, timestep = 0.0, 0, env.reset()
            while not timestep.last() and steps < args.max_steps:
                timestep = env.step(actions[rng.integers(len(actions))])
                total += timestep.reward
                steps += 1
            line += f", random-policy return {total:.3f} over {steps} steps"
        print(line)
        close = getattr(env, "close", None)
        if close:
            close()
    return 0
