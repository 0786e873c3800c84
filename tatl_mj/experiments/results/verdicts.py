"""The verdict rule: which pairs an experiment compares, the two questions asked of each, and how
each is judged (docs/protocol.md, "Verdicts", declares it with its reasons).

A pair is (method, other, role): a transfer method against its source-free **ablation**, against
itself on a **placebo** source, or any method against the experiment's frozen **best baseline**.
The pairs are declared by the spec, not by which methods a run happens to hold:

- ablation: a method table's ``ablation = "NAME"`` key, else the built-in pairing
  (``roles.ABLATION_OF``: the first of its built-in's ablations the spec lists);
- placebo: a method table's ``placebo = "NAME"`` key, else the table of the same built-in
  with ``source = "placebo"`` and otherwise the same settings;
- best baseline: the spec's ``best_baseline = {final = "...", efficiency = "..."}``, chosen on
  the tuning seeds (``choose_best_baseline``) and frozen; every method that is not a
  baseline is compared with it, on the question it was chosen for.

Each pair answers two questions, seed by seed on the seeds both finished (paired: a seed's
methods share its source policy, target samples and evaluation starts):

- **final**: the normalised score at the largest budget;
- **efficiency**: the area under the normalised curve over log counted real-target
  transitions (``statistics.efficiency_area``): one fixed range for every method of the
  experiment (the preset's smallest to largest budget), the random policy's score (0)
  before a method's first policy, scores floored at -1.

Each question's verdict comes from the paired sign statistic and its exact interval
(``statistics.sign_probability``): credited / worse / not credited. The efficiency question
is also answered on the paper's accounting (apprentice samples only, Algorithm 2's U_M
rollouts not counted), a secondary column. Within an experiment, each question's family is
its declared pairs; intervals are unadjusted and Holm's correction over the family is
reported beside them (``holm``). A mapping variant's pair of two methods without a source is
its parent's records: it belongs to the parent's family and is marked, not counted twice.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tatl_mj.experiments.results import statistics as stats
from tatl_mj.transfer import roles

VERDICT_RULE_VERSION = 2
"""Bumped whenever a change to this rule can move a verdict (written into summary.json).
1: P(X > Y) over all pairs of seeds on the area alone (unpaired), best baseline picked on the
reported seeds. 2: this module."""

FINAL, EFFICIENCY = "final", "efficiency"
QUESTIONS = (FINAL, EFFICIENCY)
ABLATION, PLACEBO, BEST_BASELINE = "ablation", "placebo", "best baseline"
SCORE_FLOOR = -1.0
"""Normalised scores below it count as it in the efficiency area: one blown-up fit (a score of
-10^6) cannot decide a seed; -1 is as far below random as the reference is above it."""
BEFORE_FIRST_POLICY = 0.0
"""What a method scores before its first policy: the random policy's normalised score. Every
data protocol here collects its first transitions with a random policy, and before a method
has returned a policy there is nothing of its own to deploy."""


@dataclasses.dataclass(frozen=True)
class Pair:
    """One declared comparison: ``method`` against ``other`` in a ``role``, on ``questions``."""

    method: str
    other: str
    role: str
    questions: tuple[str, ...] = QUESTIONS


def _base(name: str, settings: Mapping[str, Any] | None) -> str | None:
    try:
        return roles.base_of(name, dict(settings or {}))
    except ValueError:
        return None


def ablation_pairs(spec_methods: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(transfer method, its source-free ablation) for every such pair a spec declares.

    A table's ``ablation`` key names it; otherwise pairs go by built-in
    (``roles.ABLATION_OF``), so a variant (``method = "ta-tl"``) pairs with the
    ablation of its built-in: of the ablations a built-in names, the first the spec
    lists (the built-in's own table, else each variant of it). A placebo is itself an
    ablation, judged against its trained method only.
    """
    bases = {name: _base(name, settings) for name, settings in spec_methods.items()}
    pairs = []
    for name, b in bases.items():
        settings = spec_methods.get(name) or {}
        if settings.get("ablation"):
            pairs.append((name, str(settings["ablation"])))
            continue
        if settings.get("source") == "placebo":
            continue
        for wanted in roles.ABLATION_OF.get(b or "", ()):
            # The built-in itself where the spec lists it, else every variant of it.
            found = [wanted] if wanted in bases else [other for other, ob in bases.items() if ob == wanted]
            if found:
                pairs.extend((name, other) for other in found)
                break
    return pairs


def placebo_pairs(spec_methods: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(transfer method, the same method on a placebo source) for every such pair a spec declares:
    a table's ``placebo`` key, else the table with ``source = "placebo"`` of the same built-in
    whose settings are otherwise the same."""
    ignored = (roles.VARIANT_KEY, "source", *roles.PAIR_KEYS)

    def key(name: str) -> tuple[str, list] | None:
        settings = dict(spec_methods.get(name) or {})
        base = _base(name, settings)
        if base is None:
            return None
        return base, sorted((k, repr(v)) for k, v in settings.items() if k not in ignored)

    declared = [(n, str(s["placebo"])) for n, s in spec_methods.items() if (s or {}).get("placebo")]
    placebos = [n for n, s in spec_methods.items() if (s or {}).get("source") == "placebo"]
    trained = [
        n
        for n, s in spec_methods.items()
        if (s or {}).get("source", "trained") == "trained" and not (s or {}).get("placebo")
    ]
    matched = [(t, p) for p in placebos for t in trained if key(t) is not None and key(t) == key(p)]
    return declared + matched


def best_baseline_pairs(spec_methods: Mapping[str, Any], best: Mapping[str, str]) -> list[Pair]:
    """Every listed method that is not a baseline against the frozen best baseline, one pair per
    baseline named (both questions when one baseline was chosen for both)."""
    by_baseline: dict[str, list[str]] = {}
    for question in QUESTIONS:
        if best.get(question):
            by_baseline.setdefault(best[question], []).append(question)
    baselines = set(roles.BASELINES) | set(best.values())
    pairs = []
    for baseline, questions in by_baseline.items():
        for name, settings in spec_methods.items():
            if name in baselines or _base(name, settings) in roles.BASELINES:
                continue
            pairs.append(Pair(name, baseline, BEST_BASELINE, tuple(questions)))
    return pairs


def declared_pairs(spec: Mapping[str, Any]) -> list[Pair]:
    """Every pair an experiment's spec declares, in table order: ablations, placebos, best baseline."""
    methods = spec.get("methods") or {}
    pairs = [Pair(m, a, ABLATION) for m, a in ablation_pairs(methods)]
    pairs += [Pair(m, p, PLACEBO) for m, p in placebo_pairs(methods)]
    return pairs + best_baseline_pairs(methods, spec.get("best_baseline") or {})


def source_free(name: str, settings: Mapping[str, Any] | None) -> bool:
    """Whether a spec's method reads no source (a built-in of ``roles.SOURCE_FREE``)."""
    return _base(name, settings) in roles.SOURCE_FREE


def parents_pair(spec: Mapping[str, Any], pair: Pair) -> bool:
    """Whether ``pair`` is its parent's records: in a mapping variant (``streams`` names the
    experiment it shares its draws with), both methods read no source, so both records are
    the parent's and so is the verdict."""
    streams = spec.get("streams")
    if not streams or streams == spec.get("name") or spec.get("condition"):
        return False
    methods = spec.get("methods") or {}
    return source_free(pair.method, methods.get(pair.method)) and source_free(pair.other, methods.get(pair.other))


def family_sizes(spec: Mapping[str, Any]) -> dict[str, int]:
    """Per question, how many pairs the spec declares for it (a variant's parent's pairs excluded)."""
    pairs = [p for p in declared_pairs(spec) if not parents_pair(spec, p)]
    return {q: sum(q in p.questions for p in pairs) for q in QUESTIONS}


@dataclasses.dataclass(frozen=True)
class Answer:
    """One question of one pair: the paired sign statistic, its p-value, the effect size."""

    probability: stats.Estimate
    signs: stats.PairedSigns
    p_value: float
    median_difference: stats.Estimate
    unpaired: stats.Estimate

    @property
    def verdict(self) -> str:
        return stats.verdict(self.probability)

    def as_dict(self) -> dict:
        return {
            "probability": self.probability.as_dict(),
            "seeds": self.signs.as_dict(),
            "p_value": None if np.isnan(self.p_value) else float(self.p_value),
            "median_difference": self.median_difference.as_dict(),
            "unpaired_probability": self.unpaired.as_dict(),
            "verdict": self.verdict,
        }


def answer(x: np.ndarray, y: np.ndarray) -> Answer:
    """The paired answer for per-seed statistics ``x`` (the method) and ``y`` (the other), seed by seed."""
    signs = stats.paired_signs(x, y)
    return Answer(
        probability=stats.sign_probability(signs),
        signs=signs,
        p_value=stats.sign_p_value(signs),
        median_difference=stats.median_difference(x, y),
        unpaired=stats.improvement_interval([(np.asarray(x), np.asarray(y))]),
    )


def judge(
    spec: Mapping[str, Any],
    per_seed: Mapping[str, Mapping[str, np.ndarray]],
    paper_efficiency: Mapping[str, np.ndarray] | None = None,
) -> list[dict]:
    """Every declared pair whose methods both have per-seed statistics, answered.

    ``per_seed[question][method]`` holds the method's statistic on the compared seeds (the
    same seeds, in the same order, for every method); ``paper_efficiency[method]`` the
    efficiency area on the paper's accounting. Holm's correction runs per question over
    the family the spec declares (``family_sizes``).
    """
    sizes = family_sizes(spec)
    out = []
    for pair in declared_pairs(spec):
        have = all(pair.method in per_seed[q] and pair.other in per_seed[q] for q in pair.questions)
        if not have:
            continue
        entry: dict[str, Any] = {
            "method": pair.method,
            "other": pair.other,
            "role": pair.role,
            "parents": parents_pair(spec, pair),
        }
        for question in pair.questions:
            entry[question] = answer(per_seed[question][pair.method], per_seed[question][pair.other]).as_dict()
        if EFFICIENCY in pair.questions and paper_efficiency is not None:
            entry["efficiency_paper"] = answer(paper_efficiency[pair.method], paper_efficiency[pair.other]).as_dict()
        out.append(entry)
    for question in QUESTIONS:
        asked = [e for e in out if question in e and not e["parents"]]
        p_values = [e[question]["p_value"] if e[question]["p_value"] is not None else np.nan for e in asked]
        for entry, rejected in zip(asked, stats.holm(p_values, max(sizes[question], len(asked)))):
            entry[question]["holm"] = bool(rejected) and entry[question]["verdict"] != stats.NOT_CREDITED
    return out


def choose_best_baseline(experiment: Mapping[str, Any], baselines: Sequence[str]) -> dict[str, str]:
    """Per question, the baseline with the highest IQM of that question's per-seed statistic in a
    summary experiment (``final_iqm`` and ``efficiency``): run on the tuning seeds, then frozen
    in the spec's ``best_baseline``. Ties go to the baseline listed first."""
    methods = experiment.get("methods") or {}
    fields = {FINAL: "final_iqm", EFFICIENCY: "efficiency"}
    chosen = {}
    for question, field in fields.items():
        scored = [(b, (methods[b].get(field) or {}).get("value")) for b in baselines if b in methods]
        scored = [(b, v) for b, v in scored if v is not None]
        if scored:
            chosen[question] = max(scored, key=lambda bv: bv[1])[0]  # max keeps the first of equals
    return chosen


__all__ = [
    "ABLATION",
    "BEST_BASELINE",
    "EFFICIENCY",
    "FINAL",
    "PLACEBO",
    "QUESTIONS",
    "SCORE_FLOOR",
    "VERDICT_RULE_VERSION",
    "Answer",
    "Pair",
    "ablation_pairs",
    "answer",
    "best_baseline_pairs",
    "choose_best_baseline",
    "declared_pairs",
    "family_sizes",
    "judge",
    "parents_pair",
    "placebo_pairs",
    "source_free",
]
