"""`tatl plot DIR`: a run's figures (``figures``, ``credit_maps``) and DIR/results.md (``tables``),
all read from DIR/summary.json."""

from __future__ import annotations

from pathlib import Path

from tatl_mj.experiments.report import credit_maps, figures, premises, tables
from tatl_mj.experiments.results import summary_data
from tatl_mj.experiments.results.comparison import comparison_of


def plot(run_dir: str | Path) -> list[Path]:
    """Writes DIR/figures/EXP.png and DIR/results.md; returns the written paths."""
    run_dir = Path(run_dir)
    summary_path = run_dir / "summary.json"
    if not summary_path.exists():
        raise FileNotFoundError(f"{summary_path} not found: run `tatl run ... --out {run_dir}` first")
    summary = summary_data.read(summary_path)  # an older schema's upgraded
    out = run_dir / "figures"
    out.mkdir(exist_ok=True)
    written = []
    for name, experiment in summary.experiments.items():
        if not comparison_of(experiment).seeds:
            continue
        written.append(figures.figure(name, experiment, out / f"{name}.png"))
    if summary.aggregate:
        written.append(figures.profile(summary, out / "performance_profile.png"))
    drawn = premises.premises_figure(summary, out / "premises.png")  # None: no record has premises
    if drawn is not None:
        written.append(drawn)
    credit = []
    for name, cells in credit_maps.sweeps(summary).items():
        written.append(credit_maps.credit_map(name, cells, out / f"credit_{name}.png"))
        credit.append(tables.credit_table(name, cells))
    results = run_dir / "results.md"
    why = premises.why_table(summary)
    why = f"\n## Why: the theorem's premises\n\n{why}" if why else ""
    results.write_text(tables.table(summary) + "\n" + tables.aggregate_table(summary) + "\n" + "\n".join(credit) + why)
    written.append(results)
    return written


__all__ = ["plot"]
