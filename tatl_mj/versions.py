"""The tested pairing of mujoco and dm-control, checked with a readable message.

dm-control 1.0.50 fails at ``suite.load`` on mujoco 4.0.0 (``'MjModel' object has
no attribute 'flex_vertedge'``): dm-control pins the mujoco it was built against.
"""

from __future__ import annotations

# dm-control release -> the mujoco versions it is known to run with, [low, high).
TESTED_PAIRS: dict[str, tuple[tuple[int, ...], tuple[int, ...]]] = {
    "1.0.50": ((3, 17), (4,)),
}


def _version_tuple(text: str) -> tuple[int, ...]:
    parts = []
    for piece in text.split("."):
        digits = "".join(ch for ch in piece if ch.isdigit())
        if not digits:
            break
        parts.append(int(digits))
    return tuple(parts)


def check_pair(mujoco_version: str, dm_control_version: str) -> None:
    """Raises RuntimeError, saying what to install, for an untested pair."""
    if dm_control_version not in TESTED_PAIRS:
        raise RuntimeError(
            f"dm-control {dm_control_version} is not a tested version; tatl-mj is tested with "
            f"dm-control {sorted(TESTED_PAIRS)}. Run: pip install 'dm-control==1.0.50' 'mujoco>=3.17,<4'"
        )
    low, high = TESTED_PAIRS[dm_control_version]
    version = _version_tuple(mujoco_version)
    if not low <= version < high:
        raise RuntimeError(
            f"mujoco {mujoco_version} does not work with dm-control {dm_control_version} "
            f"(needs mujoco >= {'.'.join(map(str, low))}, < {'.'.join(map(str, high))}; "
            "mujoco 4 fails at suite.load with \"'MjModel' object has no attribute "
            "'flex_vertedge'\"). Run: pip install 'mujoco>=3.17,<4' 'dm-control==1.0.50'"
        )
