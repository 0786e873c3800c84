"""What a run survives: kills, interrupts, corrupt records, a second run, bad input (issue 16)."""

import json
import logging
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, tiny_spec, write_tiny
from conftest import tatl as _tatl

from tatl_mj import suite
from tatl_mj.experiments import spec as spec_mod
from tatl_mj.experiments.results import records
from tatl_mj.experiments.run import lock
from tatl_mj.suite import bicycle, cartpole, mountain_car, pendulum

ENV = {**os.environ, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl", "PYTHONPATH": str(ROOT)}
linux_only = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")


def tatl(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return _tatl(*args, timeout=timeout)


def one_line_error(done: subprocess.CompletedProcess) -> str:
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    return lines[0]


# --- processes ------------------------------------------------------------------


def _stat(pid: int) -> tuple[int, str] | None:
    """(parent pid, state) of a live process, or None when it is gone (a zombie counts as gone)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    fields = text.rsplit(")", 1)[1].split()
    return (int(fields[1]), fields[0]) if fields[0] not in "ZX" else None


def descendants(pid: int) -> set[int]:
    parents = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (stat := _stat(int(entry.name))):
            parents[int(entry.name)] = stat[0]
    found, frontier = set(), {pid}
    while frontier:
        frontier = {child for child, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


def _kill_survivors(pids: set[int]) -> None:
    """Cleans up after a failing test: these are pids this test's run started."""
    for pid in pids:
        if _stat(pid):
            os.kill(pid, signal.SIGKILL)


def wait_for(condition, timeout: float, what: str) -> None:
    deadline = time.time() + timeout
    while not condition():
        assert time.time() < deadline, f"timed out waiting for {what}"
        time.sleep(0.1)


def start_run(tmp_path: Path, workers: int = 2, *extra: str) -> tuple[subprocess.Popen, Path]:
    """``tatl run`` in the background; its stderr goes to tmp_path/stderr.txt.

    Not a pipe: an orphaned worker would hold a pipe open and hang the test
    instead of failing it.
    """
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "tatl_mj.cli",
        "run",
        str(write_tiny(tmp_path)),
        "--preset",
        "tiny",
        "--seeds",
        "2",
        "--workers",
        str(workers),
        "--out",
        str(out),
        *extra,
    ]
    with open(tmp_path / "stderr.txt", "w") as stderr:
        return subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL, stderr=stderr), out


@linux_only
def test_sigkill_of_the_main_process_leaves_no_worker_or_tracker(tmp_path):
    proc, _ = start_run(tmp_path)
    try:
        # Two pool workers and the resource tracker.
        wait_for(lambda: len(descendants(proc.pid)) >= 3, 120, "the workers to start")
        children = descendants(proc.pid)
        _sigkill_and_wait(proc, children, 10, f"children {children} to end")
    finally:
        proc.kill()
        proc.wait()
        _kill_survivors(locals().get("children", set()))


def _sigkill_and_wait(proc: subprocess.Popen, children: set[int], seconds: float, what: str) -> None:
    """SIGKILLs the run's main process, then waits for every one of ``children`` to be gone."""
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    wait_for(lambda: not [p for p in children if _stat(p)], seconds, what)


def _names(pids: set[int]) -> dict[int, str]:
    out = {}
    for pid in pids:
        try:
            out[pid] = Path(f"/proc/{pid}/comm").read_text().strip()
        except OSError:
            pass
    return out


@linux_only
def test_sigkill_of_the_main_process_leaves_no_ray_process(tmp_path):
    # Without the reaper, Ray 2.60's dashboard and runtime-env agents outlive the driver by 20-30 s.
    pytest.importorskip("ray", reason="Ray is the optional extra tatl-mj[ray]")
    proc, _ = start_run(tmp_path, 2, "--executor", "ray")
    try:
        wait_for(lambda: "raylet" in _names(descendants(proc.pid)).values(), 120, "the local Ray instance")
        time.sleep(2)  # its agents and workers
        children = descendants(proc.pid)
        names = _names(children)
        assert {"gcs_server", "raylet"} <= set(names.values()), names
        _sigkill_and_wait(proc, children, 5, f"Ray processes {names} to end")
    finally:
        proc.kill()
        proc.wait()
        _kill_survivors(locals().get("children", set()))


@linux_only
@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_sigterm_and_sigint_stop_cleanly_and_keep_finished_units(tmp_path, signum, code):
    proc, out = start_run(tmp_path)
    try:
        wait_for(lambda: list((out / "records").rglob("source.json")), 240, "a finished unit")
        wait_for(lambda: len(descendants(proc.pid)) >= 2, 60, "the workers")
        children = descendants(proc.pid)
        proc.send_signal(signum)
        proc.wait(timeout=30)
    finally:
        proc.kill()
        proc.wait()
    try:
        wait_for(lambda: not [p for p in children if _stat(p)], 10, f"children {children} to end")
    finally:
        _kill_survivors(children)
    stderr = (tmp_path / "stderr.txt").read_text()
    assert proc.returncode == code, stderr
    assert "Traceback" not in stderr, stderr
    message = [line for line in stderr.splitlines() if "tatl run:" in line]
    assert len(message) == 1 and signal.Signals(signum).name in message[0], stderr
    assert list((out / "records").rglob("source.json")), "finished units must be kept"
    assert not list(out.rglob("*.tmp")), "an interrupted write must leave no temporary file"
    with lock.hold(out):  # released
        pass


def test_second_run_into_the_same_folder_refuses_naming_the_first(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"import sys, time\nfrom tatl_mj.experiments.run import lock\n"
            f"with lock.hold({str(out)!r}):\n print('held', flush=True)\n time.sleep(60)",
        ],
        env=ENV,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(lock.LockHeld, match=f"pid {holder.pid}"):
            with lock.hold(out):
                pass
        done = tatl("run", str(write_tiny(tmp_path)), "--preset", "tiny", "--seeds", "1", "--out", str(out))
        assert done.returncode == 2
        assert f"pid {holder.pid}" in one_line_error(done) and str(out) in done.stderr
        assert not (out / "run.json").exists(), "the refused run must not touch the folder"
    finally:
        holder.kill()
        holder.wait()
    # The holder died by SIGKILL, leaving its lock file: a new run takes it over.
    assert (out / lock.LOCK_NAME).read_text()
    with lock.hold(out) as path:
        assert json.loads(path.read_text())["pid"] == os.getpid()


# --- records ----------------------------------------------------------------------


def test_truncated_method_record_is_moved_aside_and_named(tmp_path, caplog):
    run_dir = records.RunDirectory(tmp_path)
    run_dir.write_unit("exp", 0, "rl", {"curve": [], "final_return": 1.0})
    assert run_dir.is_done("exp", 0, "rl")
    path = run_dir.record_path("exp", 0, "rl")
    path.write_bytes(path.read_bytes()[:7])
    with caplog.at_level(logging.WARNING):
        assert not run_dir.is_done("exp", 0, "rl")
    assert not path.exists() and path.with_name("rl.json.corrupt").exists()
    assert str(path) in caplog.text and "rl.json.corrupt" in caplog.text
    # A record that parses but lacks its keys is corrupt too.
    records.write_json(path, {"curve": []})
    assert not run_dir.is_done("exp", 0, "rl")
    assert path.with_name("rl.json.corrupt.1").exists()


@pytest.mark.parametrize("with_checksum", [True, False])
def test_truncated_source_cache_is_moved_aside_with_its_record(tmp_path, with_checksum):
    run_dir = records.RunDirectory(tmp_path)
    blob = pickle.dumps({"q": list(range(1000))}, protocol=pickle.HIGHEST_PROTOCOL)
    if with_checksum:
        run_dir.write_unit("exp", 0, "source", {"random_return": -1.0}, blob)
    else:  # a record from before checksums
        records.write_atomic(run_dir.blob_path("exp", 0), blob)
        records.write_json(run_dir.record_path("exp", 0, "source"), {"random_return": -1.0})
    assert run_dir.is_done("exp", 0, "source")
    assert pickle.loads(run_dir.read_blob("exp", 0)) == {"q": list(range(1000))}
    run_dir.blob_path("exp", 0).write_bytes(blob[: len(blob) // 2])
    assert not run_dir.is_done("exp", 0, "source")
    assert not run_dir.blob_path("exp", 0).exists() and not run_dir.record_path("exp", 0, "source").exists()
    assert run_dir.blob_path("exp", 0).with_name("source.pkl.corrupt").exists()


def test_missing_source_cache_makes_the_source_unit_rerun(tmp_path):
    run_dir = records.RunDirectory(tmp_path)
    run_dir.write_unit("exp", 0, "source", {"random_return": -1.0}, b"x.")
    run_dir.blob_path("exp", 0).unlink()
    assert not run_dir.is_done("exp", 0, "source")


def test_read_json_names_the_file_it_cannot_parse(tmp_path):
    path = tmp_path / "summary.json"
    path.write_bytes(b'{"experiments": {')
    with pytest.raises(records.RecordError, match=str(path)):
        records.read_json(path)
    path.write_bytes(b"\xff\xfe")
    with pytest.raises(records.RecordError, match=str(path)):
        records.read_json(path)


def test_run_recomputes_corrupt_records_and_caches(tmp_path):
    from tatl_mj.experiments.run import runner

    spec = tiny_spec()
    runner.run([spec], "tiny", [0], tmp_path, workers=1, methods=["rl"], progress=False)
    run_dir = records.RunDirectory(tmp_path)
    rl, blob = run_dir.record_path(spec.name, 0, "rl"), run_dir.blob_path(spec.name, 0)
    rl.write_text(rl.read_text()[:20])
    blob.write_bytes(blob.read_bytes()[:100])
    litter = rl.with_name(".rl.json.0123abcd.tmp")  # what a write cut short by a crash leaves
    litter.write_text('{"cur')
    summary = runner.run([spec], "tiny", [0], tmp_path, workers=1, methods=["rl"], progress=False)
    assert summary["failures"] == []
    assert summary["experiments"][spec.name]["methods"]["rl"]["seeds"] == [0]
    assert run_dir.is_done(spec.name, 0, "rl") and run_dir.is_done(spec.name, 0, "source")
    assert rl.with_name("rl.json.corrupt").exists() and blob.with_name("source.pkl.corrupt").exists()
    assert not litter.exists()


def test_a_run_stopped_inside_a_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    from tatl_mj.experiments.run import runner

    def stopped_mid_write(specs, preset, seeds, run_dir, *rest, **settings):
        tmp = run_dir.record_path(specs[0].name, 0, "rl").with_name(".rl.json.0123abcd.tmp")
        tmp.parent.mkdir(parents=True)
        tmp.write_text('{"cur')
        raise KeyboardInterrupt  # as a stop signal's handler raises, before the write's own cleanup

    monkeypatch.setattr(runner, "_run_locked", stopped_mid_write)
    with pytest.raises(KeyboardInterrupt):
        runner.run([tiny_spec()], "tiny", [0], tmp_path, workers=1, methods=["rl"], progress=False)
    assert not list(tmp_path.rglob("*.tmp"))
    assert (tmp_path / "records").is_dir()


# --- CLI input --------------------------------------------------------------------


@pytest.mark.parametrize(
    "args, named",
    [
        (["--seeds", "0"], "--seeds"),
        (["--seeds", "-1"], "--seeds"),
        (["--workers", "0"], "--workers"),
        (["--workers", "-3"], "--workers"),
        (["--first-seed", "-1"], "--first-seed"),
        (["--seeds", "two"], "--seeds"),
    ],
)
def test_run_refuses_bad_numbers_and_leaves_results_alone(tmp_path, args, named):
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text('{"kept": true}')
    done = tatl("run", str(write_tiny(tmp_path)), "--preset", "tiny", "--out", str(out), *args)
    assert done.returncode == 2
    assert named in done.stderr.strip().splitlines()[-1] and "Traceback" not in done.stderr
    assert (out / "summary.json").read_text() == '{"kept": true}'
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]


def test_run_refuses_an_empty_out(tmp_path):
    done = tatl("run", str(write_tiny(tmp_path)), "--preset", "tiny", "--out", "")
    assert done.returncode == 2 and "--out" in done.stderr and "Traceback" not in done.stderr


def test_run_names_every_bad_path(tmp_path):
    spec = write_tiny(tmp_path)
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff")
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    cases = [
        ((str(binary), "--out", str(tmp_path / "o")), str(binary)),
        ((str(tmp_path), "--out", str(tmp_path / "o")), str(tmp_path)),
        ((str(tmp_path / "missing.toml"), "--out", str(tmp_path / "o")), "missing.toml"),
        ((str(spec), str(tmp_path / ".." / tmp_path.name / spec.name), "--out", str(tmp_path / "o")), spec.name),
        ((str(spec), "--out", str(a_file)), str(a_file)),
        ((str(spec), "--out", str(a_file / "sub")), str(a_file)),
    ]
    for args, named in cases:
        done = tatl("run", *args, "--preset", "tiny")
        assert done.returncode == 2, (args, done.stderr)
        assert named in one_line_error(done), (args, done.stderr)
    assert not (tmp_path / "o").exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes through read-only modes")
def test_run_names_a_read_only_out(tmp_path):
    parent = tmp_path / "ro"
    parent.mkdir()
    parent.chmod(0o555)
    try:
        done = tatl("run", str(write_tiny(tmp_path)), "--preset", "tiny", "--out", str(parent / "out"))
    finally:
        parent.chmod(0o755)
    assert done.returncode == 2 and str(parent) in one_line_error(done)


def test_plot_names_a_truncated_summary(tmp_path):
    (tmp_path / "summary.json").write_text('{"experiments": {"a": ')
    done = tatl("plot", str(tmp_path))
    assert done.returncode == 2 and str(tmp_path / "summary.json") in one_line_error(done)
    (tmp_path / "summary.json").write_text('{"nothing": 1}')
    done = tatl("plot", str(tmp_path))
    assert done.returncode == 2 and "summary.json" in one_line_error(done)


@pytest.mark.parametrize("name", ["../../escape", "a/b", ".hidden", "", "x" * 101, "tab\tname", "-flag"])
def test_spec_names_that_are_not_safe_folder_names_are_refused(name):
    import tomllib

    table = tomllib.loads((ROOT / "tasks" / "ip_to_flipped_ip.toml").read_text())
    assert spec_mod.parse_spec({**table, "name": "my_exp-1.v2"}).name == "my_exp-1.v2"
    with pytest.raises(spec_mod.SpecError, match="'name'"):
        spec_mod.parse_spec({**table, "name": name}, "x.toml")


def test_runner_refuses_a_run_with_nothing_to_do(tmp_path):
    from tatl_mj.experiments.run import runner

    with pytest.raises(ValueError, match="nothing to run"):
        runner.run([tiny_spec()], "tiny", [], tmp_path / "out")
    assert not (tmp_path / "out").exists()


# --- suite input ------------------------------------------------------------------


@pytest.mark.parametrize("action", [np.zeros(2), np.zeros(10), np.zeros((1, 1)), [np.nan], [np.inf], "left"])
def test_bicycle_refuses_actions_off_its_spec(action):
    env = suite.load("bicycle", "balance", task_kwargs={"random": 0})
    env.reset()
    with pytest.raises(ValueError, match="action"):
        env.step(action)


def test_actions_of_the_spec_shape_and_plain_numbers_step():
    env = suite.load("cartpole", "balance", task_kwargs={"random": 0})
    env.reset()
    env.step(np.array([20.0]))
    env.step(20.0)
    env.step(np.array([1e6]))  # out of bounds: MuJoCo clips it to the ctrlrange
    assert env.physics.cart_force() == pytest.approx(20.0)


@pytest.mark.parametrize("domain, task", [(d, t) for d, t in suite.ALL_TASKS if d != "gridworld"])
@pytest.mark.parametrize("time_limit", [-1, 0, float("nan"), "5", None])
def test_time_limit_must_be_positive(domain, task, time_limit):
    with pytest.raises(ValueError, match="time_limit"):
        suite.load(domain, task, task_kwargs={"time_limit": time_limit})


@pytest.mark.parametrize("time_limit", [-1, 0, float("nan"), 2.5])
def test_gridworld_time_limit_must_be_whole_steps(time_limit):
    with pytest.raises(ValueError, match="time_limit"):
        suite.load("gridworld", "plain", task_kwargs={"time_limit": time_limit})


@pytest.mark.parametrize(
    "kwargs, named",
    [
        ({"speed": "fast"}, "speed"),
        ({"cg_noise": None}, "cg_noise"),
        ({"speed": True}, "speed"),
        ({"speed": -1.0}, "speed"),
        ({"cg_noise": float("nan")}, "cg_noise"),
    ],
)
def test_bicycle_task_kwargs_are_named(kwargs, named):
    with pytest.raises(ValueError, match=named):
        suite.load("bicycle", "balance", task_kwargs=kwargs)


def test_gridworld_flags_must_be_booleans():
    with pytest.raises(ValueError, match="random_start"):
        suite.load("gridworld", "plain", task_kwargs={"random_start": "no"})


@pytest.mark.parametrize(
    "make, field",
    [
        (lambda: pendulum.PendulumParams(mass="1"), "PendulumParams.mass"),
        (lambda: pendulum.PendulumParams(length=None), "PendulumParams.length"),
        (lambda: pendulum.PendulumParams(gravity=True), "PendulumParams.gravity"),
        (lambda: cartpole.CartPoleParams(pole_mass=-0.1), "CartPoleParams.pole_mass"),
        (lambda: mountain_car.MountainCarParams(damping=float("inf")), "MountainCarParams.damping"),
        (lambda: bicycle.BicycleParams(tyre_friction="1.2"), "BicycleParams.tyre_friction"),
    ],
)
def test_parameter_dataclasses_name_the_bad_field(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_parameter_dataclasses_take_numpy_numbers():
    assert pendulum.PendulumParams(mass=np.float32(2.0), length=np.int64(1)).mass == 2.0


@pytest.mark.parametrize("index", [1.7, 1.0, True, "1", None])
def test_discrete_action_takes_whole_numbers_only(index):
    with pytest.raises(ValueError, match="action index"):
        suite.discrete_action("cartpole", index)


def test_discrete_action_takes_numpy_integers():
    assert suite.discrete_action("cartpole", np.int64(2))[0] == 20.0


def test_set_pendulum_moves_the_drawn_geometry_at_once():
    physics = pendulum.make_physics()
    physics.set_state_vector([0.3, 0.0])
    qpos = physics.data.qpos.copy()
    physics.set_pendulum(1.6, 0.7)
    # The tip's world position (what a render draws) is at the new length without a forward().
    hinge = physics.named.data.xanchor["hinge"]
    tip = physics.named.data.geom_xpos["tip"]
    assert np.linalg.norm(tip - hinge) == pytest.approx(1.6, abs=1e-9)
    assert np.array_equal(physics.data.qpos, qpos)


def test_records_are_written_with_the_users_umask(tmp_path):
    old = os.umask(0o022)
    try:
        records.write_json(tmp_path / "a.json", {"x": 1})
    finally:
        os.umask(old)
    assert (tmp_path / "a.json").stat().st_mode & 0o777 == 0o644
    assert not list(tmp_path.glob("*.tmp"))
