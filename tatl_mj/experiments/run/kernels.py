"""The arithmetic kernels a process computes with, and how to make worker processes use others.

A record depends on its kernels as on its seed (docs/protocol.md, "Across
machines"): OpenBLAS picks a kernel for the processor when it is loaded, and
numpy its SIMD loops when it is imported. Both read an environment variable at
that moment and never after (``OPENBLAS_CORETYPE``, ``NPY_DISABLE_CPU_FEATURES``),
so setting them pins the kernels of processes started afterwards (the run's
spawned workers), not of one that has loaded them already. :func:`probe` asks a
fresh process which kernels an environment gives, so whether pinning worked is
measured, never assumed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import subprocess
import sys
from collections.abc import Iterator
from functools import cache

import numpy as np
import threadpoolctl

PIN_VARIABLES = ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")
"""What :func:`pinning` sets: OpenBLAS's kernel, and the numpy SIMD targets to leave unused."""
PROBE_TIMEOUT_S = 120.0


@cache  # fixed for a process's life: the libraries choose their kernels when loaded
def kernels() -> str:
    """The arithmetic kernels this process computes with: each BLAS library by version and
    kernel, and numpy's SIMD targets, e.g. ``"openblas 0.3.31 Haswell; numpy X86_V3"``.

    A record depends on them as on its seed: other kernels sum in another order, and the
    same seeds then give other per-seed returns (docs/protocol.md, "Across machines").
    """
    import scipy.linalg  # noqa: F401 - loads scipy's own BLAS too, so every unit reports both

    blas = sorted(
        {
            f"{info['internal_api']} {info.get('version') or '?'} {info.get('architecture') or '?'}"
            for info in threadpoolctl.threadpool_info()
            if info["user_api"] == "blas"
        }
    )
    simd = np.show_config(mode="dicts").get("SIMD Extensions", {}).get("found") or ["baseline"]
    return "; ".join([*blas, f"numpy {'+'.join(simd)}"])


@dataclasses.dataclass(frozen=True)
class Kernels:
    """A :func:`kernels` label taken apart: each BLAS library's (name, version, kernel) and
    numpy's SIMD targets (empty for numpy's baseline alone)."""

    blas: tuple[tuple[str, str, str], ...]
    simd: tuple[str, ...]

    @classmethod
    def parse(cls, label: str) -> Kernels:
        *libraries, numpy_part = label.split("; ")
        name, _, targets = numpy_part.partition(" ")
        blas = tuple(tuple(part.rsplit(" ", 2)) for part in libraries)
        if name != "numpy" or any(len(b) != 3 for b in blas):
            raise ValueError(f"not a kernels label (LIBRARY VERSION KERNEL; ...; numpy TARGETS): {label!r}")
        simd = () if targets == "baseline" else tuple(targets.split("+"))
        return cls(blas=blas, simd=simd)  # type: ignore[arg-type]


def pinning(wanted: str, here: str) -> dict[str, str]:
    """The environment under which a process on this machine (whose own kernels are ``here``)
    would compute with ``wanted``; ValueError, saying why, where no setting can: other
    library versions, or SIMD targets this processor lacks."""
    want, have = Kernels.parse(wanted), Kernels.parse(here)
    libraries = sorted((name, version) for name, version, _ in want.blas)
    if libraries != sorted((name, version) for name, version, _ in have.blas):
        raise ValueError(f"other BLAS libraries or versions ({wanted!r} against this machine's {here!r})")
    cores = {core for _, _, core in want.blas}
    if len(cores) != 1:
        raise ValueError(f"its BLAS libraries use different kernels ({wanted!r}): one setting cannot pin both")
    missing = [t for t in want.simd if t not in have.simd]
    if missing:
        raise ValueError(f"numpy SIMD targets {missing} that this processor lacks ({here!r})")
    env = {"OPENBLAS_CORETYPE": cores.pop()}
    extra = [t for t in have.simd if t not in want.simd]
    if extra:
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(extra)
    return env


def probe(env: dict[str, str] | None = None) -> str:
    """The kernels a fresh Python process computes with under ``env`` (added to this
    process's environment, :data:`PIN_VARIABLES` cleared first); RuntimeError with the
    child's last line if it fails (numpy refuses to disable a baseline target)."""
    child = {k: v for k, v in os.environ.items() if k not in PIN_VARIABLES}
    code = "from tatl_mj.experiments.run.kernels import kernels; print(kernels())"
    done = subprocess.run(
        [sys.executable, "-c", code],
        env={**child, **(env or {})},
        capture_output=True,
        text=True,
        timeout=PROBE_TIMEOUT_S,
    )
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"a process under {env} failed to start: {last}")
    return done.stdout.strip().splitlines()[-1]


@dataclasses.dataclass(frozen=True)
class Pin:
    """The outcome of :func:`pin_to`: the environment to set for workers (empty: none
    needed or none can), the kernels they will compute with, and why not, if they cannot."""

    env: dict[str, str]
    kernels: str
    why_not: str | None = None

    @property
    def pinned(self) -> bool:
        return self.why_not is None


def pin_to(wanted: str) -> Pin:
    """How worker processes started from here can compute with ``wanted``: measured by
    :func:`probe` in fresh processes (this machine's own kernels, then under the setting)."""
    own = probe()
    if own == wanted:
        return Pin(env={}, kernels=own)
    try:
        env = pinning(wanted, own)
        got = probe(env)
    except (ValueError, RuntimeError) as error:
        return Pin(env={}, kernels=own, why_not=str(error))
    if got != wanted:
        return Pin(env={}, kernels=own, why_not=f"{env} gives {got!r}")
    return Pin(env=env, kernels=got)


@contextlib.contextmanager
def workers_under(pin: Pin) -> Iterator[None]:
    """Within the block, processes started from here (a run's spawned workers) compute with
    ``pin``'s kernels: :data:`PIN_VARIABLES` are set to its environment (those it does not
    name removed), and restored after. Nothing changes where ``pin`` could not pin."""
    saved = {k: os.environ.get(k) for k in PIN_VARIABLES}
    if pin.pinned:
        for key in PIN_VARIABLES:
            os.environ.pop(key, None)
        os.environ.update(pin.env)
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
