"""Choosing the OpenGL backend for headless rendering, before MuJoCo is imported.

MuJoCo and dm_control read ``MUJOCO_GL`` (and PyOpenGL reads
``PYOPENGL_PLATFORM``) once, when they are first imported, so the choice must be
made first:

>>> from tatl_mj import gl
>>> backend = gl.select_backend()      # before importing mujoco / dm_control
>>> from tatl_mj import render         # now safe

============  ==============================  ===================================
MUJOCO_GL     PYOPENGL_PLATFORM set to        needs
============  ==============================  ===================================
egl           egl                             libEGL + a driver (GPU, or Mesa's
                                              software llvmpipe)
osmesa        osmesa                          libOSMesa (software, any machine)
glfw          unset (PyOpenGL's default)      a display (X11 / Wayland)
(unset)       probe egl, then osmesa          whichever works first
============  ==============================  ===================================

Each candidate is probed in a short child process that imports mujoco under
that backend and renders one tiny frame, so a backend that crashes or fails to
load never poisons the calling process. The probe costs about a second.

``import tatl_mj`` itself only sets a default where mujoco's own would fail:
with ``MUJOCO_GL`` unset and no display, mujoco and dm_control pick GLFW, warn
about ``DISPLAY`` and cannot render; :func:`headless_default` then picks EGL or
OSMesa by whether its library loads (no probe), and :func:`select_backend`
still probes and falls back as if ``MUJOCO_GL`` were unset.
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
from collections.abc import MutableMapping

BACKENDS: tuple[str, ...] = ("egl", "osmesa", "glfw")
AUTO_ORDER: tuple[str, ...] = ("egl", "osmesa")
LIBRARIES = {"egl": "EGL", "osmesa": "OSMesa"}
DEFAULT_MARKER = "TATL_MJ_GL_DEFAULT"  # names the backend headless_default chose
PROBE_TIMEOUT_S = 120.0

# First loads the GL library the way PyOpenGL looks for it (lib<name>.so, then
# .so.9 ... .so.0), so a missing library is reported by name rather than by
# PyOpenGL's later AttributeError; then renders one 8x8 frame of a one-sphere
# model: the context, MuJoCo's render context and the pixel read-back, exactly
# the path render.py uses.
_PROBE = """\
import sys
from tatl_mj.gl import LIBRARIES, library_error
library = LIBRARIES.get(sys.argv[1])
error = library and library_error(library)
if error:
    sys.exit(f"cannot load lib{library}.so ({error})")
import mujoco
model = mujoco.MjModel.from_xml_string(
    '<mujoco><worldbody><light pos="0 0 2"/><geom size=".1"/></worldbody></mujoco>')
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
with mujoco.Renderer(model, 8, 8) as renderer:
    renderer.update_scene(data)
    renderer.render()
"""

_FIX = (
    "How to fix: on Debian/Ubuntu install a software renderer with "
    "`sudo apt-get install libosmesa6` (or `libegl1` plus a GPU driver for EGL), "
    "then run again, or choose a backend that works with "
    "`export MUJOCO_GL=egl` (or osmesa, glfw)."
)


class GLBackendError(RuntimeError):
    """No usable OpenGL backend; the message says what was tried and how to fix it."""


class UnknownBackendError(GLBackendError, ValueError):
    """``MUJOCO_GL`` names no backend; a ValueError that a GLBackendError handler also catches."""


def headless_default(environ: MutableMapping[str, str] = os.environ) -> str | None:
    """Sets ``MUJOCO_GL`` on a machine without a display if it is unset; returns the choice or None.

    Does nothing if ``MUJOCO_GL`` is set, a display is (``DISPLAY`` or
    ``WAYLAND_DISPLAY``), or mujoco is already imported. Otherwise picks the
    first of egl, osmesa whose library loads, and records it in
    ``TATL_MJ_GL_DEFAULT`` (inherited by worker processes) so that
    :func:`select_backend` treats it as a default, not as the user's choice.
    """
    if any(environ.get(k) for k in ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY")) or "mujoco" in sys.modules:
        return None
    for name in AUTO_ORDER:
        if library_error(LIBRARIES[name]) is None:
            _set(environ, name)
            environ[DEFAULT_MARKER] = name
            return name
    return None


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


def select_backend(environ: MutableMapping[str, str] = os.environ) -> str:
    """Chooses the GL backend, sets ``MUJOCO_GL`` and ``PYOPENGL_PLATFORM``; returns its name.

    Call it before mujoco or dm_control is imported. If ``MUJOCO_GL`` is set it
    is honoured (and checked to work); otherwise EGL is tried, then OSMesa.

    Raises:
      UnknownBackendError: ``MUJOCO_GL`` names no backend tatl-mj can render
        with (both a ValueError and a GLBackendError).
      GLBackendError: no backend works (the message names what was tried, the
        errors and the fix), or mujoco was already imported with another backend.
    """
    requested = environ.get("MUJOCO_GL", "").strip().lower()
    if requested and requested == environ.get(DEFAULT_MARKER) and _imported_backend() is None:
        requested = ""  # headless_default's guess, not the user's choice: probe as if unset
    if requested and requested not in BACKENDS:
        raise UnknownBackendError(
            f"MUJOCO_GL={environ['MUJOCO_GL']!r} is not a rendering backend; "
            f"valid choices: {', '.join(BACKENDS)} (or unset it to choose automatically)"
        )

    imported = _imported_backend()
    if imported is not None:
        # The backend is fixed for this process; do not probe, only check.
        if requested and requested != imported:
            raise GLBackendError(
                f"mujoco was already imported with the {imported!r} GL backend, but "
                f"MUJOCO_GL={requested!r}. Call tatl_mj.gl.select_backend() before "
                "anything imports mujoco or dm_control."
            )
        if not requested:
            raise GLBackendError(
                f"mujoco was already imported (GL backend {imported!r}) before "
                "tatl_mj.gl.select_backend() could choose one. Call it before anything "
                "imports mujoco or dm_control, or set MUJOCO_GL."
            )
        _set(environ, imported)
        return imported

    candidates = (requested,) if requested else AUTO_ORDER
    errors = []
    for name in candidates:
        error = probe(name, environ)
        if error is None:
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
    """Tries backend ``name`` in a child process; returns None if it renders, else the error."""
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


def _set(environ: MutableMapping[str, str], name: str) -> None:
    environ["MUJOCO_GL"] = name
    if name == "glfw":
        # A windowed context uses the platform's own GL; a leftover egl/osmesa breaks it.
        environ.pop("PYOPENGL_PLATFORM", None)
    else:
        environ["PYOPENGL_PLATFORM"] = name


def _imported_backend() -> str | None:
    """The backend of an already imported mujoco (it binds GLContext at import), or None."""
    mujoco = sys.modules.get("mujoco")
    context = getattr(mujoco, "GLContext", None) if mujoco is not None else None
    if context is None:
        return None
    # mujoco.egl.GLContext, mujoco.osmesa.GLContext or mujoco.glfw.GLContext.
    return context.__module__.split(".")[1] if "." in context.__module__ else None


def _last_error_line(stderr: str) -> str:
    """The exception line of a child's traceback (the useful part), or its last line."""
    lines = [line.strip() for line in stderr.strip().splitlines() if line.strip()]
    for line in reversed(lines):
        if "Error" in line.split(":", 1)[0]:
            return line
    return lines[-1] if lines else ""
