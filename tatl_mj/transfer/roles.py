"""The keys of a spec's ``[methods.NAME]`` table that are not settings, without importing any method.

Plain data: the spec loader, the registry and the reports read it. A method's roles (whether
it uses the source, what it is the ablation of, whether it is a baseline or privileged) are
not here: each method declares its own (``tatl_mj.transfer.method.contract``).
"""

from __future__ import annotations

from typing import Any

VARIANT_KEY = "method"
"""A spec's ``[methods.NAME]`` table may name a built-in here (``method = "ta-tl-h"``):
NAME is then a variant of it with these settings, reported under NAME (an ablation
such as ``ta-tl-h-no-cart``). Without it, NAME is the built-in itself. A value
``"module:attribute"`` names a user's own method instead (:func:`plugin_path`)."""


PAIR_KEYS = ("ablation", "placebo")
"""Keys of a spec's ``[methods.NAME]`` table that declare which method NAME is judged against
(its source-free ablation, its placebo; ``tatl_mj.experiments.results.pairs``): not settings."""


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


__all__ = ["PAIR_KEYS", "VARIANT_KEY", "base_of", "plugin_path"]
