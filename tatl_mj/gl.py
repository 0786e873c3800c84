"""OpenGL for headless frames: nothing is loaded until the first frame is drawn.

MuJoCo and dm_control each bind an OpenGL backend when they are imported, from
``MUJOCO_GL``, and what they load stays in the process. Mesa's software EGL and
OSMesa bring Mesa's LLVM, and a later ``import triton`` (torch's optimizers do
it) then crashes the process; with ``MUJOCO_GL`` unset and no display, glfw
warns about ``DISPLAY`` instead. So tatl-mj owns its rendering context:

- ``import tatl_mj`` imports mujoco and dm_control with their backends off
  (:func:`import_simulators`): importing, loading and stepping tasks loads no GL
  library and prints nothing, whatever ``MUJOCO_GL`` says;
- the first frame a process draws (a :class:`Canvas`: ``env.render()``,
  ``physics.render``, ``tatl render``, a clip) chooses the backend
  (:func:`select_backend`), sets ``PYOPENGL_PLATFORM`` before PyOpenGL is first
  imported, and makes contexts of ``mujoco.egl``, ``mujoco.osmesa`` or
  ``mujoco.glfw`` from then on;
- if triton is installed, that first frame imports it first (:func:`load`):
  triton's LLVM loaded before Mesa's is the order that works, the other one
  crashes. So a process may render, then build a torch optimizer.

Why in the process and not in a child process that renders: a frame is drawn
from the live ``MjModel`` and ``MjData`` (the time-varying pendulum edits its
model every step), where a child would need both sent over a pipe for every
frame; the only order in-process frames cannot survive, Mesa's LLVM before
triton's, is taken out by the triton import above.

============  ==============================  ===================================
MUJOCO_GL     PYOPENGL_PLATFORM set to        needs
============  ==============================  ===================================
egl           egl                             libEGL + a driver (GPU, or Mesa's
                                              software llvmpipe)
osmesa        osmesa                          libOSMesa (software, any machine)
glfw          unset (PyOpenGL's default)      a display (X11 / Wayland)
(unset)       probe egl, then osmesa          whichever works first
============  ==============================  ===================================

Each candidate is probed in a short child process that draws one tiny frame
through :class:`Canvas`, so a backend that crashes or fails to load never
poisons the calling process. The probe costs about a second, once a process.
"""

from __future__ import annotations

import atexit
import ctypes
import functools
import importlib
import importlib.util
import os
import subprocess
import sys
import weakref
from collections.abc import MutableMapping
from typing import Any

import numpy as np

# mujoco is imported inside the functions: this module is imported by tatl_mj's own
# __init__, before import_simulators() imports mujoco with its backend off.

BACKENDS: tuple[str, ...] = ("egl", "osmesa", "glfw")
AUTO_ORDER: tuple[str, ...] = ("egl", "osmesa")
LIBRARIES = {"egl": "EGL", "osmesa": "OSMesa"}
PROBE_TIMEOUT_S = 120.0
# Loaded before Mesa's LLVM where installed: its own LLVM must come first (see the module docstring).
LLVM_FIRST: tuple[str, ...] = ("triton",)

# The child's check: the library loads (named in the error, rather than PyOpenGL's later
# AttributeError), then one 8x8 frame of a one-sphere model through Canvas, the path every
# frame takes.
_PROBE = """\
import sys
from tatl_mj import gl
sys.exit(gl.probe_frame(sys.argv[1]))
"""

_FIX = (
    "How to fix: on Debian/Ubuntu install a software renderer with "
    "`sudo apt-get install libosmesa6` (or `libegl1` plus a GPU driver for EGL), "
    "then run again, or choose a backend that works with "
    "`export MUJOCO_GL=egl` (or osmesa, glfw)."
)

# The backend this process draws with, once it drew a frame: {name: its GLContext class}.
_LOADED: dict[str, Any] = {}
_PROBED: set[str] = set()  # backends whose probe drew a frame (probed once a process)
_OPEN: weakref.WeakSet = weakref.WeakSet()  # canvases to free before the backend's own exit hooks run


class GLBackendError(RuntimeError):
    """No usable OpenGL backend; the message says what was tried and how to fix it."""


class UnknownBackendError(GLBackendError, ValueError):
    """``MUJOCO_GL`` names no backend; a ValueError that a GLBackendError handler also catches."""


def import_simulators(environ: MutableMapping[str, str] = os.environ) -> None:
    """Imports mujoco and dm_control with their GL backends off; ``environ`` is left as it was.

    Both read ``MUJOCO_GL`` once, at import, and load (or, for glfw, warn about)
    the backend it names; with ``disable`` they load none, and frames are drawn
    on tatl-mj's own contexts (:class:`Canvas`). Modules already imported keep
    the backend they were imported with.
    """
    saved = environ.get("MUJOCO_GL")
    environ["MUJOCO_GL"] = "disable"
    try:
        importlib.import_module("mujoco")
        importlib.import_module("dm_control.mujoco")
    finally:
        if saved is None:
            environ.pop("MUJOCO_GL", None)
        else:
            environ["MUJOCO_GL"] = saved


def library_error(library: str) -> str | None:
    """Loads lib<library>.so globally under the names PyOpenGL tries; None, or the first name's error."""
    failures = []
    for name in [f"lib{library}.so"] + [f"lib{library}.so.{i}" for i in range(9, -1, -1)]:
        try:
            ctypes.CDLL(name, mode=ctypes.RTLD_GLOBAL)
            return None
        except OSError as error:
            failures.append(str(error))
    return failures[0]


def loaded_backend() -> str | None:
    """The backend this process draws frames with, or None before its first frame.

    A mujoco imported before tatl-mj with ``MUJOCO_GL=egl`` or ``osmesa`` has
    loaded that backend (and fixed PyOpenGL's platform) already.
    """
    if _LOADED:
        return next(iter(_LOADED))
    mujoco = sys.modules.get("mujoco")
    context = getattr(mujoco, "GLContext", None) if mujoco is not None else None
    name = context.__module__.split(".")[1] if context is not None and "." in context.__module__ else None
    return name if name in LIBRARIES else None


def select_backend(environ: MutableMapping[str, str] = os.environ) -> str:
    """Chooses the GL backend, sets ``MUJOCO_GL`` and ``PYOPENGL_PLATFORM``; returns its name.

    If ``MUJOCO_GL`` is set it is honoured (and checked to work); otherwise EGL
    is tried, then OSMesa. Once this process drew a frame, its backend is the
    answer. Loads nothing in this process: the first :class:`Canvas` does.

    Raises:
      UnknownBackendError: ``MUJOCO_GL`` names no backend tatl-mj can render
        with (both a ValueError and a GLBackendError).
      GLBackendError: no backend works (the message names what was tried, the
        errors and the fix), or this process already draws with another backend.
    """
    requested = environ.get("MUJOCO_GL", "").strip().lower()
    if requested and requested not in BACKENDS:
        raise UnknownBackendError(
            f"MUJOCO_GL={environ['MUJOCO_GL']!r} is not a rendering backend; "
            f"valid choices: {', '.join(BACKENDS)} (or unset it to choose automatically)"
        )
    loaded = loaded_backend()
    if loaded is not None:
        # The backend is fixed for this process; do not probe, only check.
        if requested and requested != loaded:
            raise GLBackendError(
                f"this process already draws frames with the {loaded!r} GL backend, but "
                f"MUJOCO_GL={requested!r}; one process renders with one backend: set MUJOCO_GL "
                "before the first frame is drawn."
            )
        _set(environ, loaded)
        return loaded

    candidates = (requested,) if requested else AUTO_ORDER
    errors = []
    for name in candidates:
        error = None if name in _PROBED else probe(name, environ)
        if error is None:
            _PROBED.add(name)
            _set(environ, name)
            return name
        errors.append(f"  {name}: {error}")

    how = (
        f"MUJOCO_GL={requested} (set in the environment)"
        if requested
        else ("MUJOCO_GL is unset, so tried " + ", then ".join(AUTO_ORDER))
    )
    raise GLBackendError(
        f"No working OpenGL backend for headless rendering. {how}.\n" + "\n".join(errors) + "\n" + _FIX
    )


def probe(name: str, environ: MutableMapping[str, str] = os.environ) -> str | None:
    """Tries backend ``name`` in a child process; returns None if it draws a frame, else the error."""
    if name not in BACKENDS:
        raise ValueError(f"backend {name!r} is unknown; valid choices: {', '.join(BACKENDS)}")
    env = dict(environ)
    _set(env, name)
    # The probe imports tatl_mj.gl: make this copy of the package importable there.
    package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, env.get("PYTHONPATH")]))
    try:
        result = subprocess.run(
            [sys.executable, "-c", _PROBE, name],
            env=env,
            capture_output=True,
            text=True,
            timeout=PROBE_TIMEOUT_S,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return f"the probe hung for more than {PROBE_TIMEOUT_S:.0f} s"
    if result.returncode == 0:
        return None
    return _last_error_line(result.stderr) or f"probe exited with status {result.returncode}"


def probe_frame(name: str) -> str | None:
    """Draws one 8x8 frame with backend ``name`` in this process; None, or why it failed (the probe)."""
    library = LIBRARIES.get(name)
    error = library and library_error(library)
    if error:
        return f"cannot load lib{library}.so ({error})"
    import mujoco

    _load(name)
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><light pos="0 0 2"/><geom size=".1"/></worldbody></mujoco>'
    )
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with Canvas(model, 8, 8) as canvas:
        canvas.draw(data)
    return None


def load() -> str:
    """Chooses (:func:`select_backend`) and loads this process's backend, once; returns its name.

    Where triton is installed and not yet imported, it is imported first: its
    LLVM loaded after Mesa's crashes the process, before it is fine.
    """
    loaded = loaded_backend()
    if loaded is not None and loaded in _LOADED:
        return loaded
    name = select_backend()
    for module in LLVM_FIRST:
        if module not in sys.modules and importlib.util.find_spec(module) is not None:
            importlib.import_module(module)
    _load(name)
    return name


def _load(name: str) -> Any:
    """Backend ``name``'s GLContext class, its module imported with PyOpenGL's platform set to match."""
    if name in _LOADED:
        return _LOADED[name]
    if _LOADED:
        raise GLBackendError(f"this process already draws frames with {next(iter(_LOADED))!r}, not {name!r}")
    if "OpenGL" not in sys.modules:  # PyOpenGL reads its platform once, at its first import
        _set(os.environ, name)
    try:
        module = importlib.import_module(f"mujoco.{name}")
    except (ImportError, OSError, RuntimeError) as error:
        raise GLBackendError(f"cannot load the {name!r} GL backend: {error}") from None
    _LOADED[name] = module.GLContext
    return module.GLContext


@functools.cache
def _close_at_exit() -> None:
    """Closes open canvases at exit: registered after the first context is made, which
    registers the backend's own hook (EGL terminates its display), so it runs before it."""
    atexit.register(lambda: [canvas.close() for canvas in list(_OPEN)])


class Canvas:
    """Frames of one MuJoCo model, drawn offscreen on a GL context of its own.

    The first canvas of a process loads the backend (:func:`load`). ``draw``
    returns a new ``(height, width, 3)`` uint8 RGB image of ``data`` from a
    camera of the model (an id, or -1 for the free camera). Close it (or use it
    as a context manager) to free the context; any still open are closed at exit.
    """

    def __init__(self, model: Any, height: int, width: int) -> None:
        import mujoco

        buffer = model.vis.global_
        for field, size, most in (("width", width, buffer.offwidth), ("height", height, buffer.offheight)):
            if size > most:
                raise ValueError(
                    f"{field} {size} is more than the model's offscreen buffer ({most} pixels; "
                    f"<visual><global off{field}=.../></visual>)"
                )
        context_type = _LOADED[load()]
        self.model = model
        self._mujoco = mujoco
        self._context: Any = context_type(width, height)
        _close_at_exit()
        self._context.make_current()
        self._scene = mujoco.MjvScene(model, maxgeom=10_000)
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._render_context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._render_context)
        self._rect = mujoco.MjrRect(0, 0, width, height)
        self._pixels = np.empty((height, width, 3), np.uint8)
        _OPEN.add(self)

    def draw(self, data: Any, camera: int = -1, model: Any = None) -> np.ndarray:
        """``data``'s frame; ``model``, where given, replaces the canvas's for this frame: one of
        the same layout whose sizes or masses differ (the time-varying pendulum's steps)."""
        mujoco = self._mujoco
        model = self.model if model is None else model
        if self._context is None:
            raise ValueError("this canvas is closed")
        self._context.make_current()
        if camera < 0:
            self._camera.type = mujoco.mjtCamera.mjCAMERA_FREE
            mujoco.mjv_defaultFreeCamera(model, self._camera)
        else:
            self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
            self._camera.fixedcamid = camera
        mujoco.mjv_updateScene(
            model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL.value, self._scene
        )
        mujoco.mjr_render(self._rect, self._scene, self._render_context)
        mujoco.mjr_readPixels(self._pixels, None, self._rect, self._render_context)
        return self._pixels[::-1].copy()  # OpenGL's rows run bottom-up

    def close(self) -> None:
        if self._context is None:
            return
        self._context.make_current()
        self._render_context.free()
        self._context.free()
        self._context = None
        _OPEN.discard(self)

    def __enter__(self) -> Canvas:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _set(environ: MutableMapping[str, str], name: str) -> None:
    environ["MUJOCO_GL"] = name
    if name == "glfw":
        # A windowed context uses the platform's own GL; a leftover egl/osmesa breaks it.
        environ.pop("PYOPENGL_PLATFORM", None)
    else:
        environ["PYOPENGL_PLATFORM"] = name


def _last_error_line(stderr: str) -> str:
    """The exception line of a child's traceback (the useful part), or its last line."""
    lines = [line.strip() for line in stderr.strip().splitlines() if line.strip()]
    for line in reversed(lines):
        if "Error" in line.split(":", 1)[0]:
            return line
    return lines[-1] if lines else ""
