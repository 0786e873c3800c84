"""docs/extending.md: every Python block runs as a script, as a reader would run it:
saved on its own in an empty folder outside the repository (under the file name
its first line gives, if any) and run from there, with only the package importable."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "extending.md").read_text(), flags=re.S)


def test_the_page_has_its_three_examples():
    assert len(BLOCKS) == 3


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=["spec", "method", "domain"][: len(BLOCKS)])
def test_example_runs_from_any_folder(index, tmp_path):
    block = BLOCKS[index]
    named = re.match(r"# (\w+\.py)\n", block)
    folder = tmp_path / "mine"  # a user's own folder: nothing of the repository in it or above it
    folder.mkdir()
    script = folder / (named.group(1) if named else "example.py")
    script.write_text(block)
    # Only the package is importable (as an installed one would be); not the repository's
    # folders, nor the folder the test runs from.
    scratch = tmp_path / "tmp"  # where the examples' temporary folders go (tempfile honours TMPDIR)
    scratch.mkdir()
    env = {
        **os.environ,
        "MUJOCO_GL": "disable",
        "PYTHONPATH": str(ROOT),
        "PYTHONDONTWRITEBYTECODE": "1",
        "TMPDIR": str(scratch),
    }
    done = subprocess.run(
        [sys.executable, script.name],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip(), "the example printed nothing"
    assert sorted(p.name for p in folder.iterdir()) == [script.name], "the example wrote into the folder it ran from"
    assert f"records in {scratch}" in done.stdout, done.stdout  # under the temporary folder
