#!/usr/bin/env python
"""A real two-node Ray cluster on loopback, checked end to end (issue #30).

    python scripts/ray_cluster_check.py [--work DIR]

Needs Linux, root (it makes namespaces of its own with ``unshare``) and Ray
(``pip install 'tatl-mj[ray]'``); tests/test_ray_cluster.py runs it, skipped
where these are missing. It exits 0 when every check passed, 1 otherwise.

Ray 2.x advertises the machine's non-loopback interface even when given
``--node-ip-address 127.0.0.1``, and its driver probes 8.8.8.8 for the local
address. So the whole cluster and every run live in a network namespace
whose only interface is loopback (nothing here can send traffic elsewhere),
which is also a PID namespace of its own with its own /proc: this script
re-runs itself as that namespace's first process (PID 1), under
``unshare --net --pid --mount-proc --fork --kill-child``, and nothing it starts
can outlive it (when PID 1 ends, the kernel ends the namespace).

Inside, with ``RAY_AUTH_MODE=disabled`` (token authentication is on by default):

1. loopback up; a head (``ray start --head --port 6379 --num-cpus 1``) and a
   second node (``ray start --address 127.0.0.1:6379 --num-cpus 1``);
2. the reference: the tiny ``ip_to_flipped_ip`` spec (tests/conftest.py's TINY),
   methods ta-tl and rl, two seeds, on the local executor (one worker);
3. the same on the cluster (``--executor ray --address 127.0.0.1:6379``): its
   records must equal the reference's, field by field, timings aside;
4. again into a fresh folder, killing the second node's raylet (SIGKILL) while
   a unit runs on that node: the run must still finish with exit 0, no record
   written before the kill may change, no record may be written twice, and every
   record must equal the reference's (a run that ends before a unit runs on
   that node after a record is written is tried again afresh, up to 3 times);
5. a user's domain and method by import path (tests/plugin_domain.py's spec)
   on what is left of the cluster, equal to its local run;
6. a wrong address: one line, no traceback, exit 2, within seconds;
7. every process of the namespace but this one (GCS, raylets, workers, the
   dashboard and runtime-env agents, which outlive the raylet they belong to)
   stopped by pid, SIGTERM then SIGKILL, and none may be left.

Outside, once the namespace's PID 1 has exited, no process of that PID
namespace may remain.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PORT = 6379  # the namespace is this script's own: no other cluster can hold it
ADDRESS = f"127.0.0.1:{PORT}"
WRONG_ADDRESS = f"127.0.0.1:{PORT + 11}"
INSIDE = "--inside"
KILL_ATTEMPTS = 3
START = time.monotonic()
# Costs, not results (timings, MuJoCo substeps: the schedule's idle steps vary), and
# source.pkl's hash (the pickled artifacts hold their timings).
TIMING_KEYS = ("timings", "blob_sha256", "physics_substeps")


def say(text: str) -> None:
    print(f"[{time.monotonic() - START:6.1f} s] {text}", flush=True)


class CheckFailed(Exception):
    pass


def check(condition: bool, what: str, detail: str = "") -> None:
    """Says ``what`` held, or raises CheckFailed with it and ``detail`` (e.g. a command's output)."""
    if not condition:
        raise CheckFailed(f"{what}\n{detail}" if detail else what)
    say(f"ok: {what}")


# --- processes of the namespace -----------------------------------------------------


def processes() -> dict[int, tuple[int, str, str]]:
    """{pid: (parent pid, state, command line)} of every process here but this one."""
    out = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            stat = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:
            continue
        out[int(entry.name)] = (int(stat[1]), stat[0], cmdline)
    return out


def reap() -> None:
    """Collects exited orphans (this is PID 1: every orphan of the namespace is its child)."""
    for pid, (ppid, state, _) in processes().items():
        if ppid == os.getpid() and state == "Z":
            try:
                os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                pass


def stop_everything() -> list[str]:
    """SIGTERM, then SIGKILL, every process of the namespace but this one, by pid; what was stopped."""
    reap()
    alive = {pid: info for pid, info in processes().items() if info[1] != "Z"}
    names = [f"{pid} {cmd[:80]}" for pid, (_, _, cmd) in sorted(alive.items())]
    for pid in alive:
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(info[1] != "Z" for info in processes().values()):
        reap()
        time.sleep(0.2)
    for pid, (_, state, cmd) in processes().items():
        if state != "Z":
            say(f"{pid} outlived SIGTERM by 15 s; SIGKILL: {cmd[:80]}")
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and processes():
        reap()
        time.sleep(0.2)
    return names


# --- commands -------------------------------------------------------------------------


def environment() -> dict[str, str]:
    env = {
        **os.environ,
        "RAY_AUTH_MODE": "disabled",
        "RAY_USAGE_STATS_ENABLED": "0",
        # The cluster's workers import tatl_mj and the test's own domain and method from here.
        "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests")]),
        "MUJOCO_GL": "disable",
    }
    env.pop("PYOPENGL_PLATFORM", None)
    return env


def run(args: list[str], timeout: float) -> subprocess.CompletedProcess:
    done = subprocess.run(args, env=environment(), capture_output=True, text=True, timeout=timeout)
    reap()
    return done


def tatl(*args: str) -> list[str]:
    return [sys.executable, "-m", "tatl_mj.cli", "run", *args]


def stripped(value):
    """A record without its timings (keys ending in _s, and TIMING_KEYS)."""
    if isinstance(value, dict):
        return {k: stripped(v) for k, v in value.items() if not k.endswith("_s") and k not in TIMING_KEYS}
    if isinstance(value, list):
        return [stripped(v) for v in value]
    return value


def records(out: Path) -> dict[str, dict]:
    return {
        str(p.relative_to(out / "records")): stripped(json.loads(p.read_text()))
        for p in sorted((out / "records").rglob("*.json"))
    }


def same_records(mine: Path, reference: Path) -> bool:
    a, b = records(mine), records(reference)
    if a.keys() != b.keys():
        say(f"record files differ: {sorted(a.keys() ^ b.keys())}")
        return False
    differ = [name for name in a if a[name] != b[name]]
    for name in differ:
        keys = sorted(k for k in a[name].keys() | b[name].keys() if a[name].get(k) != b[name].get(k))
        say(f"{name} differs in {keys}")
    return bool(a) and not differ


# --- the checks -------------------------------------------------------------------------


def raylet_of_second_node(before: set[int]) -> int:
    raylets = [
        pid
        for pid, (_, _, cmd) in processes().items()
        if pid not in before and cmd.split(" ", 1)[0].endswith("/raylet")
    ]
    check(len(raylets) == 1, f"the second node has one raylet of its own ({raylets})")
    return raylets[0]


def run_and_kill(
    spec: str, common: list[str], out: Path, raylet2: int
) -> tuple[subprocess.Popen, str, dict[Path, int] | None, set[Path]]:
    """Runs the tiny spec on the cluster into ``out``, killing the second node's raylet (SIGKILL)
    as soon as a unit runs there and a record is written: the run, its output, each record's
    mtime at the kill (None if it never came) and the records written twice."""
    proc = subprocess.Popen(
        tatl(spec, *common, "--seeds", "2", "--executor", "ray", "--address", ADDRESS, "--out", str(out)),
        env=environment(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    seen: dict[Path, int] = {}
    rewritten: set[Path] = set()
    at_kill: dict[Path, int] | None = None
    deadline = time.monotonic() + 600
    while proc.poll() is None and time.monotonic() < deadline:
        for path in (out / "records").rglob("*.json") if (out / "records").exists() else ():
            stamp = path.stat().st_mtime_ns
            if seen.setdefault(path, stamp) != stamp:
                rewritten.add(path)
        here = processes()
        busy = [pid for pid, (ppid, _, cmd) in here.items() if ppid == raylet2 and cmd.startswith("ray::work")]
        if at_kill is None and busy and seen:  # a unit runs there, and some records are already written
            os.kill(raylet2, signal.SIGKILL)
            at_kill = dict(seen)
            say(f"killed the second node's raylet (pid {raylet2}) while it ran a unit (worker {busy[0]}); "
                f"{len(at_kill)} records written before")  # fmt: skip
        reap()
        time.sleep(0.05)
    if proc.poll() is None:
        proc.kill()
    output = proc.communicate()[0]
    reap()
    return proc, output, at_kill, rewritten


def inside(work: Path) -> int:
    sys.path.insert(0, str(ROOT / "tests"))
    from conftest import write_tiny
    from plugin_domain import SPEC

    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)
    links = subprocess.run(["ip", "-o", "link"], capture_output=True, text=True, check=True).stdout.splitlines()
    temp = Path(tempfile.mkdtemp(prefix="tatl-ray-", dir="/tmp"))  # short: Ray's socket paths must fit 107 bytes
    failed = None
    try:
        check([line.split(":")[1].strip() for line in links] == ["lo"], "loopback is the only interface")
        spec = write_tiny(work)
        point_mass = work / "point_mass.toml"
        point_mass.write_text(SPEC)
        common = ["--preset", "tiny", "--methods", "ta-tl,rl"]

        head = [
            str(Path(sys.executable).with_name("ray")),
            "start",
            "--node-ip-address",
            "127.0.0.1",
            "--num-cpus",
            "1",
        ]
        done = run([*head, "--head", "--port", str(PORT), "--include-dashboard", "false", "--temp-dir", str(temp)], 120)
        check(done.returncode == 0, "ray start --head", done.stderr[-500:])
        before = set(processes())
        done = run([*head, "--address", ADDRESS], 120)
        check(done.returncode == 0, f"ray start --address {ADDRESS}", done.stderr[-500:])
        raylet2 = raylet_of_second_node(before)
        node2 = {pid for pid in processes() if pid not in before}

        done = run(tatl(str(spec), *common, "--seeds", "2", "--workers", "1", "--out", str(work / "local")), 600)
        check(done.returncode == 0, "the local reference run", done.stderr[-500:])

        done = run(tatl(str(spec), *common, "--seeds", "2", "--executor", "ray", "--address", ADDRESS,
                        "--out", str(work / "ray")), 600)  # fmt: skip
        check(done.returncode == 0, "the run on the cluster", done.stderr[-1500:])
        check(same_records(work / "ray", work / "local"), "the cluster's records equal the local ones")

        # The kill needs a unit running on the second node after a record is written; on a fast
        # machine the tiny run can end before that moment comes, so it is tried again afresh.
        for attempt in range(1, KILL_ATTEMPTS + 1):
            out = work / f"ray-kill-{attempt}"
            proc, output, at_kill, rewritten = run_and_kill(str(spec), common, out, raylet2)
            if at_kill is not None or proc.returncode != 0:
                break
            say(f"attempt {attempt}: the run ended before a unit ran on the second node after a record")
        check(at_kill is not None, "the second node's raylet was killed while it ran a unit, after the first record")
        check(proc.returncode == 0, "the run finished despite the lost node", output[-1500:])
        check(not rewritten, f"no record was written twice ({sorted(map(str, rewritten))})")
        assert at_kill is not None
        check(
            all(path.stat().st_mtime_ns == stamp for path, stamp in at_kill.items()),
            "the records written before the kill are untouched",
        )
        check(same_records(out, work / "local"), "its records equal the local ones")
        now = processes()
        survivors = [f"{pid} {now[pid][2][:60]}" for pid in sorted(node2 & set(now)) if now[pid][1] != "Z"]
        say(f"processes of the dead node still running (stopped below): {survivors}")

        done = run(tatl(str(point_mass), "--preset", "tiny", "--seeds", "1", "--out", str(work / "pm-local")), 600)
        check(done.returncode == 0, "a user's domain by import path, locally", done.stderr[-500:])
        done = run(tatl(str(point_mass), "--preset", "tiny", "--seeds", "1", "--executor", "ray",
                        "--address", ADDRESS, "--out", str(work / "pm-ray")), 600)  # fmt: skip
        check(done.returncode == 0, "a user's domain by import path, on the cluster", done.stderr[-500:])
        check(same_records(work / "pm-ray", work / "pm-local"), "its records equal the local ones")

        began = time.monotonic()
        done = run(tatl(str(spec), *common, "--executor", "ray", "--address", WRONG_ADDRESS,
                        "--out", str(work / "wrong")), 120)  # fmt: skip
        took = time.monotonic() - began
        check(
            done.returncode == 2 and done.stderr.count("\n") == 1 and "Traceback" not in done.stderr and took < 30,
            f"a wrong address is one line and exit 2 in {took:.1f} s: {done.stderr.strip()!r}",
        )
        check(not (work / "wrong").exists(), "a wrong address touches no output folder")
    except (CheckFailed, subprocess.TimeoutExpired) as error:
        failed = error
        say(f"FAILED: {error}")
    finally:
        stopped = stop_everything()
        say(f"stopped by pid: {len(stopped)} processes")
        for line in stopped:
            print("   ", line, flush=True)
        shutil.rmtree(temp, ignore_errors=True)
    left = processes()
    if left:
        say(f"FAILED: processes left: {left}")
        return 1
    say("ok: no process of the namespace is left")
    return 1 if failed else 0


def outside(work: Path, timeout: float) -> int:
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        print("ray_cluster_check: needs unshare (util-linux) and ip (iproute2)", file=sys.stderr)
        return 1
    command = ["unshare", "--net", "--pid", "--mount-proc", "--fork", "--kill-child"]
    proc = subprocess.Popen([*command, sys.executable, __file__, INSIDE, "--work", str(work)])
    namespace = None
    deadline = time.monotonic() + 30
    while namespace is None and proc.poll() is None and time.monotonic() < deadline:
        for entry in Path("/proc").iterdir():  # unshare's child is the namespace's PID 1
            try:
                if entry.name.isdigit() and int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == proc.pid:
                    namespace = os.readlink(entry / "ns" / "pid")
            except (OSError, ValueError):
                continue
        time.sleep(0.05)
    try:
        code = proc.wait(timeout)
    except subprocess.TimeoutExpired:
        print(f"ray_cluster_check: over {timeout:.0f} s; stopping it", file=sys.stderr, flush=True)
        proc.kill()  # --kill-child: its PID 1 goes, and the kernel ends the namespace
        proc.wait()
        code = 1
    if namespace is None:
        print("ray_cluster_check: could not find the namespace's first process", file=sys.stderr)
        return 1
    time.sleep(0.5)
    left = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and os.readlink(entry / "ns" / "pid") == namespace:
                left.append(int(entry.name))
        except OSError:
            continue
    if left:
        print(f"ray_cluster_check: processes of the namespace outlived it: {left}", file=sys.stderr)
        return 1
    print(f"ray_cluster_check: no process of {namespace} is left outside", flush=True)
    return code


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=None, help="folder for the runs (default: a temporary one)")
    parser.add_argument("--timeout", type=float, default=1500, help="seconds for everything (default: 1500)")
    parser.add_argument(INSIDE, action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.inside:
        return inside(args.work)
    work = args.work or Path(tempfile.mkdtemp(prefix="tatl-ray-check-"))
    work.mkdir(parents=True, exist_ok=True)
    return outside(work.resolve(), args.timeout)


if __name__ == "__main__":
    sys.exit(main())
