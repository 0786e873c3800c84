"""The results table's samples-to-threshold ratios, on a hand-made summary."""

from tatl_mj.experiments import plot


def summary(samples_to_threshold: dict) -> dict:
    methods = {
        name: {"final_return": [1.0, 2.0, 3.0], "samples_to_threshold": values, "curve": {"samples": [100, 1000]}}
        for name, values in samples_to_threshold.items()
    }
    experiment = {
        "spec": {"title": "Toy"}, "threshold_meaningful": True, "methods": methods,
        "threshold": 1.5, "random_return": 0.0, "mapping_target_samples": [10],
    }
    return {"preset": "p", "seeds": [0, 1, 2], "threshold_fraction": 0.95, "experiments": {"toy": experiment}}


def row(table: str, label: str) -> list[str]:
    line = next(line for line in table.splitlines() if line.startswith(f"| {label} |"))
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_ratio_is_the_median_over_ta_tl_median():
    table = plot.table(summary({"ta-tl": [100, 100, None], "uma-tl": [1000, 1000, 100], "rl": [None, None, 1000]}))
    assert row(table, "TA-TL")[2:] == ["100 (2/3 seeds reached)", "-"]
    assert row(table, "UMA-TL")[2:] == ["1,000 (3/3 seeds reached)", "10.0x"]
    # RL's median seed never reached it: the ratio is at least the largest budget over TA-TL's.
    assert row(table, "RL (no transfer)")[2:] == ["not reached (1/3 seeds reached)", "> 10x (median seed never reached it)"]
    assert "mean ± sd" in table and "| 2 ± 0.82 |" in table


def test_ratio_when_ta_tl_never_reaches_the_threshold():
    table = plot.table(summary({"ta-tl": [None, None, 100], "uma-tl": [100, 100, 100], "rl": [None, None, None]}))
    assert row(table, "UMA-TL")[3] == "TA-TL (median seed) never reached it"
    assert row(table, "RL (no transfer)")[3] == "neither (median seed) reached it"
