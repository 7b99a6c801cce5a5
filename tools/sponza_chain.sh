#!/usr/bin/env bash
# Sponza's model built on a CPU machine, over as many sessions as it takes (docs/sponza.md): set up
# (tools/setup.sh), then
#   1. `diviewer build` with K = 8 alone, then with K = 8 and 16 (the capture, its check, the trainings, the
#      exports, their scores on the shipped compact evaluation set, the pick and the ship to runs/sponza/ship). K = 8
#      ships first because runs/ does not outlive its machine: a model shipped ~1.6 h after the capture can be
#      committed by the session that sees it, instead of ~4.3 h after;
#   2. the full evaluation set (`diviewer evalset --scene sponza`, 24 frames a split at 1024 spp) and the interim
#      model's scores on it;
#   3. the same build with the whole ladder (K = 32 added: trained, scored and recorded; the recipe's
#      `[ladder] max_mb` keeps it from shipping), and the shipped model's scores on the full set.
# Every stage resumes where it stopped and skips what is done, so after a session ends the same command goes on:
#   nohup setsid bash tools/sponza_chain.sh > runs/sponza_chain.log 2>&1 &
# The build reads the recipe as runs/sponza/sponza.toml, a copy of assets/recipes/sponza_walk.toml under the name
# its model ships with (the card records the recipe's name and file). Stop it with `kill -- -PGID`; pause it with
# `kill -STOP -- -PGID` (and `-CONT`) while timing anything else.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$ROOT"
WORK="${SPONZA_WORK:-runs/sponza}"
mkdir -p "$WORK"
cp assets/recipes/sponza_walk.toml "$WORK/sponza.toml.part" && mv "$WORK/sponza.toml.part" "$WORK/sponza.toml"
BUILD=(diviewer build --scene sponza --recipe "$WORK/sponza.toml" --evalset assets/evalsets/sponza --work "$WORK"
       --ship "$WORK/ship")

stage() { echo "[sponza_chain] $(date -u '+%F %T') $*"; }

stage "build, K = 8"
"${BUILD[@]}" --ks 8
stage "build, K = 8 and 16"
"${BUILD[@]}" --ks 8 16
stage "full evaluation set"
diviewer evalset --scene sponza --out "$WORK/evalset"
if [ ! -f "$WORK/eval_full_k8_16.json" ]; then
  stage "the interim model on the full evaluation set"
  diviewer eval --evalset "$WORK/evalset" --model "$WORK/ship/sponza.onnx" --out "$WORK/eval_full_k8_16.json"
fi
stage "build, the whole ladder"
"${BUILD[@]}"
stage "the shipped model on the full evaluation set"
diviewer eval --evalset "$WORK/evalset" --model "$WORK/ship/sponza.onnx" --out "$WORK/eval_full.json"
stage "done"
