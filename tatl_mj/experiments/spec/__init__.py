"""Experiment specs: one TOML file per transfer experiment, validated on load.

A spec names the source and target tasks, how the source policy is learned,
the inter-task mapping, the transfer methods to compare with their settings
(``[methods.NAME]`` tables, built by ``tatl_mj.transfer.registry.resolve``), and named
presets of sample budgets and evaluation protocol. Validation calls the same
factories the workers use (``suite.describe``, ``make_regressor``, the method
constructors), so any unknown key (feature tables included), wrong type,
impossible value or setting that a choice ignores stops the load with a message
naming the file, the key path and what was expected. See ``tasks/*.toml``.

A user's own code is named by import path, ``"module:attribute"``, and imported
wherever the spec is used (here and in every worker): a side's ``domain``
(``tatl_mj.suite.domain``), and a ``[methods.NAME]`` table's ``method`` key, a
class built with the table's other settings (``tatl_mj.transfer.registry.resolve``).

The package, by job: ``schema`` (the dataclasses and SpecError), ``parse`` (a TOML table to
a spec), ``checks`` (its values), ``load`` (a spec file, ``extends`` and ``unset`` resolved),
``sweep`` (a sweep's conditions), ``build`` (its methods), ``content`` (its content hash and
dynamics versions). ``tatl_mj.suite`` is imported inside the functions that use it, not when
the package is.
"""

from tatl_mj.experiments.spec.build import methods_from_spec
from tatl_mj.experiments.spec.content import NOT_CONTENT, content_hash, dynamics_versions, spec_to_dict
from tatl_mj.experiments.spec.load import EXTENDS, UNSET, load_spec
from tatl_mj.experiments.spec.parse import parse_spec
from tatl_mj.experiments.spec.schema import (
    ALIGNMENT_DATA,
    NAME_PATTERN,
    SAMPLING_KINDS,
    SOURCE_LEARNERS,
    Data,
    ExperimentSpec,
    Learner,
    MappingSpec,
    Preset,
    Side,
    SpecError,
)
from tatl_mj.experiments.spec.sweep import conditions

__all__ = [
    "ALIGNMENT_DATA",
    "EXTENDS",
    "NAME_PATTERN",
    "NOT_CONTENT",
    "SAMPLING_KINDS",
    "SOURCE_LEARNERS",
    "UNSET",
    "Data",
    "ExperimentSpec",
    "Learner",
    "MappingSpec",
    "Preset",
    "Side",
    "SpecError",
    "conditions",
    "content_hash",
    "dynamics_versions",
    "load_spec",
    "methods_from_spec",
    "parse_spec",
    "spec_to_dict",
]
