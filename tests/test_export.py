"""The tidy export: one row per experiment x method x seed x budget, read back equal to the records."""

import csv
import math

import pytest
from conftest import tatl

from tatl_mj.experiments.results import export, records

EXPERIMENT = "tiny_flip"


def test_the_export_round_trips_against_the_records(tiny_reference, tmp_path):
    _, run, _ = tiny_reference
    path = export.export(run, tmp_path / "tidy.csv")
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == export.COLUMNS
    summary = records.read_record(run / "summary.json")
    experiment = summary["experiments"][EXPERIMENT]
    methods = list(experiment["methods"])
    assert len(rows) == len(methods) * 2 * 2  # two seeds, two budgets each
    for row in rows:
        record = records.read_record(
            run / "records" / row["experiment"] / f"seed{row['seed']}" / f"{row['method']}.json"
        )
        point = next(p for p in record["curve"] if p["samples"] == int(row["budget"]))
        assert float(row["mean_return"]) == point["mean_return"]  # repr round-trips every bit
        assert int(row["counted_transitions"]) == point["target_transitions"]
        assert int(row["rollout_transitions"]) == point["rollout_transitions"]
        assert int(row["apprentice_samples"]) == point["samples_used"]
        assert float(row["mean_steps"]) == point["mean_steps"]
        assert row["data"] == record["data"] and row["kernels"] == record["kernels"]
        assert (row["preset"], row["tatl_mj_version"], int(row["schema_version"])) == (
            "tiny",
            "0.1.0",
            records.SCHEMA_VERSION,
        )
        assert row["dynamics"] == "pendulum/swingup=1 pendulum/swingup_flipped=1"
        # The normalised score is the summary's, seed by seed and budget by budget.
        data = experiment["methods"][row["method"]]
        seed, budget = data["seeds"].index(int(row["seed"])), data["curve"]["samples"].index(int(row["budget"]))
        assert float(row["normalised_score"]) == pytest.approx(data["normalised"][seed][budget], abs=1e-12)
    assert all(math.isfinite(float(r["normalised_score"])) for r in rows)


def test_the_export_command_writes_csv_and_refuses_other_formats(tiny_reference, tmp_path):
    _, run, _ = tiny_reference
    done = tatl("export", str(run), "--out", str(tmp_path / "x.csv"))
    assert done.returncode == 0 and done.stdout == f"wrote {tmp_path / 'x.csv'}\n"
    parquet = tatl("export", str(run), "--format", "parquet")
    assert parquet.returncode == 2 and "invalid choice: 'parquet' (choose from 'csv')" in parquet.stderr
    missing = tatl("export", str(tmp_path / "nothing"))
    assert missing.returncode == 2
    assert missing.stderr == (
        f"tatl export: {tmp_path / 'nothing' / 'summary.json'} not found: run `tatl run ... --out "
        f"{tmp_path / 'nothing'}` first\n"
    )


def test_the_final_export_holds_one_row_per_method_seed_and_experiment_at_its_largest_budget(tiny_reference, tmp_path):
    _, run, _ = tiny_reference
    done = tatl("export", str(run), "--final")
    assert done.returncode == 0, done.stderr
    path = run / "export-final.csv"
    assert done.stdout == f"wrote {path}\n"
    with path.open(newline="") as handle:
        final = list(csv.DictReader(handle))
    with export.export(run, tmp_path / "all.csv").open(newline="") as handle:
        every = list(csv.DictReader(handle))
    keys = [(r["experiment"], r["method"], r["seed"]) for r in final]
    assert len(keys) == len(set(keys)) == len({(r["experiment"], r["method"], r["seed"]) for r in every})
    assert {r["budget"] for r in final} == {"120"}  # the tiny preset's largest
    assert final == [r for r in every if r["budget"] == "120"]
    path.unlink()
