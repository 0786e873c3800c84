"""Headless clips of a policy acting in a tatl-mj task (optionally beside its source).

Render and write (the GL backend is chosen and loaded at the first frame, ``tatl_mj.gl``):

>>> from tatl_mj import render, suite
>>> env = suite.load("cartpole", "balance", task_kwargs={"random": 0})
>>> frames = render.render_episode(env, policy, seconds=4, method_label="ta-tl")
>>> render.write_clip(frames, "cartpole.mp4", fps=30)

How a clip is made
  - The environment is reset once and stepped at its own control rate; a frame is
    drawn only when one is due (clip time ``k / fps``), showing the state after
    the last step at or before that time. Nothing here runs unless a clip is
    asked for, so simulation and training are never slowed by rendering.
  - MuJoCo tasks are drawn on a ``gl.Canvas`` (tatl-mj's own offscreen context) from a camera of the model:
    by default the one the task's domain declares (:func:`default_camera`, the
    ``CAMERA`` of its suite module: the bicycle from behind, where its roll
    shows; cart-pole, pendulum and mountain car side-on); a task without a
    MuJoCo model draws itself (its ``painter``, numpy and Pillow).
  - Overlay (top left, small): episode time, method label, running return and
    episode number.
    Each panel is labelled with its domain at the bottom left.
  - Episode end: the last frame, labelled with the reason (terminal state, time
    limit or diverged), is held for at most ``END_HOLD_SECONDS`` (0.5 s); then with
    ``on_end="reset"`` (default) a new episode starts, its overlay giving its number
    and why the previous one ended, and with ``on_end="stop"`` the clip ends there
    (shorter than asked). No frame is ever held longer, so a clip never freezes.
  - Side by side (``source=(source_env, source_state_fn)``): for every frame the
    source system is put in the mapped state ``source_state_fn(target_state)`` and
    drawn to the right of the target; the clip is then ``2 * width`` wide.
  - Render contexts are created per clip and freed before returning, so the
    process exits without GL clean-up errors.

Memory: a 640x480 frame is 0.9 MB, so ``render_episode`` holds about 28 MB per
second of clip at 30 fps; :func:`iter_frames` streams frames instead, and
:func:`write_clip` accepts either.
"""

from __future__ import annotations

import contextlib
import math
import sys
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import imageio.v2 as imageio_v2
import imageio.v3 as imageio_v3
import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from tatl_mj import gl
from tatl_mj.validation import integer, number

Policy = Callable[[np.ndarray], np.ndarray]
SourceSpec = tuple[Any, Callable[[np.ndarray], np.ndarray]]

END_MODES: tuple[str, ...] = ("reset", "stop")
END_HOLD_SECONDS = 0.5  # how long the end of an episode stays on screen
CLIP_EXTENSIONS: tuple[str, ...] = (".mp4", ".gif")
UNTIMED_STEP_SECONDS = 0.25  # steps without a duration (no physics): show four per second
DEFAULT_CAMERA = "tracking"  # for a model whose domain declares no CAMERA


def default_camera(env: Any) -> str:
    """The camera clips of ``env`` are filmed from: the one its domain shows best.

    A domain declares it as ``CAMERA`` in the module that defines its physics
    class (``tatl_mj.suite.bicycle.CAMERA == "behind"``); without one (e.g. a
    dm_control task) it is ``DEFAULT_CAMERA``.
    """
    physics = getattr(env, "physics", None)
    module = sys.modules.get(type(physics).__module__) if physics is not None else None
    return str(getattr(module, "CAMERA", DEFAULT_CAMERA))


def render_episode(
    env: Any,
    policy: Policy,
    *,
    seconds: float,
    width: int = 640,
    height: int = 480,
    fps: float = 30,
    method_label: str = "",
    camera: str | None = None,
    source: SourceSpec | None = None,
    on_end: str = "reset",
) -> np.ndarray:
    """Films ``policy`` acting in ``env``; returns frames ``(n, H, W, 3)`` uint8.

    ``n`` is ``round(seconds * fps)``, or fewer with ``on_end="stop"`` when the
    episode ends first.

    Args:
      env: a tatl-mj (or dm_control) environment, or one that draws itself (``painter``).
      policy: maps a batched state ``(1, d)`` to action values ``(1, m)`` (or
        action indices ``(1,)`` for a task that takes indices).
      seconds: clip length in simulated seconds (untimed steps count
        ``UNTIMED_STEP_SECONDS`` each).
      width, height: size of each panel in pixels (at most the model's
        offscreen buffer, 1280x960 for tatl-mj models).
      fps: frames per second of the clip.
      method_label: shown in the overlay, e.g. ``"ta-tl"``.
      camera: the model's camera to film from (for both panels); None: each
        panel's :func:`default_camera`.
      source: ``(source_env, source_state_fn)`` to show the source system, put in
        the mapped state ``source_state_fn(target_state)`` (a ``(d,)`` state to a
        ``(d_s,)`` state), to the right of the target; the frames are then
        ``2 * width`` wide.
      on_end: after an episode ends (and its last frame has been held for at
        most ``END_HOLD_SECONDS``), ``"reset"`` starts a new one, ``"stop"`` ends
        the clip.
    """
    frames = None
    count = 0
    for k, frame in enumerate(
        iter_frames(
            env,
            policy,
            seconds=seconds,
            width=width,
            height=height,
            fps=fps,
            method_label=method_label,
            camera=camera,
            source=source,
            on_end=on_end,
        )
    ):
        if frames is None:
            frames = np.empty((_frame_count(seconds, fps),) + frame.shape, np.uint8)
        frames[k] = frame
        count = k + 1
    return frames[:count]


def iter_frames(
    env: Any,
    policy: Policy,
    *,
    seconds: float,
    width: int = 640,
    height: int = 480,
    fps: float = 30,
    method_label: str = "",
    camera: str | None = None,
    source: SourceSpec | None = None,
    on_end: str = "reset",
) -> Iterator[np.ndarray]:
    """Like :func:`render_episode`, but yields the frames one by one (constant memory).

    A yielded array may be yielded again (the held end of an episode), so copy it
    to keep it.
    """
    n_frames = _frame_count(seconds, fps)
    _check_size("width", width)
    _check_size("height", height)
    if on_end not in END_MODES:
        raise ValueError(f"on_end must be one of {END_MODES}, got {on_end!r}")
    if source is not None and (not isinstance(source, tuple) or len(source) != 2 or not callable(source[1])):
        raise ValueError("source must be a tuple (source_env, source_state_fn)")

    step_seconds = _step_seconds(env)
    with contextlib.ExitStack() as stack:
        paint, _ = _painter(env, width, height, default_camera(env) if camera is None else camera, stack)
        draw = _frame_drawer(env, paint, source, width, height, camera, stack)
        yield from _clip_frames(env, policy, draw, n_frames, fps, step_seconds, method_label, on_end)


def _frame_drawer(
    env: Any,
    paint: Painter,
    source: SourceSpec | None,
    width: int,
    height: int,
    camera: str | None,
    stack: contextlib.ExitStack,
) -> Callable[[np.ndarray, str], np.ndarray]:
    """A function drawing one frame from the target's state and overlay text: the target
    labelled, and with ``source`` the source in the mapped state beside it."""
    show_source = None
    if source is not None:
        source_env, source_state_fn = source
        source_env.reset()
        _, show_source = _painter(
            source_env, width, height, default_camera(source_env) if camera is None else camera, stack
        )
    target_name = _domain_name(env)
    source_name = None if source is None else _domain_name(source[0])

    def draw(state: np.ndarray, text: str) -> np.ndarray:
        image = _label(paint(), text, "top")
        image = _label(image, target_name if source is None else f"target: {target_name}", "bottom")
        if show_source is not None:
            mapped = np.asarray(source_state_fn(state), dtype=np.float64).reshape(-1)
            right = _label(show_source(mapped), f"source: {source_name} (mapped state)", "bottom")
            right[:, :2] = 40  # a thin divider between the panels
            image = np.concatenate([image, right], axis=1)
        return image

    return draw


def _clip_frames(
    env: Any,
    policy: Policy,
    draw: Callable[[np.ndarray, str], np.ndarray],
    n_frames: int,
    fps: float,
    step_seconds: float,
    method_label: str,
    on_end: str,
) -> Iterator[np.ndarray]:
    """The clip's frames: ``env`` stepped on the clip's clock, each episode's end held, then
    a new episode or (``on_end="stop"``) the end of the clip."""
    # An episode end stays on screen for hold_frames frames (at least one).
    hold_frames = max(1, math.floor(END_HOLD_SECONDS * fps + 1e-9))
    timestep = env.reset()
    episode, episode_steps, episode_return = 1, 0, 0.0
    episode_start = 0.0  # clip time at which this episode's first state is shown
    ended, previous_end, held, end_frame = "", "", 0, None
    for k in range(n_frames):
        clip_time = k / fps
        if ended:
            if held < hold_frames:
                held += 1
                yield end_frame
                continue
            if on_end == "stop":
                return
            timestep = env.reset()
            episode, episode_steps, episode_return = episode + 1, 0, 0.0
            episode_start, previous_end, ended = clip_time, ended, ""
        # Step until the next step would pass this frame's time.
        while not ended and episode_start + (episode_steps + 1) * step_seconds <= clip_time + 1e-9:
            timestep = env.step(_action(policy, _state(timestep)))
            episode_steps += 1
            episode_return += float(timestep.reward or 0.0)
            if timestep.last():
                ended = _end_reason(env, timestep)

        state = _state(timestep)
        text = _overlay_text(
            clock=f"t {episode_steps * step_seconds:5.2f} s" if hasattr(env, "physics") else f"step {episode_steps:3d}",
            method_label=method_label,
            episode_return=episode_return,
            episode=episode,
            previous_end=previous_end,
            ended=ended,
        )
        image = draw(state, text)
        if ended:
            end_frame, held = image, 1
        yield image


def _overlay_text(
    *, clock: str, method_label: str, episode_return: float, episode: int, previous_end: str, ended: str
) -> str:
    """The top overlay: clock, method, return, episode number (and why the last one ended)."""
    text = clock
    if method_label:
        text += f"   {method_label}"
    text += f"   return {episode_return:.1f}   episode {episode}"
    if previous_end and not ended:
        text += f" (episode {episode - 1}: {previous_end})"
    if ended:
        text += f"   [{ended}]"
    return text


def write_clip(frames: np.ndarray | Iterable[np.ndarray], path: str | Path, fps: float) -> Path:
    """Writes RGB uint8 frames ``(n, H, W, 3)`` to ``.mp4`` (H.264, yuv420p) or ``.gif``.

    Odd sizes are padded by one edge pixel to even (H.264 with yuv420p needs even
    sizes). Returns the path written.
    """
    path = Path(path)
    extension = path.suffix.lower()
    if extension not in CLIP_EXTENSIONS:
        raise ValueError(f"path {str(path)!r}: clip extension must be one of {CLIP_EXTENSIONS}, got {extension!r}")
    number("", "fps", fps, 0.0, low_open=True)
    checked = (_check_frame(i, frame) for i, frame in enumerate(frames))
    path.parent.mkdir(parents=True, exist_ok=True)
    if extension == ".gif":
        stack = list(checked)
        if not stack:
            raise ValueError("frames is empty: a clip needs at least one frame")
        # GIF delays are whole centiseconds; Pillow rounds the duration (ms).
        imageio_v3.imwrite(path, np.stack(stack), extension=".gif", duration=1000.0 / fps, loop=0)
        return path
    count = 0
    try:
        with imageio_v2.get_writer(
            path,
            format="FFMPEG",
            mode="I",
            fps=fps,
            codec="libx264",
            pixelformat="yuv420p",
            macro_block_size=2,
            quality=5,
        ) as writer:
            for frame in checked:
                pad = ((0, frame.shape[0] % 2), (0, frame.shape[1] % 2), (0, 0))
                writer.append_data(np.pad(frame, pad, mode="edge") if any(p[1] for p in pad) else frame)
                count += 1
        if count == 0:
            raise ValueError("frames is empty: a clip needs at least one frame")
    except BaseException:
        path.unlink(missing_ok=True)  # no half-written clip left behind
        raise
    return path


# --- Painters -----------------------------------------------------------------

Painter = Callable[[], np.ndarray]
StatePainter = Callable[[np.ndarray], np.ndarray]


def _painter(
    env: Any, width: int, height: int, camera: str, stack: contextlib.ExitStack
) -> tuple[Painter, StatePainter]:
    """Two functions drawing ``env`` as a fresh (height, width, 3) uint8 image.

    ``paint()`` draws the current state; ``show(state)`` draws ``state`` (for a
    MuJoCo env it puts the simulator in that state first).
    """
    if hasattr(env, "painter"):  # an environment that draws itself (no MuJoCo model)
        show_state = env.painter(width, height)
        return (lambda: show_state(env.state_vector())), show_state
    physics = getattr(env, "physics", None)
    if physics is None:
        raise ValueError(
            f"env must be a tatl-mj task (a MuJoCo environment or one with a painter), got {type(env).__name__}"
        )
    model = physics.model
    camera_id = mujoco.mj_name2id(model.ptr, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if camera_id < 0:
        cameras = [model.id2name(i, "camera") for i in range(model.ncam)]
        raise ValueError(f"camera {camera!r} is not in the {_domain_name(env)} model; valid choices: {cameras}")
    canvas = None

    def close() -> None:
        if canvas is not None:
            canvas.close()

    stack.callback(close)

    def paint() -> np.ndarray:
        nonlocal canvas
        # A task may recompile its model (e.g. new parameters per episode).
        if canvas is None or canvas.model is not physics.model.ptr:
            close()
            canvas = gl.Canvas(physics.model.ptr, height, width)
        return canvas.draw(physics.data.ptr, camera_id)

    def show(state: np.ndarray) -> np.ndarray:
        physics.set_state_vector(state)
        return paint()

    return paint, show


# --- Overlay --------------------------------------------------------------------


def _label(image: np.ndarray, text: str, where: str) -> np.ndarray:
    """Writes ``text`` on a darkened strip at the top or bottom left of ``image`` (in place)."""
    height = image.shape[0]
    font = _font(max(11, round(height / 30)))  # 16 px at 480 rows
    margin = max(4, round(font.size / 3))
    left, top, right, bottom = font.getbbox(text)
    y = margin if where == "top" else height - (bottom - top) - 3 * margin
    # Only the strip goes through Pillow: whole-frame copies would cost more than the text.
    strip = image[y : y + bottom - top + 2 * margin, : right + 3 * margin]
    canvas = Image.fromarray(strip // 3)  # dark background keeps the text legible
    ImageDraw.Draw(canvas).text((margin, margin - top), text, font=font, fill=(255, 255, 255))
    strip[...] = np.asarray(canvas)
    return image


_FONTS: dict[int, ImageFont.ImageFont] = {}


def _font(size: int) -> Any:
    if size not in _FONTS:
        _FONTS[size] = ImageFont.load_default(size=size)
    return _FONTS[size]


# --- Helpers ------------------------------------------------------------------


def _frame_count(seconds: float, fps: float) -> int:
    for name, value in (("seconds", seconds), ("fps", fps)):
        number("", name, value, 0.0, low_open=True)
    n = int(round(seconds * fps))
    if n < 1:
        raise ValueError(f"seconds * fps = {seconds * fps:g} gives no frame; ask for at least 1")
    return n


def _check_size(name: str, value: int) -> None:
    integer("", name, value, 16, unit=" pixels")


def _check_frame(index: int, frame: np.ndarray) -> np.ndarray:
    frame = np.asarray(frame)
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
        raise ValueError(
            f"frames[{index}] must be an (H, W, 3) uint8 RGB image, got shape {frame.shape} dtype {frame.dtype}"
        )
    return frame


def _step_seconds(env: Any) -> float:
    if hasattr(env, "physics"):
        return float(env.control_timestep())
    return UNTIMED_STEP_SECONDS


def _state(timestep: Any) -> np.ndarray:
    observation = timestep.observation
    if isinstance(observation, dict) and "state" in observation:
        return np.asarray(observation["state"], dtype=np.float64)
    if isinstance(observation, dict):
        # dm_control's own suite: the flattened observation stands in for the state.
        return np.concatenate([np.ravel(v) for v in observation.values()]).astype(np.float64)
    return np.asarray(observation, dtype=np.float64)


def _action(policy: Policy, state: np.ndarray) -> np.ndarray:
    action = np.asarray(policy(state[None]))
    if action.ndim == 0 or action.shape[0] != 1:
        raise ValueError(
            f"policy must map a (1, {state.size}) state batch to a batch of one action, got shape {action.shape}"
        )
    return action[0]


def _end_reason(env: Any, timestep: Any) -> str:
    if getattr(env, "diverged", None):
        return "diverged"
    return "terminal state" if timestep.discount == 0 else "time limit"


def _domain_name(env: Any) -> str:
    if hasattr(env, "title"):
        return str(env.title)
    physics = getattr(env, "physics", None)
    owner = type(physics) if physics is not None else type(env)
    return owner.__module__.rsplit(".", 1)[-1]
