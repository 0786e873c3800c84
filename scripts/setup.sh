#!/usr/bin/env bash
# Sets up everything tatl-mj needs on a fresh Debian machine: the OSMesa GL
# library (for headless rendering without EGL), a virtual environment in .venv
# and the package with its test and Ray extras. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! ldconfig -p 2>/dev/null | grep -q libOSMesa; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing libosmesa6 (software OpenGL for headless rendering)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libosmesa6 >/dev/null
  else
    echo "setup: libOSMesa not found; MUJOCO_GL=osmesa will not work (apt-get install libosmesa6)" >&2
  fi
fi

PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e ".[test,ray]"
