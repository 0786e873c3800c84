"""Test-wide setup and shared helpers.

Frames drawn in the test process use EGL (set before the first one is drawn). The helpers
(tiny specs, the ``tatl`` command in a subprocess) are imported by test modules
as ``from conftest import ...``.
"""

import dataclasses
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

ROOT = Path(__file__).resolve().parents[1]
TINY = {
    "source_samples": 400,
    "alignment_samples": 40,
    "target_budgets": [40, 120],
    "evaluation_episodes": 2,
    "evaluation_steps": 40,
}


def tiny_spec(name: str = "ip_to_flipped_ip", **target_kwargs):
    """A shipped spec with the tiny preset and few FQI iterations; ``target_kwargs`` are set
    past the validator (which would refuse bad ones), to fault a worker on purpose."""
    from tatl_mj.experiments import spec as spec_mod

    table = tomllib.loads((ROOT / "tasks" / f"{name}.toml").read_text())
    table["presets"] = {"tiny": TINY}
    table["source_learning"]["iterations"] = 5
    for settings in table["methods"].values():
        if "iterations" in settings:
            settings["iterations"] = 5
    for learner in ("apprentice-fqi", "apprentice-fqi-samples", "apprentice-fqi-samples-rbf"):
        if learner in table["methods"]:
            table["methods"][learner]["model_samples"] = 2000
    spec = spec_mod.parse_spec(table, f"{name}.toml")
    if target_kwargs:
        target = dataclasses.replace(spec.target, task_kwargs=target_kwargs)
        spec = dataclasses.replace(spec, name=name + "_broken", target=target)
    return spec


def write_tiny(path: Path, name: str = "ip_to_flipped_ip") -> Path:
    """A shipped spec written under ``path`` with a ``tiny`` preset instead of its own."""
    text = (ROOT / "tasks" / f"{name}.toml").read_text().split("[presets.smoke]")[0]
    text += "[presets.tiny]\n" + "\n".join(f"{k} = {json.dumps(v)}" for k, v in TINY.items()) + "\n"
    out = path / f"{name}.toml"
    out.write_text(text)
    return out


def tatl(*args: str, env: dict | None = None, timeout: float = 600) -> subprocess.CompletedProcess:
    """``tatl ARGS`` in a subprocess from the repository root, headless."""
    return subprocess.run(
        [sys.executable, "-m", "tatl_mj.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl", "PYTHONPATH": str(ROOT), **(env or {})},
        cwd=ROOT,
    )


@pytest.fixture
def drawn(monkeypatch) -> list:
    """The matplotlib figures saved while a test runs, in order (their files are written too)."""
    import matplotlib.figure

    figures: list = []
    save = matplotlib.figure.Figure.savefig
    monkeypatch.setattr(
        matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: (figures.append(fig), save(fig, *a, **k))
    )
    return figures


# A small experiment for reference sets: the flipped pendulum with five methods (TA-TL, its
# placebo and ablation, two baselines) on two seeds, with a reference return above random.
FEATURES = (
    '{ kind = "rbf", centers = 25, low = [-3.14159, -8.0], high = [3.14159, 8.0], sigma = [1.2, 3.0], '
    "periodic = [true, false] }"
)
TINY_REFERENCE_SPEC = """
name = "tiny_flip"
title = "A tiny flipped pendulum"
paper_claim = "(test) none"
best_baseline = { final = "uma-tl", efficiency = "uma-tl" }

[source]
domain = "pendulum"
task = "swingup"
data = { sampling = "uniform", state_low = [-3.14159, -8.0], state_high = [3.14159, 8.0] }

[target]
domain = "pendulum"
task = "swingup_flipped"
data = { sampling = "episodes", episode_steps = 40 }

[source_learning]
features = FEATURES
gamma = 0.95
iterations = 5

[mapping]
kind = "identity"

[methods.ta-tl]
apprentice = { kind = "linear", periodic = [true, false] }
zeta = 0.1

[methods.ta-tl-placebo]
method = "ta-tl"
apprentice = { kind = "linear", periodic = [true, false] }
zeta = 0.1
source = "placebo"

[methods.apprentice-fqi]
apprentice = { kind = "linear", periodic = [true, false] }
features = FEATURES
iterations = 5
model_samples = 400

[methods.uma-tl]
features = FEATURES
iterations = 5

[methods.rl]
features = FEATURES
iterations = 5

[presets.tiny]
seeds = 2
source_samples = 400
alignment_samples = 40
target_budgets = [40, 120]
evaluation_episodes = 2
evaluation_steps = 40
reference_return = -200
""".replace("FEATURES", FEATURES)


@pytest.fixture(scope="session")
def tiny_reference(tmp_path_factory):
    """(spec path, run folder, reference set): a finished tiny run and the set packed from it."""
    from tatl_mj.experiments import spec as spec_mod
    from tatl_mj.experiments.results import reference
    from tatl_mj.experiments.run import runner

    folder = tmp_path_factory.mktemp("tiny-reference")
    path = folder / "tiny_flip.toml"
    path.write_text(TINY_REFERENCE_SPEC)
    run = folder / "run"
    runner.run([spec_mod.load_spec(path)], "tiny", [0, 1], run, workers=2, progress=False)
    built = reference.build(run, "tiny", f"tatl run {path} --preset tiny --out {run}", folder / "sets")
    return path, run, built
