"""Transfer algorithms of the paper: FQI (Phase I), manifold alignment (Phase II),
the target apprentice (Algorithm 2), the TA-TL policy (Algorithm 1), the UMA-TL and
RL baselines (``methods``), and the interface a user's own method implements (``method``).

Pure numpy / scipy / scikit-learn: nothing here imports mujoco or a suite domain.
"""

from __future__ import annotations

import importlib
from typing import Any

# Name -> the submodule that defines it. Imported on first use (PEP 562), so importing one
# submodule (the roles a spec reads) does not load every method and scikit-learn with it.
_EXPORTS = {
    "AffineMapping": "intertask_mapping",
    "IdentityMapping": "intertask_mapping",
    "LinearAlignment": "manifold_alignment",
    "Mapping": "intertask_mapping",
    "align_manifolds": "manifold_alignment",
    "Apprentice": "apprentice",
    "fit_apprentice": "apprentice",
    "learn_apprentice": "apprentice",
    "RBF": "features",
    "Features": "features",
    "LinearFeatures": "features",
    "OneHot": "features",
    "make_features": "features",
    "ExtraTrees": "fqi",
    "LinearQ": "fqi",
    "LinearRegressor": "fqi",
    "QFunction": "fqi",
    "fitted_q_iteration": "fqi",
    "make_regressor": "fqi",
    "Policy": "method",
    "TransferMethod": "method",
    "TransferProblem": "method",
    "RL": "methods.target_fqi",
    "UMATL": "methods.target_fqi",
    "MappedQ": "methods.target_fqi",
    "TargetFQI": "methods.target_fqi",
    "TATL": "methods.tatl",
    "METHODS": "registry",
    "TabularQ": "tabular_q",
    "q_iteration": "tabular_q",
    "DiscreteTATLPolicy": "algorithm1",
    "TATLPolicy": "algorithm1",
    "TATLStep": "algorithm1",
}


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value  # once: later lookups do not come back here
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_EXPORTS])


__all__ = sorted(_EXPORTS)
