"""The results table and figures, on hand-made summaries with known answers."""

import math

import numpy as np
import pytest
from PIL import Image

from tatl_mj.experiments.report import figures, style, tables
from tatl_mj.experiments.results import records
from tatl_mj.experiments.results.summary_data import Experiment, Summary

BUDGETS = [100, 1000, 10000]


def curve_for(samples_to_threshold: float | None) -> list[float]:
    """A return curve (threshold 9.5 with random 0 and best final 10) reaching it at the given budget."""
    if samples_to_threshold is None:
        return [0.0, 0.0, 5.0]
    return [10.0 if b >= samples_to_threshold else 0.0 for b in BUDGETS]


def experiment(reach: dict, seeds: dict | None = None) -> dict:
    methods = {}
    for name, values in reach.items():
        own = (seeds or {}).get(name, list(range(len(values))))
        curves = [curve_for(v) for v in values]
        methods[name] = {
            "seeds": own,
            "final_return": [c[-1] for c in curves],
            "curve": {"samples": BUDGETS, "mean_return": curves, "target_transitions": [BUDGETS] * len(curves)},
            "data": "shared",
        }
    all_seeds = sorted({s for m in methods.values() for s in m["seeds"]})
    return {
        "spec": {"title": "Toy"},
        "methods": methods,
        "source_seeds": all_seeds,
        "random_returns": [0.0] * len(all_seeds),
        "mapping_target_samples": [10],
    }


def summary(reach: dict, seeds: dict | None = None, methods: list | None = None) -> dict:
    return {
        "preset": "p",
        "seeds": [0, 1, 2],
        "threshold_fraction": 0.95,
        "methods": methods or list(reach),
        "experiments": {"toy": experiment(reach, seeds)},
    }


def typed(data: dict) -> Summary:
    """A hand-made summary (no schema version: an older one) as the readers get it, upgraded."""
    return Summary.from_json(records.upgrade(data))


def typed_experiment(exp: dict) -> Experiment:
    summary = {"preset": "p", "seeds": [0, 1, 2], "methods": list(exp["methods"]), "experiments": {"toy": exp}}
    return typed(summary).experiments["toy"]


def row(table: str, label: str) -> list[str]:
    line = next(line for line in table.splitlines() if line.startswith(f"| {label} |"))
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_transitions_to_threshold_on_both_accountings():
    result = summary({"ta-tl": [100, 100, None], "uma-tl": [1000, 1000, 100], "rl": [None, None, 1000]})
    table = tables.table(typed(result))
    assert row(table, "TA-TL (paper, Alg. 1)")[3:] == ["100 (2/3 reached, 2 at the smallest budget)", "100"]
    assert row(table, "UMA-TL")[3:] == ["1,000 (3/3 reached, 1 at the smallest budget)", "1,000"]
    assert row(table, "RL (no transfer)")[3:] == ["never (1/3 reached)", "never"]
    assert row(table, "TA-TL (paper, Alg. 1)")[2] == "8.333 ± 2.4 (10)"
    assert "Seed sets differ" not in table
    # 2,000 transitions of Algorithm 2's rollouts at every budget: counted, not on the paper's accounting.
    curve = result["experiments"]["toy"]["methods"]["ta-tl"]["curve"]
    curve["target_transitions"] = [[b + 2000 for b in BUDGETS]] * 3
    curve["rollout_transitions"] = [[2000] * 3] * 3
    assert row(tables.table(typed(result)), "TA-TL (paper, Alg. 1)")[3:5] == ["2,100 (2/3 reached)", "100"]


def test_table_compares_only_shared_seeds_and_says_so():
    # TA-TL finished seed 0 only; UMA-TL finished 0 and 1 and reached it only on seed 1.
    table = tables.table(
        typed(
            summary({"ta-tl": [100], "uma-tl": [None, 100], "rl": []}, seeds={"ta-tl": [0], "uma-tl": [0, 1], "rl": []})
        )
    )
    assert row(table, "UMA-TL")[3] == "never (0/1 reached)"
    assert row(table, "TA-TL (paper, Alg. 1)")[3] == "100 (1/1 reached, 1 at the smallest budget)"
    assert (
        "Seed sets differ: compared over seeds [0], the ones every method finished; UMA-TL also "
        "finished [1] (not compared); RL (no transfer) finished no seed (not shown)."
    ) in table


def test_table_without_meaningful_threshold_judges_final_returns():
    exp = experiment({"ta-tl": [None], "uma-tl": [None]})
    exp["random_returns"] = [50.0]  # every method ends at 5, below random
    table = tables.table(
        typed({"preset": "p", "seeds": [0], "methods": ["ta-tl", "uma-tl"], "experiments": {"toy": exp}})
    )
    assert "No meaningful threshold" in table and "Judged on final returns" in table
    assert row(table, "TA-TL (paper, Alg. 1)")[3:] == ["no meaningful threshold", "n/a"]


def test_axis_limits_clip_outliers_but_keep_references():
    values = [-100.0, -90.0, -80.0, -95.0, -500000.0]
    low, high = figures.axis_limits(values, keep=[-120.0])
    assert -130 < low < -120 and -80 < high < -75  # the -500,000 seed is left out, random kept
    assert figures.axis_limits([1.0, 2.0, 3.0]) == pytest.approx((0.88, 3.12))  # nothing to clip


def test_colours_are_stable_and_distinct():
    names = ["ta-tl", "uma-tl", "rl", "ta-tl-h", "ta-tl-replan", "apprentice-upright", "oracle", "oracle-h"]
    colours = style.method_colors(names)
    assert len(set(colours.values())) == len(names)
    assert colours["ta-tl"] == style.COLORS["ta-tl"]
    assert style.method_colors(["oracle"])["oracle"] == style.method_colors(["oracle", "ta-tl"])["oracle"]


def test_compact_labels_and_spaced_ticks():
    assert [style.compact(v) for v in (250, 1500, -230000, 1.2e6, 0.5)] == ["250", "1.5k", "-230k", "1.2M", "0.5"]
    assert style.spaced_ticks([100, 120, 1000, 10000], min_gap=0.5) == [120, 1000, 10000]  # largest kept first


@pytest.mark.parametrize("case", ["eight-methods", "seed-sets-differ", "no-threshold"])
def test_figure_is_drawn_for_any_number_of_methods(tmp_path, case):
    if case == "eight-methods":
        names = ["ta-tl", "uma-tl", "rl", "ta-tl-h", "ta-tl-replan", "apprentice-upright", "oracle", "oracle-h"]
        exp = experiment({m: [100, None, 1000] for m in names})
        exp["methods"]["rl"]["curve"]["mean_return"][0][1] = -5e5  # an outlier to clip
    elif case == "seed-sets-differ":
        exp = experiment({"ta-tl": [100], "uma-tl": [None, 100]}, seeds={"ta-tl": [0], "uma-tl": [0, 1]})
    else:
        exp = experiment({"ta-tl": [None], "uma-tl": [None]})
        exp["random_returns"] = [50.0]
    path = figures.figure("toy", typed_experiment(exp), tmp_path / "toy.png")
    image = np.asarray(Image.open(path).convert("RGB"))
    assert image.shape[1] == 1320 and image.shape[0] > 500
    # Every method's colour appears in the figure.
    for colour in style.method_colors(sorted(exp["methods"], key=style.order)).values():
        rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)])
        assert (np.abs(image.astype(int) - rgb).sum(axis=2) < 10).sum() > 20, colour
    assert math.isfinite(image.mean())


def test_table_says_whether_transfer_beats_its_ablation_without_the_source():
    result = summary({"ta-tl-replan": [100, 100, 1000], "replan-no-source": [10000, 10000, 10000]})
    result["experiments"]["toy"]["spec"]["methods"] = {"ta-tl-replan": {}, "replan-no-source": {}}
    table = tables.table(typed(result))
    assert "Transfer against its ablation without the source:" in table
    assert (
        "- `ta-tl-replan` vs `replan-no-source`: mean final return 10 vs 10 (higher on 0, lower on 0 of 3 seeds); "
        "median target transitions to threshold 100 vs 10,000 (fewer on 3, more on 0 of 3 seeds): "
        "`ta-tl-replan` **beats** its source-free ablation"
    ) in table
    del result["experiments"]["toy"]["spec"]["methods"]
    assert "ablation without the source" not in tables.table(typed(result))


@pytest.mark.parametrize("meaningful", [True, False], ids=["threshold", "no-threshold"])
def test_axes_say_what_a_return_is_and_titles_agree_with_them(tmp_path, drawn, meaningful):
    exp = experiment({"ta-tl": [100, 1000], "rl": [None, 10000]} if meaningful else {"ta-tl": [None], "rl": [None]})
    if not meaningful:
        exp["random_returns"] = [50.0]
    figures.figure("toy", typed_experiment(exp), tmp_path / "toy.png")
    (fig,) = drawn
    curve, length = fig.axes
    assert curve.get_ylabel() == "return (undiscounted episode sum)"
    assert "average" not in curve.get_title()
    if meaningful:
        assert length.get_ylabel() == "target transitions to threshold"
        assert length.get_title() == "(b) target transitions to threshold"
    else:
        assert length.get_ylabel() == "final return (undiscounted episode sum)"
        assert length.get_title().startswith("(b) final return")


def interval_experiment() -> dict:
    """An experiment with normalised statistics: ta-tl credited against its ablation on final,
    worse on efficiency; its first three budgets share one policy and count (Algorithm 2)."""
    exp = experiment({"ta-tl": [100, 100, 1000], "apprentice-fqi": [None, None, None]})
    for name, level in (("ta-tl", 0.95), ("apprentice-fqi", 0.2)):
        data = exp["methods"][name]
        data["curve"]["target_transitions"] = [BUDGETS] * 3
        data["curve"]["rollout_transitions"] = [[0] * 3] * 3
        data["iqm"] = [
            {"value": level * j / 2, "low": level * j / 2 - 0.1, "high": level * j / 2 + 0.1} for j in range(3)
        ]
    collapsed = exp["methods"]["ta-tl"]
    collapsed["curve"]["target_transitions"] = [[2100, 2100, 12000]] * 3
    collapsed["curve"]["rollout_transitions"] = [[2000, 2000, 2000]] * 3
    collapsed["iqm"][1] = dict(collapsed["iqm"][0])
    final = {
        "probability": {"value": 0.9, "low": 0.7, "high": 1.0},
        "seeds": {"better": 9, "tied": 0, "worse": 1},
        "verdict": "credited",
        "holm": False,
    }
    efficiency = {**final, "probability": {"value": 0.1, "low": 0.0, "high": 0.3}, "verdict": "worse"}
    exp["verdicts"] = [
        {"method": "ta-tl", "other": "apprentice-fqi", "role": "ablation", "final": final, "efficiency": efficiency}
    ]
    exp["reference_return"] = 10.0
    return exp


def test_interval_figure_draws_both_accountings_and_the_paired_verdicts(tmp_path, drawn):
    import matplotlib.collections

    figures.figure("toy", typed_experiment(interval_experiment()), tmp_path / "toy.png")
    (fig,) = drawn
    counted, paper, pairs = fig.axes
    assert counted.get_ylabel() == paper.get_ylabel() == figures.NORMALISED_LABEL
    assert counted.get_xlabel() == figures.ACCOUNTINGS["counted"] and paper.get_xlabel() == figures.ACCOUNTINGS["paper"]
    # One band per method, spanning its interval at the largest budget.
    bands = [c for c in counted.collections if isinstance(c, matplotlib.collections.PolyCollection)]
    assert len(bands) == 2
    top = max(bands, key=lambda b: b.get_paths()[0].vertices[:, 1].max())
    assert top.get_paths()[0].vertices[:, 1].max() == pytest.approx(0.95 + 0.1)
    # ta-tl's first two budgets share one point (2,100 counted; 100 on the paper's accounting):
    # it is drawn and says how many budgets it stands for, on both accountings.
    for ax, x in ((counted, 2100.0), (paper, 100.0)):
        (label,) = [t for t in ax.texts if t.get_text() == "x2"]
        assert label.xy[0] == x
    # Each question's interval and point, the 0.5 line and both verdicts.
    segments = [c for c in pairs.collections if isinstance(c, matplotlib.collections.LineCollection)]
    assert sorted(s.get_segments()[0][:, 0].tolist() for s in segments) == [[0.0, 0.3], [0.7, 1.0]]
    assert [t.get_text() for t in pairs.texts] == ["fin.: credited\neff.: worse"]
    assert pairs.get_yticklabels()[0].get_text() == "ta-tl > apprentice-fqi\n(ablation)"


def test_the_preamble_names_the_kernels_that_computed_the_records():
    reach = {"ta-tl": [100, 100, 100], "rl": [1000, 1000, 1000]}
    preamble = tables.table(typed(summary(reach))).split("\n\n")[0]
    assert "Arithmetic kernels" not in preamble  # a summary written before the field

    one = summary(reach) | {"kernels": {"openblas 0.3.31 SkylakeX; numpy X86_V4": 1030}}
    preamble = tables.table(typed(one)).split("\n\n")[0]
    assert preamble.endswith(
        "Arithmetic kernels: `openblas 0.3.31 SkylakeX; numpy X86_V4` (1,030 records). Per-seed returns "
        'depend on them, verdicts should not (docs/protocol.md, "Across machines").'
    )

    mixed = summary(reach) | {"kernels": {"openblas 0.3.31 SkylakeX": 4, "openblas 0.3.31 Haswell": 12, "unknown": 3}}
    preamble = tables.table(typed(mixed)).split("\n\n")[0]
    assert (
        "Arithmetic kernels: `openblas 0.3.31 Haswell` (12 records), `openblas 0.3.31 SkylakeX` (4 records); "
        "3 older records do not name theirs." in preamble
    )


def test_where_the_accountings_part_the_table_names_what_each_paid_before_a_first_policy():
    import types

    from tatl_mj.experiments.report import tables
    from tatl_mj.experiments.results.summary_data import Answer, Interval, PairVerdict

    def answer(verdict):
        return Answer(Interval(0.5, 0.2, 0.8), {"better": 5, "tied": 0, "worse": 5}, verdict)

    exp = types.SimpleNamespace(
        methods={
            "ta-tl": types.SimpleNamespace(first_policy={"counted": 300.0, "paper": 100.0}),
            "apprentice-fqi": types.SimpleNamespace(first_policy={"counted": 100.0, "paper": 100.0}),
        }
    )
    differ = PairVerdict("ta-tl", "apprentice-fqi", "ablation", False, None, answer("worse"), answer("not credited"))
    assert tables.why_accountings_differ(differ, exp) == (
        "before a first policy, counted / paper's: `ta-tl` 300 / 100; `apprentice-fqi` 100"
    )
    agree = PairVerdict("ta-tl", "apprentice-fqi", "ablation", False, None, answer("worse"), answer("worse"))
    assert tables.why_accountings_differ(agree, exp) == ""
