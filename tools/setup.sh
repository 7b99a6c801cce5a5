#!/usr/bin/env bash
# Set up diviewer from nothing: system libraries (when run as root with apt-get), a virtual
# environment in .venv with the CPU build of torch, and the project with its extras.
# Sourced by tools/run.sh and tools/test.sh; safe to run again (it only adds what is missing, and skips pip
# when pyproject.toml and the venv are unchanged since the last install).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${DIVIEWER_VENV:-$ROOT/.venv}"
PY="${PYTHON:-python3}"

if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1 && [ -z "${DIVIEWER_SKIP_APT:-}" ]; then
  # EGL + Mesa (headless GL), Xvfb (the viewer's window tests), libLLVM 19 (Mitsuba's fast llvm variant).
  pkgs="libegl1 libegl-mesa0 libgl1-mesa-dri libglx-mesa0 xvfb xauth libllvm19"
  missing=""
  for p in $pkgs; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
  if [ -n "$missing" ]; then
    echo "[setup] apt-get install$missing"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $missing >/dev/null
  fi
elif ! ldconfig -p 2>/dev/null | grep -q libEGL.so; then
  echo "[setup] warning: no libEGL found; install Mesa's EGL (Debian: libegl1 libegl-mesa0 libgl1-mesa-dri)" >&2
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating $VENV"
  "$PY" -m venv "$VENV"
fi
# shellcheck disable=SC1091
. "$VENV/bin/activate"
TORCH_PIN="torch==2.13.0"
# pip runs only when what it would install changed: the stamp holds a hash of pyproject.toml, the pin, this
# checkout's path and the venv's python; a fresh clone (no .venv) has none, so it installs everything.
# DIVIEWER_REINSTALL=1 forces the install.
STAMP="$VENV/.diviewer-setup-stamp"
KEY="$( { cat "$ROOT/pyproject.toml"; echo "$TORCH_PIN $ROOT"; python -c 'import sys; print(sys.executable, sys.version)'; } \
        | sha256sum | cut -d' ' -f1)"
if [ -n "${DIVIEWER_REINSTALL:-}" ] || [ "$(cat "$STAMP" 2>/dev/null)" != "$KEY" ] \
   || ! (cd / && env -u PYTHONPATH python -c "import diviewer, torch, sys; from pathlib import Path
sys.exit(Path(diviewer.__file__).resolve().parents[1] != Path(sys.argv[1]).resolve())" "$ROOT") >/dev/null 2>&1; then
  python -m pip install -q --upgrade pip
  # The CPU build of torch first: an unpinned torch would pull a multi-GB CUDA build.
  python -c "import torch" >/dev/null 2>&1 || python -m pip install -q "$TORCH_PIN"
  python -m pip install -q -e "$ROOT[train,dev,bench]"
  echo "$KEY" > "$STAMP"
else
  echo "[setup] $VENV is up to date with pyproject.toml (no pip; DIVIEWER_REINSTALL=1 forces it)"
fi
if [ -z "${DRJIT_LIBLLVM_PATH:-}" ]; then
  for f in /usr/lib/x86_64-linux-gnu/libLLVM-19.so /usr/lib/x86_64-linux-gnu/libLLVM-19.so.1 /usr/lib/llvm-19/lib/libLLVM-19.so; do
    if [ -e "$f" ]; then export DRJIT_LIBLLVM_PATH="$f"; break; fi
  done
fi
echo "[setup] ready: $(diviewer --version)"
