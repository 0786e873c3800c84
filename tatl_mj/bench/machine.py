"""What ``tatl bench``'s figures were taken on, and which tasks it times."""

from __future__ import annotations

import os
import platform
from typing import Any

import numpy as np


def physics_tasks() -> dict[str, str]:
    """The first task of every domain with physics: what ``tatl bench`` times, by domain."""
    from tatl_mj import suite

    out: dict[str, str] = {}
    for domain, task in suite.ALL_TASKS:
        if domain not in out and not suite.describe(domain, task).discrete:
            out[domain] = task
    return out


def reference() -> tuple[str, str]:
    """The task of the FQI, memory and render figures: the first physics task (cart-pole's)."""
    return next(iter(physics_tasks().items()))


def machine() -> dict[str, Any]:
    """CPU model, cores, and the versions that decide the figures."""
    from importlib import metadata

    import mujoco

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "usable_cores": usable,
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "python": platform.python_version(),
        "mujoco": mujoco.__version__,
        "dm_control": metadata.version("dm-control"),
        "numpy": np.__version__,
        "mujoco_gl": os.environ.get("MUJOCO_GL", ""),
    }
