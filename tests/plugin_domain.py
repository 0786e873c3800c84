"""A user's own domain, as a spec names it: ``domain = "plugin_domain:point_mass"``.

A one-dimensional point mass on a rail (state [x (m), x_dot (m/s)], force
-1, 0, +1 N), with a ``reach`` task (reward -x^2, start uniform in +-1 m at
rest) and ``reach_flipped`` (the actuator's sign reversed). Nothing in the
installed package knows it: the runner imports it by its path, in the process
that loads the spec and in every worker.
"""

import functools
import types

import numpy as np

from tatl_mj.description import TaskDescription
from tatl_mj.suite import common

XML = """
<mujoco model="point_mass">
  <option timestep="0.01" integrator="RK4"/>
  <worldbody>
    <body name="mass"><joint name="x" type="slide" axis="1 0 0" damping="0.1"/>
      <geom type="sphere" size=".05" mass="1"/></body>
  </worldbody>
  <actuator><motor name="force" joint="x" gear="GEAR" ctrllimited="true" ctrlrange="-1 1"/></actuator>
</mujoco>
"""
ACTIONS = np.array([[-1.0], [0.0], [1.0]])
CONTROL_TIMESTEP = 0.05


class Physics(common.StatePhysics):
    STATE_SIZE = 2

    def states_from(self, qpos, qvel):
        return np.concatenate([qpos, qvel], axis=1)

    def qpos_qvel_from(self, states):
        states = np.asarray(states, np.float64)
        return states[:, :1].copy(), states[:, 1:].copy()


class Task(common.StateTask):
    def start_configurations(self, physics, n):
        return self.random.uniform(-1.0, 1.0, size=(n, 1)), np.zeros((n, 1))

    def batch_reward(self, states):
        return -(np.asarray(states)[:, 0] ** 2)


def reach(gear=1.0, time_limit=5.0, random=None, environment_kwargs=None):
    physics = Physics.from_xml_string(XML.replace("GEAR", str(gear)))
    return common.Environment(
        physics,
        Task(random=random),
        time_limit=time_limit,
        control_timestep=CONTROL_TIMESTEP,
        **(environment_kwargs or {}),
    )


def describe(task, **_):
    return TaskDescription(
        domain="point_mass",
        task=task,
        state_names=("x", "x_dot"),
        periodic=(False, False),
        action_values=ACTIONS,
        discrete=False,
        control_timestep=CONTROL_TIMESTEP,
        action_low=np.array([-1.0]),
        action_high=np.array([1.0]),
        reset_low=np.array([-1.5, -2.0]),
        reset_high=np.array([1.5, 2.0]),
    )


point_mass = types.SimpleNamespace(
    ACTIONS=ACTIONS,
    TASKS={"reach": reach, "reach_flipped": functools.partial(reach, gear=-1.0)},
    describe=describe,
)

NOT_A_DOMAIN = types.SimpleNamespace(ACTIONS=ACTIONS, describe=describe)  # no TASKS


SPEC = """
name = "point_mass_to_flipped"
title = "A user's point mass to the same with its actuator flipped"
paper_claim = "(test) a user's domain and method, named by import path, run in a batch."

[source]
domain = "plugin_domain:point_mass"
task = "reach"
data = { sampling = "uniform", state_low = [-1.5, -2.0], state_high = [1.5, 2.0] }

[target]
domain = "plugin_domain:point_mass"
task = "reach_flipped"
data = { sampling = "episodes", episode_steps = 40 }

[source_learning]
features = { kind = "rbf", centers = 25, low = [-1.5, -2.0], high = [1.5, 2.0], sigma = [0.6, 0.8] }
gamma = 0.9
iterations = 5

[mapping]
kind = "identity"

[methods.ta-tl]
apprentice = { kind = "linear" }

[methods.rl]
features = { kind = "rbf", centers = 25, low = [-1.5, -2.0], high = [1.5, 2.0], sigma = [0.6, 0.8] }
gamma = 0.9
iterations = 5

[methods.zero]
method = "plugin_method:ZeroTorque"

[presets.tiny]
source_samples = 400
alignment_samples = 40
target_budgets = [40, 120]
evaluation_episodes = 2
evaluation_steps = 40
"""
