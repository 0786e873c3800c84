"""tatl-mj: a MuJoCo benchmark for cross-domain transfer with Target Apprentice TL.

Importing this package imports mujoco and dm_control with their OpenGL backends
off (``gl.import_simulators``): no GL library is loaded, and nothing printed,
until a frame is drawn, when ``tatl_mj.gl`` chooses and loads one. So training
code (torch, triton) never meets a GL library it did not ask for.
"""

from tatl_mj import gl as _gl

__version__ = "0.1.0"

# Before any tatl_mj module imports mujoco or dm_control, which fix their GL backend then.
_gl.import_simulators()
