"""scripts/docs_tables.py: the README's and the docs' result blocks are the reference sets'
tables (a table and its data cannot drift apart), and the README stays a one-screen manual."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("docs_tables", ROOT / "scripts" / "docs_tables.py")
assert _spec is not None and _spec.loader is not None
docs_tables = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(docs_tables)


def test_an_empty_block_is_filled():
    text = "a\n<!-- begin: t -->\n<!-- end: t -->\nb\n"
    assert docs_tables.replace_block(text, "t", "| x |\n", "f") == "a\n<!-- begin: t -->\n| x |\n<!-- end: t -->\nb\n"


def test_a_filled_block_is_replaced_and_the_rest_kept():
    text = "a\n<!-- begin: t -->\nold\nlines\n<!-- end: t -->\nb\n<!-- begin: u -->\nkeep\n<!-- end: u -->\n"
    new = docs_tables.replace_block(text, "t", "new", "f")
    assert new == "a\n<!-- begin: t -->\nnew\n<!-- end: t -->\nb\n<!-- begin: u -->\nkeep\n<!-- end: u -->\n"
    assert docs_tables.replace_block(new, "t", "new", "f") == new  # idempotent


def test_a_missing_block_names_the_file_and_the_block():
    with pytest.raises(SystemExit, match="README.md: no block 'absent'"):
        docs_tables.replace_block("no markers here\n", "absent", "x", "README.md")


def test_the_shipped_tables_agree_with_the_reference_sets(capsys):
    assert docs_tables.main(["--check"]) == 0, capsys.readouterr().err


def test_the_readme_is_at_most_200_lines():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200
