"""Which pairs an experiment's spec declares for the verdicts, from the roles its methods declare.

A pair is (method, other, role): a transfer method against its source-free **ablation**, against
itself on a **placebo** source, or any method against the experiment's frozen **best baseline**.
The pairs are declared by the spec, not by which methods a run happens to hold:

- ablation: a method table's ``ablation = "NAME"`` (or ``["NAME", ...]``) key, else the methods
  whose ``ablation_of`` names the built-in (or plug-in) the table builds: every built-in's own table among them, else,
  where the spec lists only variants, every variant of the first one's built-in;
- placebo: a method table's ``placebo = "NAME"`` key, else the table of the same built-in
  whose method declares ``source = "placebo"`` and whose settings are otherwise the same;
- best baseline: the spec's ``best_baseline = {final = "...", efficiency = "..."}``, chosen on
  the tuning seeds (``verdicts.choose_best_baseline``) and frozen; every method that is not a
  baseline is compared with it, on the question it was chosen for.

Every role (``uses_source``, ``ablation_of``, ``baseline``, ``source``) is read from the method
the table builds (``tatl_mj.transfer.method.contract``), as the runner reads ``uses_source`` to
share a record: summary.json keeps the spec's tables, not the methods, so they are built here.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Mapping
from typing import Any

from tatl_mj.transfer import registry, roles
from tatl_mj.transfer.method import Contract, contract

FINAL, EFFICIENCY = "final", "efficiency"
QUESTIONS = (FINAL, EFFICIENCY)
ABLATION, PLACEBO, BEST_BASELINE = "ablation", "placebo", "best baseline"


@dataclasses.dataclass(frozen=True)
class Pair:
    """One declared comparison: ``method`` against ``other`` in a ``role``, on ``questions``."""

    method: str
    other: str
    role: str
    questions: tuple[str, ...] = QUESTIONS


def roles_of(spec_methods: Mapping[str, Any]) -> dict[str, Contract]:
    """Each of a spec's methods' roles, read from the method its table builds."""
    return {name: _roles(name, json.dumps(settings or {}, sort_keys=True)) for name, settings in spec_methods.items()}


@functools.lru_cache(maxsize=None)
def _roles(name: str, settings: str) -> Contract:
    table = json.loads(settings)
    try:
        return contract(registry.resolve(name, table))
    except ValueError:
        if _base(name, table) in registry.METHODS:  # a built-in or a variant of one must build
            raise
        # A table that builds nothing here: ``tatl compare``'s user methods (the summary's spec
        # holds their pairs, not their import paths) or a plug-in this machine cannot import.
        # They get the roles of a plug-in that declares none; their pairs are declared by name.
        return Contract()


def _base(name: str, settings: Mapping[str, Any] | None) -> str | None:
    """The built-in (or plug-in path) a table builds, None for a malformed ``method`` key."""
    try:
        return roles.base_of(name, dict(settings or {}))
    except ValueError:
        return None


def ablation_pairs(spec_methods: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(transfer method, its source-free ablation) for every such pair a spec declares.

    A table's ``ablation`` key names it (a list: each of them); otherwise a method that uses
    the source, on its trained source, pairs with the methods that declare themselves the ablation of its built-in
    (``ablation_of``; a variant, ``method = "ta-tl"``, pairs as its built-in): of those, every
    built-in's own table the spec lists (``ta-tl`` against both ``apprentice-fqi`` and
    ``apprentice-fqi-samples`` where the spec lists both), else, where it lists only variants,
    each variant of the first one's built-in. A placebo is itself an ablation, judged against
    its trained method only.
    """
    bases = {name: _base(name, settings) for name, settings in spec_methods.items()}
    held = roles_of(spec_methods)
    pairs = []
    for name, b in bases.items():
        settings = spec_methods.get(name) or {}
        if settings.get("ablation"):
            declared = settings["ablation"]
            pairs.extend((name, str(other)) for other in (declared if isinstance(declared, list) else [declared]))
            continue
        if held[name].source == "placebo" or not held[name].uses_source or b is None:
            continue
        found = [other for other in bases if other != name and b in held[other].ablation_of]
        # Every built-in's own table among them (apprentice-fqi and apprentice-fqi-samples for
        # ta-tl), else every variant of the first one's built-in.
        group = [other for other in found if other == bases[other]]
        if found and not group:
            group = [other for other in found if bases[other] == bases[found[0]]]
        pairs.extend((name, other) for other in group)
    return pairs


def placebo_pairs(spec_methods: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(transfer method, the same method on a placebo source) for every such pair a spec declares:
    a table's ``placebo`` key, else the table whose method declares ``source = "placebo"``, of
    the same built-in and with the settings otherwise the same."""
    ignored = (roles.VARIANT_KEY, "source", *roles.PAIR_KEYS)
    held = roles_of(spec_methods)

    def key(name: str) -> tuple[str, list] | None:
        settings = dict(spec_methods.get(name) or {})
        base = _base(name, settings)
        if base is None:
            return None
        return base, sorted((k, repr(v)) for k, v in settings.items() if k not in ignored)

    declared = [(n, str(s["placebo"])) for n, s in spec_methods.items() if (s or {}).get("placebo")]
    placebos = [n for n in spec_methods if held[n].source == "placebo"]
    trained = [n for n, s in spec_methods.items() if held[n].source == "trained" and not (s or {}).get("placebo")]
    matched = [(t, p) for p in placebos for t in trained if key(t) is not None and key(t) == key(p)]
    return declared + matched


def baselines(spec_methods: Mapping[str, Any]) -> list[str]:
    """The spec's methods that declare themselves baselines, in the spec's order."""
    return [name for name, held in roles_of(spec_methods).items() if held.baseline]


def best_baseline_pairs(spec_methods: Mapping[str, Any], best: Mapping[str, str]) -> list[Pair]:
    """Every listed method that is not a baseline against the frozen best baseline, one pair per
    baseline named (both questions when one baseline was chosen for both)."""
    by_baseline: dict[str, list[str]] = {}
    for question in QUESTIONS:
        if best.get(question):
            by_baseline.setdefault(best[question], []).append(question)
    excluded = set(baselines(spec_methods)) | set(best.values())
    pairs = []
    for baseline, questions in by_baseline.items():
        for name in spec_methods:
            if name not in excluded:
                pairs.append(Pair(name, baseline, BEST_BASELINE, tuple(questions)))
    return pairs


def declared_pairs(spec: Mapping[str, Any]) -> list[Pair]:
    """Every pair an experiment's spec declares, in table order: ablations, placebos, best baseline."""
    methods = spec.get("methods") or {}
    pairs = [Pair(m, a, ABLATION) for m, a in ablation_pairs(methods)]
    pairs += [Pair(m, p, PLACEBO) for m, p in placebo_pairs(methods)]
    return pairs + best_baseline_pairs(methods, spec.get("best_baseline") or {})


def source_free(name: str, settings: Mapping[str, Any] | None) -> bool:
    """Whether a spec's method reads no source (its ``uses_source`` is False)."""
    return not roles_of({name: settings})[name].uses_source


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


__all__ = [
    "ABLATION",
    "BEST_BASELINE",
    "EFFICIENCY",
    "FINAL",
    "PLACEBO",
    "QUESTIONS",
    "Pair",
    "ablation_pairs",
    "baselines",
    "best_baseline_pairs",
    "declared_pairs",
    "family_sizes",
    "parents_pair",
    "placebo_pairs",
    "roles_of",
    "source_free",
]
