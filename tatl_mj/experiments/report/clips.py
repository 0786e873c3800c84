"""`tatl render`: a clip of a method's policy on an experiment's target task.

It reuses a finished ``tatl run`` folder when given one (the source policy,
mapping and target data of that seed), and otherwise trains what it needs at
the chosen preset. The policy is the one the method learns from the preset's
largest target-sample budget, built by the same call as in evaluation
(``method_unit.learned_policy``), so the clip shows the evaluated policy.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from tatl_mj import render, suite
from tatl_mj.experiments.results.records import RunDirectory, load_blob
from tatl_mj.experiments.run import determinism, method_unit, sides, source_unit
from tatl_mj.experiments.spec import ExperimentSpec, load_spec, methods_from_spec

RANDOM = "random"  # the uniformly random reference policy


def _artifacts(spec, preset, seed: int, run_dir: str | None) -> source_unit.SourceArtifacts:
    if run_dir is not None:
        folder = RunDirectory(run_dir)
        blob = folder.blob_path(spec.name, seed)
        # is_done validates the cache against its record (and moves a corrupt one aside).
        if folder.is_done(spec.name, seed, "source"):
            return load_blob(folder.read_blob(spec.name, seed))
        print(f"note: no valid {blob}; training seed {seed} at preset {preset} instead")
    return source_unit.learn_source(spec, spec.preset(preset), seed)


def clip_policy(spec: ExperimentSpec, preset: str, seed: int, method: str, artifacts: Any) -> Any:
    """The policy a clip shows: the spec's ``method`` at the preset's largest budget, as evaluated."""
    if method == RANDOM:
        return sides.random_policy(spec.target, determinism.derive_seed(seed, "random-policy"))
    chosen = spec.preset(preset)
    transfer = methods_from_spec(spec, chosen, [method])[method]
    with warnings.catch_warnings(record=True) as caught:  # e.g. Algorithm 2's rule not met: one line each
        warnings.simplefilter("always")
        policy = method_unit.learned_policy(spec, chosen, seed, transfer, artifacts, max(chosen.target_budgets))
    for message in sorted({str(w.message) for w in caught}):
        meaning = (
            " (the apprentice then uses every sample: expected where the model never matches the target closely)"
            if "stopping rule" in message
            else ""
        )
        print(f"note: {message}{meaning}")
    return policy


def render_from_spec(
    spec_path: str,
    *,
    method: str,
    seed: int,
    out: str,
    seconds: float = 5.0,
    width: int = 640,
    height: int = 480,
    fps: int = 30,
    preset: str = "smoke",
    run_dir: str | None = None,
    with_source: bool = False,
) -> Path:
    suffix = Path(out).suffix.lower()
    if suffix not in render.CLIP_EXTENSIONS:
        raise ValueError(f"clip path must end in one of {render.CLIP_EXTENSIONS}, got {out!r}")
    spec = load_spec(spec_path)
    spec.preset(preset)  # an unknown preset fails here, naming the valid ones
    if method != RANDOM and method not in spec.methods:
        raise ValueError(f"unknown method {method!r} for {spec.name}; valid methods: {[*spec.methods, RANDOM]}")
    with determinism.one_thread():  # as a unit runs: the clip shows the evaluated policy
        return _render(spec, method, seed, out, seconds, width, height, fps, preset, run_dir, with_source)


def _render(
    spec: ExperimentSpec,
    method: str,
    seed: int,
    out: str,
    seconds: float,
    width: int,
    height: int,
    fps: int,
    preset: str,
    run_dir: str | None,
    with_source: bool,
) -> Path:
    target = spec.target
    needs_artifacts = method != RANDOM or with_source
    artifacts = _artifacts(spec, preset, seed, run_dir) if needs_artifacts else None
    policy = clip_policy(spec, preset, seed, method, artifacts)
    kwargs = {**target.task_kwargs, "random": determinism.derive_seed(seed, spec.stream_name, "clip")}
    env = suite.load(target.domain, target.task, task_kwargs=kwargs)
    source = None
    if with_source:
        src = spec.source
        source_env = suite.load(src.domain, src.task, task_kwargs={**src.task_kwargs, "random": 0})
        mapping = artifacts.mapping
        source = (source_env, lambda state: mapping.chi_plus(np.asarray(state)[None])[0])
    frames = render.render_episode(
        env,
        policy,
        seconds=seconds,
        width=width,
        height=height,
        fps=fps,
        method_label=f"{method.upper()} on {target.domain}/{target.task}",
        source=source,
    )
    render.write_clip(frames, out, fps)
    return Path(out)
