#!/usr/bin/env bash
# Set up (tools/setup.sh) and run the main job: the viewer on the shipped default scene (cornell)
# with its shipped model. Extra arguments go to `diviewer view` (e.g. --frames 60 --screenshot s.png).
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$ROOT"
if [ -z "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ]; then
  echo "[run] no display: the viewer needs one (e.g. run under 'xvfb-run -a bash tools/run.sh --frames 60 --screenshot view.png')" >&2
fi
exec diviewer view --scene cornell --model auto "$@"
