"""What keeps a unit's record the same on any executor and machine: seeds derived from
names (``derive_seed``) and one thread for its whole work (``one_thread``)."""

from __future__ import annotations

import contextlib
import zlib
from typing import Iterator

import numpy as np
import threadpoolctl

from tatl_mj import sampling


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """One thread, for a unit's whole work (and a clip's training), as Ray runs a one-CPU task.

    One BLAS/OpenMP thread: a record must not depend on the executor or the machine's
    core count (a sum's last bit can flip with the thread count, and chaotic targets
    amplify it). One MuJoCo thread: the numbers would be the same on more, but a run's
    units already fill the cores, and their thread pools would wait on each other.
    """
    with threadpoolctl.threadpool_limits(limits=1), sampling.mujoco_threads(1):
        yield


def derive_seed(seed: int, *names: str) -> int:
    """A stable 32-bit seed for (seed, names...), identical across processes and hosts."""
    words = [seed] + [zlib.crc32(name.encode()) for name in names]
    return int(np.random.SeedSequence(words).generate_state(1)[0])
