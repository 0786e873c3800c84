"""Property: any input to the spec loader either loads or raises SpecError, never anything else."""

import copy
import datetime
import tempfile
import tomllib
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from tatl_mj.experiments import spec as spec_mod  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SPEC_FILES = sorted((ROOT / "tasks").glob("*.toml"))
VALID = [tomllib.loads(p.read_text()) for p in SPEC_FILES]

# Every value TOML can hold.
scalars = st.one_of(
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
    st.floats(),
    st.text(max_size=12),
    st.dates(),
    st.times(),
    st.datetimes(),
    st.datetimes(timezones=st.just(datetime.timezone.utc)),
)
keys = st.text(min_size=1, max_size=10)
values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(keys, inner, max_size=4),
    max_leaves=12,
)


def _paths(table: dict, prefix: tuple = ()) -> list[tuple]:
    out = []
    for key, value in table.items():
        out.append(prefix + (key,))
        if isinstance(value, dict):
            out.extend(_paths(value, prefix + (key,)))
        elif isinstance(value, list):
            out.extend(prefix + (key, i) for i in range(len(value)))
    return out


@st.composite
def mutated_specs(draw) -> dict:
    """A real spec with a few keys replaced by random values, deleted, or added."""
    table = copy.deepcopy(draw(st.sampled_from(VALID)))
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(table)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = table
        for step in path[:-1]:
            parent = parent[step]
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "replace":
            parent[path[-1]] = draw(values)
        elif action == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[draw(keys)] = draw(values)
    return table


def _loads_or_spec_error(call) -> None:
    try:
        spec = call()
    except spec_mod.SpecError:
        return
    assert isinstance(spec, spec_mod.ExperimentSpec)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_specs())
def test_mutated_spec_tables_load_or_raise_spec_error(table):
    _loads_or_spec_error(lambda: spec_mod.parse_spec(table, "fuzz.toml"))


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(keys, values, max_size=6))
def test_random_tables_load_or_raise_spec_error(table):
    _loads_or_spec_error(lambda: spec_mod.parse_spec(table, "fuzz.toml"))


@settings(max_examples=200, deadline=None)
@given(
    st.one_of(
        st.binary(max_size=200),
        st.text(max_size=200).map(str.encode),
        # Real spec text cut short or with a line dropped: TOML that is nearly right.
        st.tuples(st.sampled_from(SPEC_FILES), st.integers(0, 4000)).map(lambda t: t[0].read_bytes()[: t[1]]),
        st.tuples(st.sampled_from(SPEC_FILES), st.integers(0, 80)).map(
            lambda t: b"\n".join(line for i, line in enumerate(t[0].read_bytes().splitlines()) if i != t[1])
        ),
    )
)
def test_random_files_load_or_raise_spec_error(data):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "fuzz.toml"
        path.write_bytes(data)
        _loads_or_spec_error(lambda: spec_mod.load_spec(path))


def test_every_shipped_spec_still_loads():
    for path in SPEC_FILES:
        assert spec_mod.load_spec(path).name == path.stem
