"""What a source unit computes, per experiment and seed: the paper's phases I and II.

``learn_source``: the source policy (FQI, or exact Q-iteration for a task with a known
model), the random-policy target data stream shared by every method, the inter-task
mapping learned from random-policy samples of both tasks, and the uniformly random
policy's return, kept together as :class:`SourceArtifacts` (the run's source cache).
"""

from __future__ import annotations

import dataclasses
import time
from functools import partial
from typing import Any

import numpy as np

from tatl_mj.experiments.run.determinism import derive_seed
from tatl_mj.experiments.run.evaluation import target_returns
from tatl_mj.experiments.run.sides import description_of, random_policy, random_transitions
from tatl_mj.experiments.spec import ExperimentSpec, Preset
from tatl_mj.transfer import fqi, mappings, tabular_q
from tatl_mj.transitions import Transitions


@dataclasses.dataclass(frozen=True)
class SourceArtifacts:
    """Everything phase III needs, shared by the methods of one experiment and seed."""

    source_q: Any
    mapping: Any
    target_stream: Transitions
    random_return: float
    mapping_target_samples: int
    mapping_source_samples: int
    source_samples: int
    timings: dict
    mapping_record: dict | None = None  # the learned or given map's coefficients, for the records


def _source_q(spec: ExperimentSpec, preset: Preset, seed: int) -> tuple[Any, int]:
    learner = spec.source_learning
    source = description_of(spec.source)
    if learner.method == "q_iteration":  # exact, on the task's known model (checked at spec load)
        assert source.known_model is not None
        next_state, reward, absorbing, cells = source.known_model()
        return tabular_q.q_iteration(next_state, reward, absorbing, learner.gamma, cells=cells), 0
    n_actions = source.n_actions
    data = random_transitions(spec.source, preset.source_samples, derive_seed(seed, spec.stream_name, "source-data"))
    regressor = fqi.make_regressor(
        {**learner.regressor_spec(), "seed": derive_seed(seed, spec.stream_name, "source-fqi")},
        data.state_dim,
    )
    q = fqi.fitted_q_iteration(data, n_actions, regressor, learner.gamma, learner.iterations)
    return q, len(data)


def _alignment_source(spec: ExperimentSpec, n: int, seed: int) -> Transitions:
    """The source's samples for a learned map: random-policy episodes unless the spec asks for its box."""
    side = spec.source
    if spec.mapping.source_data == "episodes":
        side = dataclasses.replace(
            side, data=dataclasses.replace(side.data, sampling="episodes", state_low=(), state_high=())
        )
    return random_transitions(side, n, derive_seed(seed, spec.stream_name, "alignment-source"))


def _learn_mapping(
    spec: ExperimentSpec,
    preset: Preset,
    seed: int,
    stream: Transitions,
) -> tuple[Any, dict | None, int, int]:
    """Phase II: the mapping (in each task's mapping coordinates), its record, and the
    source and target samples it used (the target's are the stream's head, reused later);
    built by its kind's entry of ``mappings.MAPPINGS``."""
    inputs = mappings.MappingInputs(
        settings=spec.mapping,
        source=description_of(spec.source),
        target=description_of(spec.target),
        n=preset.alignment_samples,
        source_samples=partial(_alignment_source, spec, seed=seed),
        target_stream=stream,
        rng=lambda: np.random.default_rng(derive_seed(seed, spec.stream_name, "alignment")),
    )
    return mappings.MAPPINGS[spec.mapping.kind](inputs)


def target_stream(spec: ExperimentSpec, preset: Preset, seed: int) -> Transitions:
    """The seed's shared random-policy stream on the target, as long as the preset needs (its
    largest budget, or the mapping's samples): every method's first ``n`` come from it."""
    size = max(max(preset.target_budgets), preset.alignment_samples)
    return random_transitions(spec.target, size, derive_seed(seed, spec.stream_name, "target-data"))


def random_return(spec: ExperimentSpec, preset: Preset, seed: int) -> float:
    """The uniformly random policy's mean return from the experiment's evaluation starts: what
    every method's (and ``tatl evaluate``'s) normalised score of this seed is measured from; it
    needs no source work."""
    policy = random_policy(spec.target, derive_seed(seed, "random-policy"))
    returns, _ = target_returns(spec, preset, policy, derive_seed(seed, spec.stream_name, "evaluation"))
    return float(np.mean(returns))


def learn_source(
    spec: ExperimentSpec, preset: Preset, seed: int, shared: SourceArtifacts | None = None
) -> SourceArtifacts:
    """Phases I and II for one seed.

    ``shared``: the artefacts of an experiment that differs from this one only in its
    mapping and draws the same streams (``runner``): their source Q, target samples and
    random return are this one's, so only the mapping is learned (no phase is done twice).
    """
    timings = {"source_learning_s": 0.0, "target_sampling_s": 0.0}
    if shared is None:
        start = time.perf_counter()
        source_q, source_samples = _source_q(spec, preset, seed)
        timings["source_learning_s"] = time.perf_counter() - start

        start = time.perf_counter()
        stream = target_stream(spec, preset, seed)
        timings["target_sampling_s"] = time.perf_counter() - start
    else:
        source_q, source_samples, stream = shared.source_q, shared.source_samples, shared.target_stream

    start = time.perf_counter()
    mapping, mapping_record, n_map_source, n_map_target = _learn_mapping(spec, preset, seed, stream)
    timings["mapping_s"] = time.perf_counter() - start

    start = time.perf_counter()
    random_mean = random_return(spec, preset, seed) if shared is None else shared.random_return
    timings["random_evaluation_s"] = time.perf_counter() - start
    return SourceArtifacts(
        source_q=source_q,
        mapping=mapping,
        target_stream=stream,
        random_return=random_mean,
        mapping_target_samples=n_map_target,
        mapping_source_samples=n_map_source,
        source_samples=source_samples,
        timings=timings,
        mapping_record=mapping_record,
    )
