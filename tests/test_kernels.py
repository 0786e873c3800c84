"""Pinning the arithmetic kernels of worker processes: the settings, and that they take effect."""

import os
import platform

import pytest
from conftest import tiny_spec

from tatl_mj.experiments.results import records
from tatl_mj.experiments.run import kernels, runner

XEON = "openblas 0.3.30 SkylakeX; openblas 0.3.31 SkylakeX; numpy X86_V3+X86_V4+AVX512_ICL"
EPYC = "openblas 0.3.30 Haswell; openblas 0.3.31 Haswell; numpy X86_V3"


def test_the_setting_that_gives_another_machines_kernels():
    assert kernels.pinning(EPYC, XEON) == {
        "OPENBLAS_CORETYPE": "Haswell",
        "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL",
    }
    assert kernels.pinning(XEON, XEON) == {"OPENBLAS_CORETYPE": "SkylakeX"}
    with pytest.raises(ValueError) as caught:
        kernels.pinning(XEON, EPYC)
    assert str(caught.value) == f"numpy SIMD targets ['X86_V4', 'AVX512_ICL'] that this processor lacks ({EPYC!r})"
    with pytest.raises(ValueError, match="^other BLAS libraries or versions"):
        kernels.pinning("openblas 0.3.29 Haswell; numpy X86_V3", EPYC)
    with pytest.raises(ValueError, match="^not a kernels label"):
        kernels.Kernels.parse("mkl")
    assert kernels.Kernels.parse("openblas 0.3.30 Haswell; numpy baseline").simd == ()


@pytest.mark.skipif(platform.machine() != "x86_64", reason="OpenBLAS kernel names are x86-64's")
def test_pinned_kernels_reach_spawned_workers_and_not_a_process_that_loaded_them(tmp_path):
    own = kernels.probe()
    here = kernels.kernels.__wrapped__()  # this process's, uncached: OPENBLAS_CORETYPE may be set for it
    lower = kernels.probe({"OPENBLAS_CORETYPE": "Sandybridge"})
    if lower == own:
        pytest.skip("this machine's own OpenBLAS kernel is Sandybridge already")
    pin = kernels.pin_to(lower)
    assert pin.pinned and pin.env["OPENBLAS_CORETYPE"] == "Sandybridge" and pin.kernels == lower
    before = {k: os.environ.get(k) for k in kernels.PIN_VARIABLES}
    with kernels.workers_under(pin):
        runner.run([tiny_spec()], "tiny", [0], tmp_path, workers=2, methods=["rl"], progress=False)
        assert kernels.kernels.__wrapped__() == here  # this process chose its kernels when it loaded numpy
    assert {k: os.environ.get(k) for k in kernels.PIN_VARIABLES} == before
    folder = records.RunDirectory(tmp_path)
    for unit in ("source", "rl"):
        assert records.read_json(folder.record_path("ip_to_flipped_ip", 0, unit))["kernels"] == lower


def test_a_machine_that_cannot_pin_says_why():
    pin = kernels.pin_to("openblas 0.0.1 Haswell; numpy X86_V3")
    assert not pin.pinned and pin.env == {} and pin.why_not.startswith("other BLAS libraries or versions")
