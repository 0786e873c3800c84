"""No GL library until a frame is drawn (tatl_mj.gl), read from /proc/self/maps in child processes.

Each child runs with ``-W error`` and without a display, so any warning (glfw's about
DISPLAY among them) fails it; the parent reads what it printed: the GL libraries mapped
before and after its first frame.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tatl_mj import gl, suite

REPO = Path(__file__).resolve().parents[1]

# What a GL backend maps: the EGL and OSMesa front ends, libGL, and Mesa's drivers and LLVM.
GL_LIBRARY_PARTS = ("libEGL", "libOSMesa", "libGL", "libLLVM", "swrast_dri", "libgallium")

MAPPED = """\
def mapped():
    with open("/proc/self/maps") as maps:
        names = {line.split()[-1].rsplit("/", 1)[-1] for line in maps if "/" in line}
    return sorted(n for n in names if any(part in n for part in %r))
""" % (GL_LIBRARY_PARTS,)

# Imports every module a user meets, loads and steps every physics task (and its Gymnasium
# id, made with a render mode), collects a batch: no GL so far. Then one frame.
IMPORT_STEP_DRAW = (
    MAPPED
    + """\
import json, sys
import numpy as np
import tatl_mj, tatl_mj.suite, tatl_mj.gym, tatl_mj.sampling, tatl_mj.render
import gymnasium
from tatl_mj import gl, sampling, suite
for domain, task in tatl_mj.gym.PHYSICS_TASKS:
    env = suite.load(domain, task, task_kwargs={"random": 0})
    env.reset()
    env.step(suite.action_set(domain)[0])
for env_id in tatl_mj.gym.GYM_IDS:
    env = gymnasium.make(env_id, render_mode="rgb_array", width=32, height=24)
    env.reset(seed=0)
    env.step(env.action_space.sample())
sampling.collect("pendulum", "swingup", 100, seed=0)
before = mapped()
frame = env.render()
print(json.dumps({"before": before, "after": mapped(), "backend": gl.loaded_backend(),
                  "frame": list(frame.shape), "std": float(frame.std())}))
"""
)


def _child_env(**overrides: str) -> dict[str, str]:
    """This environment without a display or a GL choice, plus ``overrides``."""
    drop = ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY", "WAYLAND_DISPLAY")
    env = {k: v for k, v in os.environ.items() if k not in drop}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return {**env, **overrides}


def _run(script: str, env: dict[str, str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-W", "error", "-c", script],
        env=env,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.parametrize("mujoco_gl", [None, "egl", "osmesa"], ids=["unset", "egl", "osmesa"])
def test_nothing_gl_is_loaded_or_printed_until_the_first_frame(mujoco_gl):
    env = _child_env(**({} if mujoco_gl is None else {"MUJOCO_GL": mujoco_gl}))
    child = _run(IMPORT_STEP_DRAW, env)
    assert child.returncode == 0, child.stderr[-3000:]
    assert child.stderr == "", child.stderr  # no warning at all: glfw's DISPLAY one included
    report = json.loads(child.stdout)
    assert report["before"] == [], report  # imports, loads, steps, make(render_mode=...), collect
    # The first frame chose and loaded the backend (unset: EGL works here, so EGL).
    assert report["backend"] == (mujoco_gl or "egl")
    library = {"egl": "libEGL", "osmesa": "libOSMesa"}[report["backend"]]
    assert any(name.startswith(library) for name in report["after"]), report
    assert report["frame"] == [24, 32, 3] and report["std"] > 5


TRITON_AFTER = (
    MAPPED
    + """\
import sys
import gymnasium, tatl_mj.gym
from tatl_mj import gl
if sys.argv[1] == "triton-not-first":
    gl.LLVM_FIRST = ()  # the order a process without the guard would take
env = gymnasium.make("tatl_mj/PendulumSwingup-v2", render_mode="rgb_array", width=32, height=24)
env.reset(seed=0)
env.step(env.action_space.sample())
if sys.argv[1] != "no-frame":
    env.render()
print(" ".join(mapped()), flush=True)
import triton
print("triton imported")
"""
)


@pytest.mark.parametrize("order", ["no-frame", "frame-first", "triton-not-first"])
def test_triton_is_imported_after_our_import_and_after_a_frame(order):
    # triton carries its own LLVM (torch's optimizers import it); loaded after Mesa's it crashes.
    pytest.importorskip("triton")
    child = subprocess.run(
        [sys.executable, "-c", TRITON_AFTER, order],
        env=_child_env(),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    mapped = child.stdout.splitlines()[0].split() if child.stdout else []
    if order == "no-frame":
        assert mapped == []
    if order != "triton-not-first":
        assert child.returncode == 0, child.stderr[-3000:]
        assert child.stdout.splitlines()[-1] == "triton imported"
        return
    # The control: without the first frame importing triton, Mesa's LLVM comes first and the
    # process dies on `import triton` (the clash this module prevents; a GPU driver has no LLVM).
    if not any("LLVM" in name for name in mapped):
        pytest.skip(f"this GL backend maps no LLVM ({mapped}): nothing to clash with")
    assert child.returncode == -signal.SIGSEGV, (child.returncode, child.stderr[-2000:])


def test_without_egl_the_first_frame_falls_back_to_osmesa(tmp_path):
    # MUJOCO_GL unset: the first frame probes EGL (here a library that does not load), then OSMesa.
    fake = tmp_path / "fake"
    fake.mkdir()
    for suffix in [""] + [f".{i}" for i in range(10)]:
        (fake / f"libEGL.so{suffix}").write_bytes(b"not a shared library")
    script = (
        "from tatl_mj import gl, suite\n"
        "e = suite.load('cartpole', 'balance', task_kwargs={'random': 0}); e.reset()\n"
        "shape = e.physics.render(24, 32).shape\n"
        "print(gl.loaded_backend(), shape)\n"
    )
    child = _run(script, _child_env(LD_LIBRARY_PATH=str(fake)))
    assert child.returncode == 0, child.stderr[-3000:]
    assert child.stdout.split() == ["osmesa", "(24,", "32,", "3)"]
    assert child.stderr == ""


def test_the_backend_is_fixed_once_a_frame_is_drawn():
    # This process draws with conftest's MUJOCO_GL (egl) once a frame is drawn.
    env = suite.load("cartpole", "balance", task_kwargs={"random": 0})
    env.reset()
    assert env.physics.render(24, 32).shape == (24, 32, 3)
    current = gl.loaded_backend()
    assert current == os.environ["MUJOCO_GL"]
    other = "osmesa" if current == "egl" else "egl"
    environ = {"MUJOCO_GL": current, "PYOPENGL_PLATFORM": "wrong"}
    assert gl.select_backend(environ) == current
    assert environ["PYOPENGL_PLATFORM"] == current
    assert gl.select_backend({}) == current  # unset: the one already loaded, no probe
    with pytest.raises(gl.GLBackendError, match=f"already draws frames with the '{current}'"):
        gl.select_backend({"MUJOCO_GL": other})
    with pytest.raises(ValueError, match="MUJOCO_GL='Vulkan' is not a rendering backend"):
        gl.select_backend({"MUJOCO_GL": "Vulkan"})


def test_physics_render_names_what_it_does_not_draw():
    env = suite.load("pendulum", "swingup", task_kwargs={"random": 0})
    env.reset()
    with pytest.raises(ValueError, match=r"takes height, width and camera_id; got \['depth'\]"):
        env.physics.render(24, 32, depth=True)
    with pytest.raises(ValueError, match="width 4000 is more than the model's offscreen buffer"):
        env.physics.render(24, 4000)
    by_name = env.physics.render(24, 32, camera_id="tracking")
    by_id = env.physics.render(24, 32, camera_id=env.physics.model.name2id("tracking", "camera"))
    assert by_name.std() > 5 and (by_name == by_id).all()
    env.physics.free_canvases()
    assert (env.physics.render(24, 32, camera_id="tracking") == by_name).all()  # a new context, the same frame
