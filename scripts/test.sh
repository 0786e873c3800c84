#!/usr/bin/env bash
# Sets up (scripts/setup.sh, with the sb3 extra: the deep-RL adapter and example
# are tested too), then lint (ruff), format check, types (mypy) and the whole
# test suite; any finding fails the run.
set -euo pipefail
cd "$(dirname "$0")/.."
TATL_EXTRAS=test,ray,sb3 bash scripts/setup.sh
.venv/bin/ruff check tatl_mj tests
.venv/bin/ruff format --check tatl_mj tests
.venv/bin/mypy
exec .venv/bin/python -m pytest "$@"
