"""What several commands' options share: their argument types, --out's check and --methods' parsing."""

from __future__ import annotations

import argparse
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def int_at_least(low: int) -> Any:
    """An argparse type: a whole number >= ``low``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a whole number >= {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be >= {low}, got {value}")
        return value

    parse.__name__ = f"integer >= {low}"  # what argparse names in its error
    return parse


def non_empty(text: str) -> str:
    """An argparse type: a path that is not blank."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a non-empty path")
    return text


def check_out(out: str) -> str | None:
    """Why ``--out`` cannot hold a run, or None; touches nothing."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        return f"--out {out}: exists and is not a directory"
    existing = next((p for p in [path, *path.parents] if p.exists()), Path("."))
    if not existing.is_dir():
        return f"--out {out}: {existing} is not a directory"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"--out {out}: {existing} is not writable"
    return None


def parse_methods(text: str | None, specs: Sequence[Any] = ()) -> dict | None:
    """``ta-tl,rl,mypkg.mine:MyMethod`` -> {name: method object, or None for a built-in or a
    method the specs list}; None (no --methods): each spec's own ``[methods]``. ValueError in
    one line (``registry.parse_methods``)."""
    from tatl_mj.transfer import registry

    if text is None:
        return None
    methods = registry.parse_methods(text, [m for s in specs for m in s.methods])
    if not methods:
        raise ValueError("no methods given")
    return methods
