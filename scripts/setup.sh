#!/usr/bin/env bash
# Sets up everything tatl-mj needs on a fresh Debian machine: the OSMesa GL
# library (for headless rendering without EGL), a virtual environment in .venv
# and the package with the extras in TATL_EXTRAS (default test,ray; test.sh adds
# sb3). Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."

# Headless GL: Mesa's EGL (software llvmpipe without a GPU) and OSMesa.
missing=()
ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' || missing+=(libegl1 libgl1-mesa-dri)
ldconfig -p 2>/dev/null | grep -q libOSMesa || missing+=(libosmesa6)
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing ${missing[*]} (OpenGL for headless rendering)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "setup: missing ${missing[*]}; headless rendering needs them (apt-get install ${missing[*]})" >&2
  fi
fi

PY=${PYTHON:-python3}
[ -x .venv/bin/python ] || "$PY" -m venv .venv
EXTRAS=${TATL_EXTRAS:-test,ray}
# Install only when pyproject.toml or the extras changed since the last install
# (a stamp in .venv), so reruns are quiet and fast.
stamp=.venv/.tatl-installed
want="$(sha256sum pyproject.toml | cut -d' ' -f1) $EXTRAS"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  .venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip
  if [[ ",$EXTRAS," == *",sb3,"* ]]; then
    # torch first, pinned: the CPU build the tests ran on (on this project's machines a
    # wheel on disk); the newest torch on PyPI brings gigabytes of CUDA libraries.
    .venv/bin/python -m pip install -q --disable-pip-version-check "torch==2.13.0"
  fi
  .venv/bin/python -m pip install -q --disable-pip-version-check -e ".[$EXTRAS]"
  echo "$want" > "$stamp"
fi
