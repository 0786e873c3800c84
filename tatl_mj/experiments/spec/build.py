"""A spec's methods built with its settings and a preset's defaults."""

from __future__ import annotations

from typing import Any

from tatl_mj.experiments.spec.schema import ExperimentSpec, Preset
from tatl_mj.transfer import registry, roles


def methods_from_spec(spec: ExperimentSpec, preset: Preset, names: list[str] | None = None) -> dict[str, Any]:
    """Every method of the spec (or the ``names`` among them), built with its settings.

    Algorithm 2's increment (``batch``), where a method has one and the spec leaves
    it unset, is the preset's smallest target budget; a model-based learner's
    ``model_samples``, likewise, is the preset's where it sets one.
    """
    chosen = list(spec.methods) if names is None else names
    out = {}
    for name in chosen:
        settings = dict(spec.methods.get(name, {}))
        if roles.plugin_path(settings) is None:
            known = registry.settings_of(roles.base_of(name, settings))
            if "batch" in known and settings.get("batch") is None:
                settings["batch"] = min(preset.target_budgets)
            if "model_samples" in known and "model_samples" not in settings and preset.model_samples is not None:
                settings["model_samples"] = preset.model_samples
        out[name] = registry.resolve(name, settings)
    return out
