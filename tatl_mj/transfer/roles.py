"""What a method's name and its spec table say about it, without importing any method.

The roles the reports judge methods by (baselines, source-free ablations), and
the keys of a spec's ``[methods.NAME]`` table that are not settings. Plain data:
the experiments' reports read it without building a method, and
``tatl_mj.transfer.registry`` (which imports every method class) builds them.
"""

from __future__ import annotations

from typing import Any

SOURCE_FREE = ("rl", "rl-reset", "rl-online", "apprentice-fqi", "apprentice-upright", "replan-no-source")
"""Methods that never look at the source: the ablations a transfer win is measured against."""

ABLATION_OF: dict[str, tuple[str, ...]] = {
    "ta-tl": ("apprentice-fqi", "replan-no-source"),
    "ta-tl-h": ("apprentice-upright",),
    "ta-tl-replan": ("replan-no-source",),
    "ta-tl-replan-protocol": ("replan-no-source",),
    "uma-tl": ("rl",),
    "uma-tl-prior": ("rl",),
    "uma-tl-reset": ("rl-reset",),
}
"""Transfer method -> the built-ins that are the same method without the source, in
order of preference: the first a spec lists is the one a win must beat to be credited
to transfer (``ta-tl``: the model-based learner on its own apprentice; on the grid,
whose targets are cells, the planner on the tabular apprentice)."""

BASELINES = ("uma-tl", "rl", "rl-reset", "rl-online", "uma-tl-reset")
"""The comparison methods (reports compare every other method with them); ``-reset``
ones use privileged simulator resets."""


VARIANT_KEY = "method"
"""A spec's ``[methods.NAME]`` table may name a built-in here (``method = "ta-tl-h"``):
NAME is then a variant of it with these settings, reported under NAME (an ablation
such as ``ta-tl-h-no-cart``). Without it, NAME is the built-in itself. A value
``"module:attribute"`` names a user's own method instead (:func:`plugin_path`)."""


PAIR_KEYS = ("ablation", "placebo")
"""Keys of a spec's ``[methods.NAME]`` table that declare which method NAME is judged against
(its source-free ablation, its placebo; ``tatl_mj.experiments.results.verdicts``): not settings."""


def base_of(name: str, settings: dict[str, Any] | None = None) -> str:
    """The built-in a method table builds: its ``method`` key, else its own name.

    Whether that name is a built-in, and whether NAME may be a variant of it, is the
    registry's to check (``registry.build``)."""
    base = (settings or {}).get(VARIANT_KEY, name)
    if not isinstance(base, str):
        raise ValueError(f"{VARIANT_KEY!r} of method {name!r} must name a built-in method, got {base!r}")
    return base


def plugin_path(settings: dict[str, Any] | None) -> str | None:
    """The ``module:attribute`` a ``[methods.NAME]`` table's ``method`` key names, or None
    (a built-in or a variant of one)."""
    base = (settings or {}).get(VARIANT_KEY)
    return base if isinstance(base, str) and ":" in base else None


__all__ = ["ABLATION_OF", "BASELINES", "PAIR_KEYS", "SOURCE_FREE", "VARIANT_KEY", "base_of", "plugin_path"]
