"""The mujoco / dm-control pairing: a bad pair fails with a readable message."""

from importlib import metadata

import pytest

from tatl_mj import versions


def test_installed_pair_is_tested_and_loads():
    versions.check_pair(metadata.version("mujoco"), metadata.version("dm-control"))
    from dm_control import suite as dm_suite  # the import that breaks on a bad pair

    env = dm_suite.load("cartpole", "balance", task_kwargs={"random": 0})
    assert env.reset().observation["position"].shape == (3,)


@pytest.mark.parametrize(
    "mujoco_version, dm_control_version, needle",
    [
        ("4.0.0", "1.0.50", "flex_vertedge"),
        ("3.2.7", "1.0.50", "mujoco >= 3.17"),
        ("3.17.0", "1.0.49", "not a tested version"),
    ],
)
def test_bad_pair_is_named(mujoco_version, dm_control_version, needle):
    with pytest.raises(RuntimeError, match=needle) as info:
        versions.check_pair(mujoco_version, dm_control_version)
    assert "pip install" in str(info.value)


def test_good_pairs_pass():
    versions.check_pair("3.17.0", "1.0.50")
    versions.check_pair("3.99.1rc1", "1.0.50")
