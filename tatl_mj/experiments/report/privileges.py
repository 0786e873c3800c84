"""Who may credit whom, and how the tables say so: each method's privileges as a spec's tables
build it, the rule that a verdict credits transfer only against a comparator holding no privilege
the method lacks (:func:`credits`), the labels beside each side, and the order of a method's rows
(the non-privileged comparator first). Presentation of verdicts the unchanged rule gives
(``tatl_mj.experiments.results.verdicts``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from tatl_mj.experiments.results import pairs as pairs_mod
from tatl_mj.experiments.results import verdicts
from tatl_mj.experiments.results.summary_data import PairVerdict

ROLE_WORDS = {verdicts.ABLATION: "source-free", verdicts.PLACEBO: "placebo", verdicts.BEST_BASELINE: "best baseline"}
PRIVILEGED = "privileged"
"""The label of a method with target resources a robot lacks (simulator resets, the target's reward
function at states it chooses): a verdict against it does not credit transfer (docs/protocol.md)."""


def privileged(spec_methods: Mapping[str, object]) -> dict[str, frozenset[str]]:
    """The spec's privileged methods, each with the privileges its roles name (read from the built
    methods; ``tatl_mj.transfer.method.PRIVILEGES``)."""
    return {name: roles.privileges for name, roles in pairs_mod.roles_of(spec_methods).items() if roles.privileged}


def against(pair: PairVerdict, marked: Mapping[str, frozenset[str]]) -> str:
    """A pair's other side with its role, and ``privileged`` where it is (with :data:`NOT_CREDIT`
    where the verdict against it does not credit transfer, :func:`credits`)."""
    words = [ROLE_WORDS[pair.role], *([PRIVILEGED] if pair.other in marked else [])]
    note = "" if credits(pair, marked) else f": {NOT_CREDIT}"
    return f"`{pair.other}` ({', '.join(words)}{note})"


def method_cell(name: str, marked: Mapping[str, frozenset[str]]) -> str:
    """A pair's method, with ``(privileged)`` where it is."""
    return f"`{name}` ({PRIVILEGED})" if name in marked else f"`{name}`"


NOT_CREDIT = "does not credit or discredit transfer"
"""Said once per row, beside the comparator, where a pair does not credit (:func:`credits`)."""
INFORMATION = "information"
"""Beside each verdict of such a pair: printed as information, by the unchanged rule."""
MORE_ACTIONS = "more actions than its comparator"


def credits(pair: PairVerdict, marked: Mapping[str, frozenset[str]]) -> bool:
    """Whether a pair's verdict credits (or discredits) transfer: only where the comparator has no
    more target resources than the method, every privilege it holds (``marked``, by name) held by
    the method too: a non-privileged comparator always; ``uma-tl-reset`` against ``rl-reset`` (both
    reset the simulator); not ``ta-tl`` (the reward function on its apprentice's rollouts) against
    ``apprentice-fqi`` (the reward function on states from the whole reset box). A method's placebo
    has its privileges. The verdict of a pair that does not credit is printed as information
    (:data:`NOT_CREDIT`); the rule is unchanged."""
    return no_more_resources(marked, pair.method, pair.other)


def no_more_resources(marked: Mapping[str, frozenset[str]], method: str, other: str) -> bool:
    """Whether ``other`` holds no privilege that ``method`` lacks (``marked``: the privileged
    methods' privileges, :func:`privileged`)."""
    return marked.get(other, frozenset()) <= marked.get(method, frozenset())


def more_actions(pair: PairVerdict, spec_methods: Mapping[str, object]) -> bool:
    """Whether the pair's method chooses continuous actions and its comparator does not (the
    comparators choose from the target's discrete set): ``ta-tl-continuous``'s pairs."""

    def continuous(name: str) -> bool:
        table = spec_methods.get(name)
        return isinstance(table, Mapping) and table.get("actions") == "continuous"

    return continuous(pair.method) and not continuous(pair.other)


def _row_order(pair: PairVerdict, marked: Mapping[str, frozenset[str]]) -> tuple[int, bool]:
    """Within a method's rows: source-free comparators first, each non-privileged one before the
    privileged one beside it, then the placebo, then the best baseline."""
    roles = (verdicts.ABLATION, verdicts.PLACEBO, verdicts.BEST_BASELINE)
    return (roles.index(pair.role) if pair.role in roles else len(roles), pair.other in marked)


def ordered(
    pairs: Sequence[PairVerdict], marked: Mapping[str, frozenset[str]], methods: Sequence[str] = ()
) -> list[PairVerdict]:
    """A table's pairs grouped by method (``methods``' order first, then the declared order), each
    method's rows in :func:`_row_order`."""
    first: dict[str, int] = {}
    for pair in pairs:
        first.setdefault(pair.method, len(first))
    rank = {m: i for i, m in enumerate(methods)}

    def key(pair: PairVerdict) -> tuple[int, int, tuple[int, bool]]:
        return rank.get(pair.method, len(rank)), first[pair.method], _row_order(pair, marked)

    return sorted(pairs, key=key)


__all__ = [
    "INFORMATION",
    "MORE_ACTIONS",
    "NOT_CREDIT",
    "PRIVILEGED",
    "ROLE_WORDS",
    "against",
    "credits",
    "method_cell",
    "more_actions",
    "no_more_resources",
    "ordered",
    "privileged",
]
