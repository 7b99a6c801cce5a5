#!/usr/bin/env bash
# Set up (tools/setup.sh) and run the main job on the shipped default scene (cornell).
# Extra arguments go to `diviewer render`.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$ROOT"
diviewer render --scene cornell --res 256 --out out/cornell "$@"
echo "images in $ROOT/out/cornell"
