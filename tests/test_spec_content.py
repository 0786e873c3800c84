"""A spec's content hash and its tasks' dynamics versions, as reference sets name them."""

import dataclasses
import json
import re
import tomllib

import pytest
from conftest import ROOT

from tatl_mj import suite
from tatl_mj.experiments import spec as spec_mod

FLIPPED = ROOT / "tasks" / "ip_to_flipped_ip.toml"


def test_a_reformatted_spec_keeps_its_hash(tmp_path):
    original = spec_mod.load_spec(FLIPPED)
    # The same content written another way: comments gone, tables reordered, inline tables,
    # numbers spelled differently, another file name and title.
    table = tomllib.loads(FLIPPED.read_text())
    table["title"] = "another title"
    lines = [f"{key} = {json.dumps(value)}" for key, value in reversed(table.items()) if not isinstance(value, dict)]
    for key, value in table.items():
        if isinstance(value, dict):
            lines.append(f"{key} = {_inline(value)}")
    text = "\n".join(lines) + "\n"
    text = text.replace("0.98", "9.8e-1")  # source_learning.gamma, another spelling of the same float
    assert "9.8e-1" in text
    moved = tmp_path / "elsewhere.toml"
    moved.write_text(text)
    again = spec_mod.load_spec(moved)
    assert again.title != original.title and again.path != original.path
    assert spec_mod.content_hash(again) == spec_mod.content_hash(original)
    assert spec_mod.content_hash(again, "paper") == spec_mod.content_hash(original, "paper")
    assert re.fullmatch(r"[0-9a-f]{64}", spec_mod.content_hash(original))


def _inline(value) -> str:
    """TOML for a value: inline tables, and lists of them (a list of features specs), as such."""
    if isinstance(value, list):
        return "[" + ", ".join(_inline(v) for v in value) + "]"
    if not isinstance(value, dict):
        return json.dumps(value)
    return "{ " + ", ".join(f'"{k}" = {_inline(v)}' for k, v in value.items()) + " }"


def test_a_changed_setting_changes_the_hash_and_another_preset_does_not_matter():
    base = tomllib.loads(FLIPPED.read_text())
    original = spec_mod.parse_spec(base, "a.toml")
    changed = json.loads(json.dumps(base))
    changed["methods"]["ta-tl"]["zeta"] = 123.0
    other = spec_mod.parse_spec(changed, "a.toml")
    assert spec_mod.content_hash(other) != spec_mod.content_hash(original)
    budgets = json.loads(json.dumps(base))
    budgets["presets"]["paper"]["target_budgets"] = [100, 200]
    tweaked = spec_mod.parse_spec(budgets, "a.toml")
    assert spec_mod.content_hash(tweaked, "paper") != spec_mod.content_hash(original, "paper")
    # Records of the smoke preset do not depend on the paper preset's budgets.
    assert spec_mod.content_hash(tweaked, "smoke") == spec_mod.content_hash(original, "smoke")


def test_the_hash_of_a_spec_as_summary_json_keeps_it_is_the_specs_own():
    spec = spec_mod.load_spec(FLIPPED)
    as_json = json.loads(json.dumps(spec_mod.spec_to_dict(spec)))
    assert spec_mod.content_hash(as_json, "paper") == spec_mod.content_hash(spec, "paper")


def test_every_task_declares_its_dynamics_version_apart_from_its_gym_id():
    for domain, task in suite.ALL_TASKS:
        assert suite.describe(domain, task).dynamics_version == 1, (domain, task)
    spec = spec_mod.load_spec(FLIPPED)
    assert spec_mod.dynamics_versions(spec) == {"pendulum/swingup": 1, "pendulum/swingup_flipped": 1}


def test_a_dynamics_version_must_be_a_whole_number_from_one():
    description = suite.describe("pendulum", "swingup")
    with pytest.raises(ValueError, match="dynamics_version must be >= 1, got 0"):
        dataclasses.replace(description, dynamics_version=0)
    with pytest.raises(ValueError, match="dynamics_version must be a whole number, got 1.5"):
        dataclasses.replace(description, dynamics_version=1.5)


def test_what_cannot_change_a_record_is_not_content():
    table = tomllib.loads(FLIPPED.read_text())
    original = spec_mod.parse_spec(table, "a.toml")
    frozen = spec_mod.parse_spec({**table, "best_baseline": {"final": "rl"}}, "a.toml")
    assert spec_mod.content_hash(frozen) == spec_mod.content_hash(original)


def test_a_variant_that_extends_its_parent_hashes_as_the_same_settings_written_out(tmp_path):
    parent = spec_mod.load_spec(FLIPPED)
    child = tmp_path / "child.toml"
    child.write_text(f'extends = "{FLIPPED}"\n')
    assert spec_mod.content_hash(spec_mod.load_spec(child)) == spec_mod.content_hash(parent)
