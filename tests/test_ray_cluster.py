"""A real two-node Ray cluster on loopback: scripts/ray_cluster_check.py, run as a test.

The script makes a network, PID and mount namespace of its own (``unshare``, as
root), where loopback is the only interface, starts a head and a second node
there and checks, on the tiny flipped-pendulum spec (methods ta-tl and rl, two
seeds): the cluster's records equal the local executor's, field by field,
timings aside; killing the second node's raylet while it runs a unit loses
nothing and writes no record twice; a user's domain and method by import path
run there; a wrong address is one line and exit 2; every process it started,
Ray's agents included, is stopped by pid and none is left. About two minutes
on two busy cores.
"""

import os
import shutil
import subprocess
import sys
import time

import pytest
from conftest import ROOT


def _why_not() -> str | None:
    if not sys.platform.startswith("linux"):
        return "Linux namespaces only"
    if os.geteuid() != 0:
        return "needs root, to make a network and PID namespace of its own (unshare)"
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "needs unshare (util-linux) and ip (iproute2)"
    if shutil.which("ray", path=os.path.dirname(sys.executable)) is None:
        return "needs Ray (pip install 'tatl-mj[ray]'), its ray command next to this Python"
    probe = subprocess.run(
        ["unshare", "--net", "--pid", "--mount-proc", "--fork", "--kill-child", "ip", "link", "set", "lo", "up"],
        capture_output=True,
        text=True,
    )
    if probe.returncode != 0:
        return f"cannot make namespaces here: {probe.stderr.strip()}"
    return None


WHY_NOT = _why_not()


@pytest.mark.slow
@pytest.mark.skipif(WHY_NOT is not None, reason=WHY_NOT or "")
def test_a_two_node_ray_cluster_on_loopback(tmp_path):
    start = time.monotonic()
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "ray_cluster_check.py"), "--work", str(tmp_path), "--timeout", "1200"],
        capture_output=True,
        text=True,
        timeout=1500,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    print(done.stdout)
    assert done.returncode == 0, f"{done.stdout[-4000:]}\n{done.stderr[-4000:]}"
    assert "ok: the cluster's records equal the local ones" in done.stdout
    assert "ok: no process of the namespace is left" in done.stdout
    print(f"{time.monotonic() - start:.0f} s")
