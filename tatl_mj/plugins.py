"""A user's own object by import path, ``"module:attribute"``, for specs and workers alike.

One resolver, so that a domain and a method named in a spec fail the same way:
one line naming the path and what went wrong, a ``ValueError`` (or the subclass
given). Pure Python: importing it imports nothing else.
"""

from __future__ import annotations

import importlib
from typing import Any


def load(path: str, kind: str, error: type[ValueError] = ValueError) -> Any:
    """The attribute ``path`` names; ``error`` says which part failed (``kind``: "domain", "method")."""
    module_name, _, attribute = path.partition(":")
    if not module_name or not attribute:
        raise error(f"{kind} {path!r}: an import path must be 'module:attribute'")
    try:
        module = importlib.import_module(module_name)
    except Exception as failure:  # noqa: BLE001 - the user's module may raise anything on import
        raise error(
            f"{kind} {path!r}: cannot import module {module_name!r} ({type(failure).__name__}: {failure}); "
            "it must be importable here and in every worker (PYTHONPATH or installed)"
        ) from None
    if not hasattr(module, attribute):
        raise error(f"{kind} {path!r}: module {module_name!r} has no attribute {attribute!r}")
    return getattr(module, attribute)


__all__ = ["load"]
