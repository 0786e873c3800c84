"""The `tatl` command end to end, as a user runs it (subprocesses, tiny budgets)."""

import argparse
import json
import platform
import tomllib

import imageio.v3 as iio
import numpy as np
import pytest
from conftest import ROOT, tatl, write_tiny

from tatl_mj import cli
from tatl_mj.cli import run as run_cli


def test_list_prints_every_task():
    from tatl_mj import suite

    done = tatl("list")
    assert done.returncode == 0, done.stderr
    for domain, task in suite.ALL_TASKS:
        assert f"{domain}/{task}:" in done.stdout


def test_run_rejects_a_malformed_spec_with_file_and_key(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text().replace("gamma = 0.98", "gamma = 2.0", 1))
    done = tatl("run", str(bad), "--out", str(tmp_path / "out"))
    assert done.returncode == 2
    assert "bad.toml" in done.stderr and "source_learning.gamma" in done.stderr
    assert "Traceback" not in done.stderr


def test_run_then_plot(tmp_path):

    spec = write_tiny(tmp_path)
    out = tmp_path / "out"
    done = tatl("run", str(spec), "--preset", "tiny", "--seeds", "1", "--workers", "2", "--out", str(out))
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    listed = set(summary["experiments"]["ip_to_flipped_ip"]["spec"]["methods"])
    assert set(summary["experiments"]["ip_to_flipped_ip"]["methods"]) == listed >= {"ta-tl", "uma-tl", "rl"}
    assert summary["versions"]["mujoco"].startswith("3.")
    plotted = tatl("plot", str(out))
    assert plotted.returncode == 0, plotted.stderr
    figure = iio.imread(out / "figures" / "ip_to_flipped_ip.png")
    assert figure.shape[0] > 200 and figure.std() > 10  # a drawn figure, not a blank page
    table = (out / "results.md").read_text()
    assert "| TA-TL (paper, Alg. 1) |" in table and "| UMA-TL |" in table and "| RL (no transfer) |" in table


def test_run_with_a_plugin_method(tmp_path):

    spec = write_tiny(tmp_path)
    out = tmp_path / "out"
    env = {"PYTHONPATH": str(ROOT / "tests")}
    done = tatl(
        "run",
        str(spec),
        "--preset",
        "tiny",
        "--seeds",
        "1",
        "--workers",
        "1",
        "--out",
        str(out),
        "--methods",
        "rl,plugin_method:ZeroTorque",
        env=env,
    )
    assert done.returncode == 0, done.stderr
    methods = json.loads((out / "summary.json").read_text())["experiments"]["ip_to_flipped_ip"]["methods"]
    assert set(methods) == {"rl", "zero"}
    bad = tatl("run", str(spec), "--preset", "tiny", "--out", str(out), "--methods", "ta-tl,nope:Missing")
    assert bad.returncode == 2 and "--methods: method 'nope:Missing': cannot import module 'nope'" in bad.stderr
    # A discrete target (the grid world): the plug-in's policy returns action indices.
    grid = tatl(
        "run",
        "tasks/grid_to_windy.toml",
        "--seeds",
        "1",
        "--workers",
        "1",
        "--out",
        str(tmp_path / "grid"),
        "--methods",
        "plugin_method:ZeroTorque",
        env=env,
    )
    assert grid.returncode == 0, grid.stderr
    zero = json.loads((tmp_path / "grid" / "summary.json").read_text())["experiments"]["grid_to_windy"]["methods"]
    assert np.isfinite(zero["zero"]["final_return"])


def test_render_random_grid_world_clip(tmp_path):
    clip = tmp_path / "grid.mp4"
    done = tatl(
        "render",
        "tasks/grid_to_windy.toml",
        "--method",
        "random",
        "--seconds",
        "1",
        "--fps",
        "8",
        "--width",
        "160",
        "--height",
        "120",
        "--out",
        str(clip),
    )
    assert done.returncode == 0, done.stderr
    frames = iio.imread(clip)
    assert frames.shape[0] == 8 and frames.shape[1:3] == (120, 160)
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).max() > 0  # the agent moved
    assert "Traceback" not in done.stderr


def test_render_side_by_side_with_the_source(tmp_path):
    clip = tmp_path / "pair.mp4"
    done = tatl(
        "render",
        "tasks/grid_to_windy.toml",
        "--method",
        "ta-tl",
        "--with-source",
        "--seconds",
        "1",
        "--fps",
        "4",
        "--width",
        "160",
        "--height",
        "120",
        "--out",
        str(clip),
    )
    assert done.returncode == 0, done.stderr
    frames = iio.imread(clip)
    assert frames.shape == (4, 120, 320, 3)  # target and source panels side by side


def test_render_with_no_working_backend_says_how_to_fix(tmp_path):
    done = tatl(
        "render",
        "tasks/grid_to_windy.toml",
        "--method",
        "random",
        "--out",
        str(tmp_path / "x.mp4"),
        env={"MUJOCO_GL": "nonsense"},
    )
    assert done.returncode == 1
    assert "MUJOCO_GL" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "x.mp4").exists()


def _parsers(parser=None, prefix="tatl"):
    """(name, parser) for `tatl` and each of its subcommands, theirs included."""
    parser = parser or cli.build_parser()
    yield prefix, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _parsers(sub, f"{prefix} {name}")


def test_version_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as stop:
        cli.main(["--version"])
    assert stop.value.code == 0
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert capsys.readouterr().out.strip() == f"tatl {version}"


def test_every_option_and_subcommand_has_help_text():
    names = []
    for command, parser in _parsers():
        names.append(command)
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                missing = [c.dest for c in action._choices_actions if not (c.help or "").strip()]
                assert not missing, f"{command}: subcommands without help: {missing}"
                continue
            label = "/".join(action.option_strings) or action.dest
            assert action.help not in (None, argparse.SUPPRESS) and action.help.strip(), f"{command} {label}: no help"
        parser.format_help()  # every help string formats (e.g. no stray % signs)
    assert names == [
        "tatl",
        "tatl list",
        "tatl run",
        "tatl evaluate",
        "tatl plot",
        "tatl compare",
        "tatl reference",
        "tatl reference build",
        "tatl reference list",
        "tatl reference unpack",
        "tatl export",
        "tatl render",
        "tatl bench",
    ]


def test_run_with_an_unknown_method_says_so_in_one_line(tmp_path, capsys):
    # A typo in --methods: one line naming it and the methods the spec lists, no traceback, no work.
    out = tmp_path / "out"
    code = cli.main(
        [
            "run",
            "tasks/ip_to_flipped_ip.toml",
            "--methods",
            "ta-tl,ta-tl-replann",
            "--seeds",
            "1",
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("tatl run: --methods: unknown method 'ta-tl-replann'; valid forms: a built-in or a method ")
    from tatl_mj.experiments.spec import load_spec

    assert all(m in err for m in load_spec("tasks/ip_to_flipped_ip.toml").methods)
    assert not out.exists()
    # With two specs, a variant one of them lists: the other is named, with the methods it lists.
    specs = ["tasks/cartpole_to_bicycle.toml", "tasks/ip_to_flipped_ip.toml"]
    code = cli.main(["run", *specs, "--methods", "rl,ta-tl-h-no-cart", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and not out.exists(), err
    expected = "unknown method 'ta-tl-h-no-cart' for ip_to_flipped_ip; valid methods: ['ta-tl', 'ta-tl-placebo', "
    assert expected in err


def test_run_with_a_failing_unit_exits_non_zero_with_one_line(tmp_path, capsys):
    # tests/plugin_method.py's Broken raises in its worker: rl still finishes, nothing is lost,
    # and the run ends with 1 and one line saying how many units failed and where to look.
    spec = write_tiny(tmp_path)
    out = tmp_path / "out"
    args = ["run", str(spec), "--preset", "tiny", "--seeds", "1", "--workers", "1", "--out", str(out)]
    code = cli.main([*args, "--methods", "rl,plugin_method:Broken"])
    captured = capsys.readouterr()
    assert code == 1
    last = captured.err.strip().splitlines()[-1]
    assert last == (
        f"tatl run: 1 of 3 work units did not finish (1 failed); tracebacks in {out / 'failures'}/; "
        "rerun the same command to retry them"
    )
    assert "Traceback" not in captured.err
    traceback = (out / "failures" / "ip_to_flipped_ip__seed0__broken.txt").read_text()
    assert "deliberately broken plug-in" in traceback
    summary = json.loads((out / "summary.json").read_text())
    assert summary["experiments"]["ip_to_flipped_ip"]["methods"]["rl"]["seeds"] == [0]
    # The rerun retries only the failed unit; without it, the run succeeds and exits 0.
    assert cli.main([*args, "--methods", "rl"]) == 0


def test_run_with_a_bad_user_domain_is_one_line(tmp_path, capsys):
    import plugin_domain

    spec = tmp_path / "mine.toml"
    spec.write_text(plugin_domain.SPEC.replace('"plugin_domain:point_mass"', '"plugin_domain:pointmass"', 1))
    code = cli.main(["run", str(spec), "--preset", "tiny", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and not (tmp_path / "out").exists(), err
    assert err == (
        f"tatl run: {spec}: key 'source.domain': domain 'plugin_domain:pointmass': module 'plugin_domain' "
        "has no attribute 'pointmass'\n"
    )


def test_run_with_a_wrong_ray_address_is_one_line_and_touches_nothing(tmp_path, capsys):
    # Nothing listens at the address (a port just freed, on loopback): one line at once, not
    # Ray's minutes of retries, and the output folder is never made.
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    out = tmp_path / "out"
    base = [
        "run",
        str(write_tiny(tmp_path)),
        "--preset",
        "tiny",
        "--seeds",
        "1",
        "--out",
        str(out),
        "--executor",
        "ray",
    ]
    code = cli.main([*base, "--address", f"127.0.0.1:{port}"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err and not out.exists(), err
    assert err.startswith(f"tatl run: no Ray cluster answers at --address 127.0.0.1:{port} (Connection refused); ")
    code = cli.main([*base, "--address", "127.0.0.1"])
    err = capsys.readouterr().err
    assert code == 2 and err == (
        "tatl run: --address '127.0.0.1': expected host:port (e.g. 127.0.0.1:6379), 'auto' or ray://host:port\n"
    )


def test_a_built_in_that_cannot_run_on_a_spec_is_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main(["run", "tasks/ip_to_flipped_ip.toml", "--methods", "ta-tl-replan", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and not out.exists(), err
    assert "method 'ta-tl-replan' cannot run on ip_to_flipped_ip: ReplanTATL plans over cells" in err


def test_seeds_default_to_the_presets_own_and_must_agree(tmp_path):
    from tatl_mj.experiments import spec as spec_mod

    paper = [spec_mod.load_spec(ROOT / "tasks" / name) for name in ("ip_to_flipped_ip.toml", "mc_to_ip.toml")]
    args = argparse.Namespace(preset="paper", seeds=None, first_seed=None)
    assert run_cli._seeds(args, paper) == range(200, 210)  # held out: tuning used seeds 0-9
    assert run_cli._seeds(argparse.Namespace(preset="paper", seeds=3, first_seed=None), paper) == range(200, 203)
    assert run_cli._seeds(argparse.Namespace(preset="smoke", seeds=None, first_seed=None), paper) == range(0, 2)
    table = tomllib.loads((ROOT / "tasks" / "mc_to_ip.toml").read_text())
    table["presets"]["paper"]["first_seed"] = 300
    other = spec_mod.parse_spec(table, "mine.toml")
    assert run_cli._seeds(args, [paper[0], other]) == (
        "the specs' presets.paper.first_seed differ ([200, 300]): give --first-seed"
    )
    assert run_cli._seeds(argparse.Namespace(preset="paper", seeds=None, first_seed=7), [paper[0], other]) == range(
        7, 17
    )
    table["presets"]["paper"]["first_seed"] = -1
    with pytest.raises(spec_mod.SpecError, match=r"key 'presets.paper.first_seed' must be an integer >= 0, got -1"):
        spec_mod.parse_spec(table, "mine.toml")


def _default_blas_architecture() -> str | None:
    import threadpoolctl

    found = [i.get("architecture") for i in threadpoolctl.threadpool_info() if i["internal_api"] == "openblas"]
    return found[0] if found else None


@pytest.mark.skipif(
    platform.machine() != "x86_64" or _default_blas_architecture() in (None, "Sandybridge"),
    reason="needs x86-64 OpenBLAS whose own kernel is not Sandybridge, to force another one",
)
def test_a_run_resumed_under_other_kernels_records_both_and_says_so(tmp_path):
    spec = write_tiny(tmp_path)
    out = tmp_path / "out"
    first = tatl(
        "run", str(spec), "--preset", "tiny", "--seeds", "1", "--methods", "rl", "--workers", "1", "--out", str(out),
        env={"OPENBLAS_CORETYPE": "Sandybridge"},
    )  # fmt: skip
    assert first.returncode == 0, first.stderr
    assert "arithmetic kernels" not in first.stdout
    resumed = tatl("run", str(spec), "--preset", "tiny", "--seeds", "2", "--methods", "rl", "--out", str(out))
    assert resumed.returncode == 0, resumed.stderr
    records = out / "records" / "ip_to_flipped_ip"
    for seed, kernel in ((0, "Sandybridge"), (1, _default_blas_architecture())):
        for unit in ("source", "rl"):
            *blas, simd = json.loads((records / f"seed{seed}" / f"{unit}.json").read_text())["kernels"].split("; ")
            assert blas and all(k.startswith("openblas ") and k.endswith(f" {kernel}") for k in blas)
            assert simd.startswith("numpy ")
    counts = json.loads((out / "summary.json").read_text())["kernels"]
    assert sorted(counts.values()) == [2, 2] and len(counts) == 2
    assert "note: this run's records were computed with 2 sets of arithmetic kernels" in resumed.stdout


BAD_METHODS = {
    # an unknown built-in (a typo)
    "ta-tll": "unknown method 'ta-tll'; valid forms: ",
    # a dotted path written with a dot instead of a colon
    "mypkg.mine.OneStepMatch": (
        "unknown method 'mypkg.mine.OneStepMatch': your own is named with a colon before the class "
        "(mypkg.mine:OneStepMatch); valid forms: "
    ),
    # a class that is not a method
    "collections:OrderedDict": "method 'collections:OrderedDict' is not a TransferMethod (needs a name and ",
}


@pytest.mark.parametrize("command", ["run", "compare"])
@pytest.mark.parametrize("entry", sorted(BAD_METHODS))
def test_every_bad_methods_value_is_refused_in_one_line_before_anything_is_written(command, entry, tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main([command, "tasks/ip_to_flipped_ip.toml", "--methods", entry, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"tatl {command}: --methods: {BAD_METHODS[entry]}"), err
    assert "or your own as module:Class (e.g. mypkg.mine:MyMethod, a colon before the class)" in err
    assert ("NEW=BUILTIN" in err) == (command == "compare")
    assert not out.exists()
