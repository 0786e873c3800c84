"""tatl-mj: a MuJoCo benchmark for cross-domain transfer with Target Apprentice TL.

Importing this package does not import mujoco or dm_control, so a caller (the
``tatl`` CLI, a test) can choose the GL backend first; see ``tatl_mj.gl``. On a
machine without a display it sets ``MUJOCO_GL`` to egl or osmesa if it is unset
(``gl.headless_default``).
"""

from tatl_mj import gl as _gl

__version__ = "0.1.0"

# Without a display and with MUJOCO_GL unset, mujoco and dm_control would pick
# GLFW, warn about DISPLAY and fail to render: pick EGL or OSMesa instead.
_gl.headless_default()
