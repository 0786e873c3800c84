"""tatl-mj: a MuJoCo benchmark for cross-domain transfer with Target Apprentice TL.

Importing this package does not import mujoco or dm_control, so a caller (the
``tatl`` CLI, a test) can choose the GL backend first; see ``tatl_mj.gl``.
"""

__version__ = "0.1.0"
