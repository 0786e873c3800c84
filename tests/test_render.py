"""Headless clips and GL backend selection (issue 7).

The backend is fixed per process, so clips under EGL and OSMesa and the broken
backends run in child processes; the rest runs in-process under the EGL backend
that conftest.py selects.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio_v2
import imageio.v3 as imageio_v3
import numpy as np
import pytest

from tatl_mj import render, suite
from tatl_mj.suite import gridworld

REPO = Path(__file__).resolve().parents[1]

# What `tatl render` does: choose the backend (a clear message, no traceback, on
# failure), then film a cart-pole pushed right at full force, 1 s at 12 fps.
CLIP_SCRIPT = """\
import sys
from tatl_mj import gl
try:
    backend = gl.select_backend()
except gl.GLBackendError as error:
    sys.exit(f"tatl render: {error}")
import numpy as np
from tatl_mj import render, suite
env = suite.load("cartpole", "balance", task_kwargs={"random": 0})
frames = render.render_episode(env, lambda s: np.array([[20.0]]), seconds=1.0,
                               width=160, height=120, fps=12, method_label="push")
render.write_clip(frames, sys.argv[1], fps=12)
print(backend)
"""


def _child_env(**overrides: str | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env.update({k: v for k, v in overrides.items() if v is not None})
    return env


def _fake_gl_libraries(directory: Path, *names: str) -> str:
    """Unloadable lib<name>.so* files that shadow the real ones through LD_LIBRARY_PATH."""
    for name in names:
        for suffix in [""] + [f".{i}" for i in range(10)]:
            (directory / f"lib{name}.so{suffix}").write_bytes(b"not a shared library")
    return str(directory)


def _start(args: list[str], env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, *args], env=env, cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


def test_clip_written_under_egl_and_osmesa(tmp_path):
    # Both children run at once: each is mostly process start-up.
    children = {
        backend: (
            tmp_path / f"{backend}.mp4",
            _start(
                ["-c", CLIP_SCRIPT, str(tmp_path / f"{backend}.mp4")],
                _child_env(MUJOCO_GL=backend, PYOPENGL_PLATFORM=backend),
            ),
        )
        for backend in ("egl", "osmesa")
    }
    for backend, (path, child) in children.items():
        stdout, stderr = child.communicate(timeout=120)
        assert child.returncode == 0, stderr
        assert stdout.strip() == backend
        assert "Traceback" not in stderr, stderr
        frames = np.stack(imageio_v2.mimread(path, format="FFMPEG", memtest=False))
        assert frames.shape == (12, 120, 160, 3)
        assert frames.std() > 10, "blank clip"
        # The pole tips over and the floor slides under the tracking camera.
        assert np.abs(frames[-1].astype(int) - frames[0].astype(int)).mean() > 2, "no motion"


@pytest.mark.parametrize(
    "overrides, fake, expected",
    [
        ({"MUJOCO_GL": "osmesa"}, ("OSMesa",), ["MUJOCO_GL=osmesa", "cannot load libOSMesa", "libosmesa6"]),
        ({}, ("EGL", "OSMesa"), ["tried egl, then osmesa", "cannot load libEGL", "cannot load libOSMesa"]),
        ({"MUJOCO_GL": "vulkan"}, (), ["MUJOCO_GL='vulkan'", "egl, osmesa, glfw"]),
    ],
    ids=["osmesa-missing", "all-missing", "bad-name"],
)
def test_broken_backend_fails_with_clear_message(tmp_path, overrides, fake, expected):
    env = _child_env(**overrides)
    if fake:
        env["LD_LIBRARY_PATH"] = _fake_gl_libraries(tmp_path, *fake)
    child = subprocess.run(
        [sys.executable, "-c", CLIP_SCRIPT, str(tmp_path / "x.mp4")],
        env=env,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert child.returncode != 0
    for text in expected:
        assert text in child.stderr, child.stderr
    assert "Traceback" not in child.stderr, child.stderr
    assert not (tmp_path / "x.mp4").exists()


def test_unset_backend_falls_back_to_osmesa_when_egl_is_missing(tmp_path):
    env = _child_env(LD_LIBRARY_PATH=_fake_gl_libraries(tmp_path, "EGL"))
    script = "import os; from tatl_mj import gl; print(gl.select_backend(), os.environ['PYOPENGL_PLATFORM'])"
    child = subprocess.run(
        [sys.executable, "-c", script], env=env, cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert child.returncode == 0, child.stderr
    assert child.stdout.split() == ["osmesa", "osmesa"]


# --- In-process rendering (EGL) -------------------------------------------------


def _cartpole(seed: int = 0):
    return suite.load("cartpole", "balance", task_kwargs={"random": seed})


def _lqr_like(states: np.ndarray) -> np.ndarray:
    return np.clip(states @ np.array([1.0, 1.6, 18.0, 3.0]), -20, 20)[:, None]


def test_frames_follow_the_simulation_clock():
    env = _cartpole()
    frames = render.render_episode(env, _lqr_like, seconds=1.0, fps=10, width=64, height=48)
    assert frames.shape == (10, 48, 64, 3) and frames.dtype == np.uint8
    # The last frame is due at 0.9 s: 45 control steps of 0.02 s, no more.
    assert env.physics.data.time == pytest.approx(0.9)


def _longest_hold(frames: np.ndarray) -> int:
    """The most consecutive identical frames."""
    longest = run = 1
    for a, b in zip(frames[:-1], frames[1:]):
        run = run + 1 if np.array_equal(a, b) else 1
        longest = max(longest, run)
    return longest


def test_episode_end_is_held_at_most_half_a_second_then_a_new_episode_starts():
    env = _cartpole()
    frames = render.render_episode(env, lambda s: np.array([[20.0]]), seconds=3.0, fps=10, width=64, height=48)
    assert frames.shape[0] == 30
    # Full force right topples the pole in well under a second, so several
    # episodes fit in 3 s; the end of each is on screen for 0.5 s (5 frames), no more.
    assert _longest_hold(frames) == 5
    assert env.physics.data.time < 1.0  # a later episode, restarted from time 0
    # Frames of the first episode, its held end, and the second episode moving again.
    first_end = next(i for i in range(26) if all(np.array_equal(frames[i], frames[i + j]) for j in range(5)))
    assert not np.array_equal(frames[first_end + 5], frames[first_end + 6])


def test_stop_mode_ends_the_clip_after_the_held_end():
    env = _cartpole()
    frames = render.render_episode(
        env, lambda s: np.array([[20.0]]), seconds=3.0, fps=10, width=64, height=48, on_end="stop"
    )
    ended_at = env.physics.data.time  # the episode's last step
    # Frames up to the first one at or after the end, then 4 more of the held end.
    assert frames.shape[0] == math.ceil(ended_at * 10 - 1e-9) + 1 + 4
    assert _longest_hold(frames) == 5 and np.array_equal(frames[-1], frames[-5])


def test_overlay_names_the_episode_and_why_the_last_one_ended():
    text = render._overlay_text(
        clock="t  0.40 s", method_label="ta-tl", episode_return=3.25, episode=2, previous_end="terminal state", ended=""
    )
    assert text == "t  0.40 s   ta-tl   return 3.2   episode 2 (episode 1: terminal state)"
    text = render._overlay_text(
        clock="step  16", method_label="", episode_return=-16.0, episode=1, previous_end="", ended="terminal state"
    )
    assert text == "step  16   return -16.0   episode 1   [terminal state]"


def test_overlay_is_drawn_where_promised():
    env = _cartpole()
    plain = render.render_episode(env, _lqr_like, seconds=0.1, fps=10, camera="fixed")
    env = _cartpole()
    env.reset()
    raw = env.physics.render(480, 640, camera_id="fixed")
    differs = np.any(plain[0] != raw, axis=2)
    # Two small dark strips with text, at the top left and bottom left; nothing else.
    assert differs[5:26, :100].all() and differs[452:472, :60].all()
    assert not differs[30:445].any() and not differs[:, 320:].any()


def test_side_by_side_shows_source_in_mapped_state():
    def mirror(state: np.ndarray) -> np.ndarray:
        return -state

    env, source_env = _cartpole(0), _cartpole(1)
    frames = render.render_episode(
        env, _lqr_like, seconds=0.5, fps=10, width=160, height=120, source=(source_env, mirror), camera="fixed"
    )
    assert frames.shape == (5, 120, 320, 3)
    # Redraw the source in the mirrored final target state, independently.
    check = _cartpole(2)
    check.reset()
    check.physics.set_state_vector(-env.physics.state_vector())
    expected = check.physics.render(120, 160, camera_id="fixed")
    right = frames[-1][:, 160:]
    body = slice(20, 90)  # between the label strips
    np.testing.assert_array_equal(right[body, 2:], expected[body, 2:])
    assert np.any(frames[-1][body, :160] != right[body])  # the target differs from its mirror


def test_bad_arguments_raise_value_errors():
    env = _cartpole()
    with pytest.raises(ValueError, match=r"camera 'nope'.*valid choices: \['fixed', 'tracking'\]"):
        render.render_episode(env, _lqr_like, seconds=0.1, camera="nope")
    with pytest.raises(ValueError, match=r"on_end must be one of \('reset', 'stop'\)"):
        render.render_episode(env, _lqr_like, seconds=0.1, on_end="freeze")
    with pytest.raises(ValueError, match="seconds must be a finite number > 0, got 0"):
        render.render_episode(env, _lqr_like, seconds=0)
    with pytest.raises(ValueError, match="width must be an integer"):
        render.render_episode(env, _lqr_like, seconds=0.1, width=640.5)
    with pytest.raises(ValueError, match="batch of one action"):
        render.render_episode(env, lambda s: np.zeros((2, 1)), seconds=0.1, width=32, height=24)


def test_write_clip_round_trips_and_rejects_bad_input(tmp_path):
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, size=(7, 31, 45, 3), dtype=np.uint8)
    mp4 = render.write_clip(frames, tmp_path / "odd.mp4", fps=7)
    decoded = np.stack(imageio_v2.mimread(mp4, format="FFMPEG", memtest=False))
    assert decoded.shape == (7, 32, 46, 3)  # padded to even for yuv420p
    ramp = np.repeat(np.linspace(0, 255, 45)[None, :, None], 31, axis=0).astype(np.uint8)
    moving = np.stack([np.repeat(np.roll(ramp, 9 * i, axis=1), 3, axis=2) for i in range(4)])
    gif = render.write_clip(moving, tmp_path / "a.gif", fps=5)
    decoded_gif = imageio_v3.imread(gif, index=None)[..., :3]
    assert decoded_gif.shape == (4, 31, 45, 3)
    assert np.abs(decoded_gif.astype(int) - moving).max() <= 8  # palette quantisation
    with pytest.raises(ValueError, match=r"extension must be one of \('.mp4', '.gif'\)"):
        render.write_clip(frames, tmp_path / "clip.avi", fps=7)
    with pytest.raises(ValueError, match=r"frames\[0\] must be an \(H, W, 3\) uint8"):
        render.write_clip(frames.astype(np.float32), tmp_path / "f.mp4", fps=7)
    with pytest.raises(ValueError, match="fps must be a finite number > 0, got 0"):
        render.write_clip(frames, tmp_path / "g.mp4", fps=0)


def _agent_centre(panel: np.ndarray) -> np.ndarray:
    """Pixel centroid (x, y) of the orange agent disc of a grid-world panel."""
    r, g, b = (panel[..., i].astype(int) for i in range(3))
    ys, xs = np.nonzero((r > 200) & (g < 120) & (b < 80))
    assert len(xs) > 20, "agent not drawn"
    return np.array([xs.mean(), ys.mean()])


def test_grid_world_is_filmed_beside_its_source():
    # The windy task's optimal policy by Q-iteration: 16 steps from S (5, 0) to G (5, 8).
    next_state, reward, absorbing, _ = gridworld.transition_model(windy=True)
    q = np.zeros(next_state.shape)
    for _ in range(100):
        q = reward + 0.9 * ~absorbing * q.max(axis=1)[next_state]

    def policy(states: np.ndarray) -> np.ndarray:
        return q[gridworld.cell_indices(states)].argmax(axis=1)

    env = suite.load("gridworld", "windy", task_kwargs={"random": 0})
    plain = suite.load("gridworld", "plain", task_kwargs={"random": 0})
    frames = render.render_episode(
        env, policy, seconds=5.0, fps=4, width=320, height=240, source=(plain, lambda state: state)
    )
    assert frames.shape == (20, 240, 640, 3)
    # Goal after 16 steps (frame 16, 4 s), held 0.5 s (2 frames), then episode 2 from the start.
    first, last = frames[0], frames[16]
    np.testing.assert_array_equal(frames[17], last)
    assert not np.array_equal(frames[15], frames[16]) and not np.array_equal(frames[17], frames[18])
    np.testing.assert_allclose(_agent_centre(frames[18][:, :320]), _agent_centre(first[:, :320]))
    start, goal = _agent_centre(first[:, :320]), _agent_centre(last[:, :320])
    assert abs(goal[1] - start[1]) < 1 and goal[0] > start[0] + 100  # same row, 8 cells right
    # The source panel shows the same cell, without the wind band's blue.
    np.testing.assert_allclose(_agent_centre(last[:, 320:]), goal)
    blue = lambda p: np.mean((p[..., 2].astype(int) - p[..., 0]) > 30)  # noqa: E731
    assert blue(last[30:-30, :320]) > 0.1 and blue(last[30:-30, 322:]) < 0.01


def _rider_tilt(frame: np.ndarray) -> float:
    """Degrees from vertical of the long axis of the bicycle rider's silhouette (its
    reddish pixels), positive leaning to the image's right."""
    rgb = frame.astype(int)
    rows, cols = np.nonzero((rgb[..., 0] > 150) & (rgb[..., 0] - rgb[..., 2] > 60))
    assert len(rows) > 100, "no rider in the frame"
    _, vectors = np.linalg.eigh(np.cov(np.stack([cols - cols.mean(), rows - rows.mean()])))
    axis = vectors[:, -1] if vectors[1, -1] < 0 else -vectors[:, -1]  # pointing up the image
    return math.degrees(math.atan2(axis[0], -axis[1]))


def _falling_bicycle():
    """The bicycle from a 1.1 degree lean, no rider noise: with no steering torque it falls past
    12 degrees in about 2 s, turning only a little."""
    env = suite.load("bicycle", "balance", task_kwargs={"random": 0, "cg_noise": 0.0})

    def start(physics, n):
        states = np.zeros((n, 4))
        states[:, 2] = 0.02  # roll, rad
        return physics.qpos_qvel_from(states)

    env.task.start_configurations = start
    return env


def test_each_domain_declares_the_camera_clips_use():
    from tatl_mj.suite import bicycle, cartpole, mountain_car, pendulum

    for module in (bicycle, cartpole, mountain_car, pendulum):
        env = suite.load(module.__name__.rsplit(".", 1)[1], next(iter(module.TASKS)))
        assert render.default_camera(env) == module.CAMERA
        assert env.physics.model.name2id(module.CAMERA, "camera") >= 0
    assert bicycle.CAMERA == "behind"
    assert render.default_camera(gridworld.plain()) == render.DEFAULT_CAMERA  # draws itself; unused


def test_default_camera_shows_the_bicycle_fall():
    # Filmed side-on ("tracking") the roll is along the line of sight and the bicycle looks
    # upright even in its terminal frame; the default camera (from behind) shows it lean.
    from tatl_mj.suite import bicycle

    tilts = {}
    for camera in (None, "tracking"):
        env = _falling_bicycle()
        frames = render.render_episode(
            env, lambda s: np.zeros((1, 1)), seconds=4, fps=2, width=160, height=120, camera=camera, on_end="stop"
        )
        assert abs(env.physics.state_vector()[2]) > bicycle.ROLL_LIMIT  # it fell: the clip ends on that frame
        tilts[camera] = abs(_rider_tilt(frames[-1]) - _rider_tilt(frames[0]))
    assert tilts[None] > 8.0, tilts  # about the 12 degree roll
    assert tilts["tracking"] < 5.0, tilts  # what the old default showed
