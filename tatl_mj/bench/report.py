"""The printed table of ``tatl bench`` (without ``--json``)."""

from __future__ import annotations

from typing import Any


def print_record(record: dict[str, Any]) -> None:
    kind = record["kind"]
    if kind in ("steps", "vector") and "skipped" not in record:
        where = record["domain"] if kind == "steps" else f"{record['domain']}/{record['task']}"
        real_time = f", {record['real_time_factor']:.0f}x real time" if "real_time_factor" in record else ""
        peer = f", {record['env_id']}" if "env_id" in record else ""
        spread = (
            f", slowest of {record['repeats']}: {record['slowest_steps_per_s']:,.0f}"
            if record.get("repeats", 1) > 1
            else ""
        )
        print(
            f"{where:>13} {record['path']:>16}: {record['steps_per_s']:>11,.0f} steps/s "
            f"({record['steps']} steps in {record['seconds']:.2f} s{real_time}{peer}{spread})"
        )
    elif "skipped" in record:
        where = f" for {record['domain']}" if "domain" in record else ""
        where += f"/{record['task']}" if "task" in record else ""
        print(f"{kind}{where}: skipped ({record['skipped']})")
    elif kind == "fqi":
        print(
            f"FQI: {record['transitions']} transitions, {record['features']} RBF features, "
            f"{record['iterations']} iterations in {record['seconds']:.2f} s"
        )
    elif kind == "render":
        print(f"render: {record['fps']:.1f} frames/s at 640x480")
    elif kind == "memory":
        print(
            f"memory: {record['transitions']} cart-pole transitions stored in {record['stored_mb']:.1f} MB; "
            f"peak {record['peak_mb']:.1f} MB while collecting ({record['seconds']:.1f} s), "
            f"process max RSS so far {record['max_rss_mb']:.0f} MB"
        )
    elif kind == "summary":
        for domain, figures in record["domains"].items():
            peer = (
                f", {figures['sampler_vs_gymnasium']:.2f}x Gymnasium's loop"
                f" (raw rollout itself: {figures['rollout_vs_gymnasium']:.2f}x)"
                if "sampler_vs_gymnasium" in figures
                else ""
            )
            print(
                f"{domain:>13}: sampler {figures['sampler_vs_dm_control']:.1f}x dm_control, "
                f"{figures['sampler_vs_rollout']:.2f}x raw rollout"
                f" (median of each repeat's pair {figures['sampler_vs_rollout_paired']:.2f}){peer}; "
                f"raw rollout {figures['rollout_vs_dm_control']:.1f}x dm_control; "
                f"dm_control loop {figures['dm_control_vs_floor']:.2f}x dm_control's own floor"
            )
        for task, figures in record["vector"].items():
            print(_vector_line(task, figures, record["vector_envs"]))


def _vector_line(task: str, figures: dict[str, Any], num_envs: int) -> str:
    line = (
        f"{task}: native vector env ({num_envs} envs) {figures['vector_vs_rollout']:.2f}x raw rollout "
        f"(median of each repeat's pair {figures['vector_vs_rollout_paired']:.2f})"
    )
    if "contexts" in figures:
        return f"{line}, contexts {figures['contexts']} (raw rollout over the same per-env models)"
    return (
        f"{line}, {figures['vector_vs_sync_vector']:.1f}x SyncVectorEnv "
        f"(paired {figures['vector_vs_sync_vector_paired']:.1f}; raw rollout itself "
        f"{figures['rollout_vs_sync_vector']:.1f}x)"
    )
