"""How methods and numbers are shown, the same in every table and figure: labels, colours,
short numbers and intervals."""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tatl_mj.experiments.results.summary_data import Interval

COLORS = {"ta-tl": "#d62728", "uma-tl": "#1f77b4", "rl": "#2ca02c"}
LABELS = {"ta-tl": "TA-TL (paper, Alg. 1)", "uma-tl": "UMA-TL", "rl": "RL (no transfer)"}
# Colours for other methods, picked by a hash of the name (stable across runs);
# none is close to the fixed ones or to the grey/black reference lines.
PALETTE = ("#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#393b79", "#7b4173", "#e7ba52", "#008080")


def method_label(method: str) -> str:
    return LABELS.get(method, method)


def method_colors(methods: Sequence[str]) -> dict[str, str]:
    """A colour per method: fixed for known names, else by a hash of the name.

    Two methods of one figure never share a colour (a clash moves the later one
    to the next free palette entry).
    """
    taken: set[str] = set()
    colors = {}
    for m in methods:
        if m in COLORS:
            colors[m] = COLORS[m]
            taken.add(COLORS[m])
    for m in methods:
        if m in colors:
            continue
        start = zlib.crc32(m.encode()) % len(PALETTE)
        free = [PALETTE[(start + i) % len(PALETTE)] for i in range(len(PALETTE))]
        colors[m] = next((c for c in free if c not in taken), free[0])
        taken.add(colors[m])
    return colors


def order(method: str) -> tuple[int, str]:
    """Sort key: the paper's methods first, in the paper's order, then by name."""
    known = list(LABELS)
    return (known.index(method) if method in known else len(known), method)


def compact(value: float) -> str:
    """A short tick label: 250, 1.5k, 20k, -230k, 1.2M."""
    magnitude = abs(value)
    for scale, suffix in ((1e6, "M"), (1e3, "k")):
        if magnitude >= scale:
            return f"{value / scale:.3g}{suffix}"
    return f"{value:.3g}"


def spaced_ticks(values: Sequence[float], min_gap: float) -> list[float]:
    """``values`` (positive, for a log axis) thinned so neighbours are >= ``min_gap`` decades apart.

    The largest value is always kept (the final budget matters most).
    """
    kept: list[float] = []
    for v in sorted(set(values), reverse=True):
        if not kept or math.log10(kept[-1]) - math.log10(v) >= min_gap:
            kept.append(v)
    return sorted(kept)


def interval_text(estimate: Interval | None, fmt: str = ".2f") -> str:
    """``value [low, high]`` of a summary estimate; "(no interval)" where it has none."""
    if estimate is None or estimate.value is None:
        return "n/a"
    if estimate.low is None:
        return f"{estimate.value:{fmt}} (no interval)"
    return f"{estimate.value:{fmt}} [{estimate.low:{fmt}}, {estimate.high:{fmt}}]"


def samples_text(value: float | None) -> str:
    """A count of transitions, or "never" (infinite or missing)."""
    return "never" if value is None or math.isinf(value) else f"{int(value):,}"


def seed_range(seeds: Sequence[int] | None) -> str:
    """``100-109`` for a run of three or more consecutive seeds, else the list."""
    if not seeds:
        return "?"
    seeds = sorted(seeds)
    if seeds == list(range(seeds[0], seeds[-1] + 1)) and len(seeds) > 2:
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(str(s) for s in seeds)


__all__ = [
    "COLORS",
    "LABELS",
    "PALETTE",
    "compact",
    "interval_text",
    "method_colors",
    "method_label",
    "order",
    "samples_text",
    "seed_range",
    "spaced_ticks",
]
