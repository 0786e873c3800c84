"""A run's records as one tidy table: one row per experiment x method x seed x budget.

The long format pandas, seaborn and rliable users load in one line
(``pandas.read_csv("runs/paper/export.csv")``). CSV only: Parquet would need
pyarrow or pandas, heavy dependencies for a simulator package (convert with
``pandas.read_csv(...).to_parquet(...)`` where they are installed). Floats are
written as Python's ``repr``, so every value reads back exactly.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from tatl_mj.experiments.results import summary_data, verdicts
from tatl_mj.experiments.results.records import RunDirectory, read_record, write_atomic

FORMATS = ("csv",)
COLUMNS = (
    "experiment",
    "method",
    "seed",
    "budget",  # the budget of target samples the point was learned at
    "counted_transitions",  # every real-target transition counted (target_transitions)
    "rollout_transitions",  # of those, policy rollouts (Algorithm 2's U_M)
    "apprentice_samples",  # the shared samples it kept (samples_used; the paper's accounting)
    "mean_return",
    "normalised_score",  # (return - random) / (reference - random); empty without a reference return
    "mean_steps",
    "data",  # the data protocol
    "preset",
    "kernels",
    "schema_version",
    "tatl_mj_version",
    "dynamics",  # each task's dynamics version, "domain/task=N" separated by spaces
)


class ExportError(ValueError):
    """A run folder that cannot be exported; the message names it."""


def final_rows(rows: Iterator[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """Of ``rows``, each method, seed and experiment's row at its experiment's largest budget."""
    listed = list(rows)
    largest: dict[str, int] = {}
    for row in listed:
        largest[row["experiment"]] = max(largest.get(row["experiment"], row["budget"]), row["budget"])
    return (row for row in listed if row["budget"] == largest[row["experiment"]])


def rows(run_dir: str | Path) -> Iterator[dict[str, Any]]:
    """The export's rows, from the run's summary.json (its experiments, seeds, methods and
    reference returns) and its records, in that order."""
    run = RunDirectory(run_dir)
    try:
        summary = summary_data.read(run.summary)
    except FileNotFoundError:
        raise ExportError(f"{run.summary} not found: run `tatl run ... --out {run.root}` first") from None
    preset = summary.preset
    version = summary.versions.get("tatl-mj")
    for experiment, entry in summary.experiments.items():
        reference = entry.reference_return
        random = entry.random_by_seed or {}
        for method, data in entry.methods.items():
            for seed in data.seeds:
                record = read_record(run.record_path(experiment, seed, method))
                dynamics = " ".join(f"{task}={n}" for task, n in sorted(record["dynamics"].items()))
                for point in record["curve"]:
                    score = None
                    if reference is not None and reference > random[seed]:  # else no normalised scores
                        score = float(verdicts.normalised(np.array(point["mean_return"]), random[seed], reference))
                    yield {
                        "experiment": experiment,
                        "method": method,
                        "seed": seed,
                        "budget": point["samples"],
                        "counted_transitions": point["target_transitions"],
                        "rollout_transitions": point["rollout_transitions"],
                        "apprentice_samples": point["samples_used"],
                        "mean_return": point["mean_return"],
                        "normalised_score": score,
                        "mean_steps": point["mean_steps"],
                        "data": record["data"],
                        "preset": preset,
                        "kernels": record["kernels"],
                        "schema_version": record["schema_version"],
                        "tatl_mj_version": version,
                        "dynamics": dynamics,
                    }


def export(run_dir: str | Path, out: str | Path | None = None, fmt: str = "csv", final: bool = False) -> Path:
    """Writes the run's tidy table to ``out`` (default ``RUN_DIR/export.csv``, with ``final``
    ``RUN_DIR/export-final.csv``); returns its path. ``final``: only each method, seed and
    experiment's row at the experiment's largest budget (:func:`final_rows`)."""
    if fmt not in FORMATS:
        raise ExportError(f"--format {fmt}: valid formats: {list(FORMATS)} (Parquet would need pyarrow or pandas)")
    default = f"export-final.{fmt}" if final else f"export.{fmt}"
    path = Path(out) if out is not None else Path(run_dir) / default
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(final_rows(rows(run_dir)) if final else rows(run_dir))  # None is written as an empty cell
    write_atomic(path, text.getvalue().encode())
    return path
