"""Reference returns of the pendulum targets: a long-budget learner on the reset protocol.

For each spec given, target FQI with the spec's ``rl`` settings on 50,000 one-step
transitions of the true target from states spread over its reset box (the
privileged protocol; ``rl-reset`` at a budget no preset gives), evaluated under
the paper preset's protocol on the tuning seeds 0-4 (never the reported ones);
prints the mean, which the spec declares as ``reference_return`` of its presets
(both evaluate 200-step episodes from the same start distribution). Run from the
repository root:

    .venv/bin/python scripts/reference_returns.py tasks/ip_to_flipped_ip.toml ...
"""

from __future__ import annotations

import sys

import numpy as np

from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.run import determinism, evaluation, problems, sides, source_unit
from tatl_mj.transfer.methods.target_fqi import RL

SAMPLES = 50_000
SEEDS = range(5)


def main(paths: list[str]) -> None:
    for path in paths:
        spec = spec_mod.load_spec(path)
        for name, preset in [("paper", spec.preset("paper"))]:
            returns = []
            for seed in SEEDS:
                learner = RL(**spec.methods["rl"])
                problem = problems.transfer_problem(spec, preset, _no_source(spec, preset), seed)
                policy = learner.learn(problem, problem.reset_samples(SAMPLES))
                seed_eval = determinism.derive_seed(seed, spec.stream_name, "evaluation")
                returns.append(float(np.mean(evaluation.target_returns(spec, preset, policy, seed_eval)[0])))
            print(f"{path} [presets.{name}] reference_return = {np.mean(returns):.0f}  # seeds 0-4: {returns}")


def _no_source(spec: spec_mod.ExperimentSpec, preset: spec_mod.Preset) -> source_unit.SourceArtifacts:
    """Artifacts with no source: the reference learner never looks at one."""
    from tatl_mj.transfer.fqi import ZeroQ
    from tatl_mj.transfer.intertask_mapping import IdentityMapping

    n_actions = sides.description_of(spec.target).n_actions
    stream = sides.random_transitions(spec.target, 10, 0)
    return source_unit.SourceArtifacts(ZeroQ(n_actions), IdentityMapping(), stream, 0.0, 0, 0, 0, {})


if __name__ == "__main__":
    main(sys.argv[1:])
