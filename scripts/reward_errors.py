"""``apprentice-fqi-samples``'s reward and end model, its error on held-out samples: per experiment,
method (the comparator and its ``-rbf`` twin) and budget, the median over a preset's seeds.

What each unit's ``learn`` measures (``SampleModelPolicy.reward_errors``) and does not record: the
model fitted without a held-out fifth of the budget's samples, scored on that fifth. It depends on
the seed's shared target stream and the method's own settings and seed only, so it is recomputed
here from them, with no policy learned (``reward_errors``; tests/test_sample_model.py checks it
equals the learned policy's).

    PYTHONPATH=. .venv/bin/python scripts/reward_errors.py tasks/*.toml [--preset paper]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from tatl_mj.experiments.run.problems import learning_seed
from tatl_mj.experiments.run.sides import description_of
from tatl_mj.experiments.run.source_unit import target_stream
from tatl_mj.experiments.spec import ExperimentSpec, load_spec, methods_from_spec
from tatl_mj.transfer.methods.sample_model import ApprenticeFQISamples
from tatl_mj.transfer.reward_model import HeldOutErrors, held_out_errors, reward_bases


def reward_errors(spec: ExperimentSpec, preset: str, method: str, seed: int) -> list[HeldOutErrors]:
    """Per budget of ``preset``, the held-out errors ``method``'s unit of ``seed`` measures."""
    chosen = spec.preset(preset)
    learner = methods_from_spec(spec, chosen, [method])[method]
    target = description_of(spec.target)
    stream = target_stream(spec, chosen, seed)
    bases = reward_bases(learner.reward_basis, target.state_dim)
    out = []
    for budget in chosen.target_budgets:
        # The unit's own generator, first drawn from by the holdout (ApprenticeFQISamples.learn).
        rng = np.random.default_rng(learning_seed(spec, seed))
        fit = (bases, learner.reward_inputs, target.n_actions, learner.reward_ridge)
        out.append(held_out_errors(stream.head(budget), *fit, holdout=learner.holdout, rng=rng))
    return out


def _median(values: list[float | None]) -> float:
    present = [v for v in values if v is not None]
    return float(np.median(present)) if present else float("nan")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("specs", nargs="+")
    parser.add_argument("--preset", default="paper")
    args = parser.parse_args(argv)
    columns = "reward RMSE, smallest / largest budget | held-out rewards' std | ends mispredicted"
    print(f"| experiment | method | seeds | {columns} |")
    print("|---|---|---|---|---|---|")
    for path in args.specs:
        spec = load_spec(Path(path))
        chosen = spec.preset(args.preset)
        names = [
            n
            for n, m in methods_from_spec(spec, chosen, list(spec.methods)).items()
            if isinstance(m, ApprenticeFQISamples)
        ]
        seeds = range(chosen.first_seed, chosen.first_seed + chosen.seeds)
        for name in names:
            found = [reward_errors(spec, args.preset, name, seed) for seed in seeds]
            first, last = [f[0] for f in found], [f[-1] for f in found]
            print(
                f"| {spec.name} | `{name}` | {seeds[0]}-{seeds[-1]} "
                f"| {_median([e.reward_rmse for e in first]):.3g} / {_median([e.reward_rmse for e in last]):.3g} "
                f"| {_median([e.reward_scale for e in last]):.3g} | {_median([e.end_error for e in last]):.3g} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
