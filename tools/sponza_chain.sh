#!/usr/bin/env bash
# Sponza's model built on a CPU machine, over as many sessions as it takes (docs/sponza.md): set up
# (tools/setup.sh), then
#   1. the 64-spp capture (assets/recipes/sponza_walk64.toml) and its check: `diviewer build ... --ks 8
#      --stop-after check` (~3.5-4.2 h here; a machine that lost `runs/` starts here, as on 2026-11-29, 2026-11-30 and
#      2026-12-01). Its K = 8 shipped from 2026-11-29 to 2026-11-30 and is not trained again;
#   2. the full evaluation set (`diviewer evalset --scene sponza`, 24 frames a split at 1024 spp, ~3 h here; or
#      the same set rendered on a lent device, runs/evalsets/sponza: tools/device_evalsets.sh, compact with every
#      frame, taken where present, as SPONZA_EVALSET names another) and
#      the shipped model's scores on it, with its margin over the 64-spp truth;
#   3. the ladder on the 256-spp truth, the first stop of the refinement (since 2026-12-01: docs/sponza.md, "`runs/`
#      lost a fourth time"): the shipped recipe (assets/recipes/sponza.toml, `refine_from = 64`) in runs/sponza256,
#      whose data/ links to the 64-spp capture: the refinement (`diviewer data refine`, 192 samples a frame, ~8-9 h),
#      then K = 8 and 16 (~4.3 h), scored on the full set, picked and shipped to runs/sponza256/ship, then K = 32
#      (~3-6 h). Each K's margin over the truth it trained on, frame by frame: WORK/truth_margin_kK.json (as after each
#      build below). It lands the ladder 8/16/32 in about a day of this machine, where the 768-spp one needs two: `runs/`
#      did not outlive 26 h of it on 2026-11-30/12-01. With SPONZA_CONTROLS_256=1 the shipped model's controls follow
#      (as they ran on 2026-11-30; their figures are in docs/data/sponza256 and docs/accuracy.md): its figure at the
#      viewer's exposure, 3a, the stride-pattern lever, and 3b, K = 8 without the recipe's structure term
#      (`--ssim-weight 0`, ~1 h);
#   4. the 256-spp set refined again to 512 (assets/recipes/sponza_walk512.toml, `refine_from = 256`, in runs/sponza512
#      whose data/ links to runs/sponza256/data_256spp; 256 samples a frame, ~14 h here; the build stops after the
#      refinement's check), then to 768 (assets/recipes/sponza_walk768.toml, `refine_from = 512`, in runs/sponza768
#      whose data/ links to runs/sponza512/data_512spp; 256 samples a frame, ~14 h here);
#   5. the ladder on it, in runs/sponza768: K = 8 and 16, picked and shipped to runs/sponza768/ship, then K = 32
#      (trained, scored and recorded; the recipe's `[ladder] max_mb` keeps it from shipping). The issue asks for a
#      training truth 6 dB above the model's error: the 256-spp K = 8 is 3.0-4.8 dB under its truth (median per split),
#      512 spp would leave the unseen stretches ~6 dB with that model and less with a better one, 768 ~7.8
#      (sponza_walk768.toml). Stage 3's margins say what the wider K need.
# Every stage resumes where it stopped and skips what is done, so after a session ends the same command goes on:
#   nohup setsid bash tools/sponza_chain.sh > runs/sponza_chain.log 2>&1 &
# Each build reads its recipe as WORK/sponza.toml, a copy under the name its model ships with (the card records the
# recipe's name and file). Stop it with `kill -- -PGID`; pause it with `kill -STOP -- -PGID` (and `-CONT`) while
# timing anything else.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$ROOT"
WORK="${SPONZA_WORK:-runs/sponza}"
REFINED="${SPONZA_REFINED_WORK:-runs/sponza256}"
TWICE="${SPONZA_TWICE_WORK:-runs/sponza512}"
LADDER="${SPONZA_LADDER_WORK:-runs/sponza768}"
mkdir -p "$WORK" "$REFINED" "$TWICE" "$LADDER"
cp assets/recipes/sponza_walk64.toml "$WORK/sponza.toml.part" && mv "$WORK/sponza.toml.part" "$WORK/sponza.toml"
cp assets/recipes/sponza.toml "$REFINED/sponza.toml.part" && mv "$REFINED/sponza.toml.part" "$REFINED/sponza.toml"
cp assets/recipes/sponza_walk512.toml "$TWICE/sponza.toml.part" && mv "$TWICE/sponza.toml.part" "$TWICE/sponza.toml"
cp assets/recipes/sponza_walk768.toml "$LADDER/sponza.toml.part" && mv "$LADDER/sponza.toml.part" "$LADDER/sponza.toml"
[ -e "$REFINED/data" ] || [ -L "$REFINED/data" ] || ln -s "$(realpath -m "$WORK/data")" "$REFINED/data"
[ -e "$TWICE/data" ] || [ -L "$TWICE/data" ] || ln -s "$(realpath -m "$REFINED/data_256spp")" "$TWICE/data"
[ -e "$LADDER/data" ] || [ -L "$LADDER/data" ] || ln -s "$(realpath -m "$TWICE/data_512spp")" "$LADDER/data"
links_to() {  # links_to LINK TARGET WHY: refused, naming the link, if it leads elsewhere (a runs/ of another plan)
  [ "$(realpath -m "$1")" = "$(realpath -m "$2")" ] && return 0
  echo "[sponza_chain] $1: links to $(realpath -m "$1"), not $2 that $3; move that folder aside" >&2
  exit 1
}
links_to "$REFINED/data" "$WORK/data" "sponza.toml refines (refine_from = 64)"
links_to "$TWICE/data" "$REFINED/data_256spp" "sponza_walk512.toml refines (refine_from = 256; until 2026-12-01 64)"
links_to "$LADDER/data" "$TWICE/data_512spp" "sponza_walk768.toml refines (refine_from = 512)"

stage() { echo "[sponza_chain] $(date -u '+%F %T') $*"; }
# A stage that fails is run once more after a minute (it resumes where it stopped): an unattended chain should not
# wait for the next session over a passing fault (on 2026-11-28 a build crashed when the code was edited under it,
# its process holding one module of the old code and one of the new). A second failure stops the chain.
again() { "$@" || { stage "failed (exit $?), once more in 60 s: $*"; sleep 60; "$@"; }; }

# Each model's margin over its training truth, frame by frame (tools/experiments/truth_margin.py, seconds), from a
# `diviewer eval` JSON on the full set: margin EVAL KEY OUT, again whenever the scores are newer.
margin() {
  [ -f "$1" ] && ! [ "$3" -nt "$1" ] || return 0
  stage "truth margin of $2 ($1)"
  python tools/experiments/truth_margin.py --eval "$1" --model-key "$2" --project 512 --project 768 --project 1024 \
    --out "$3" \
    || stage "no truth margin for $2 (above)"
}
stage "the 64-spp capture and its check"
again diviewer build --scene sponza --recipe "$WORK/sponza.toml" --evalset assets/evalsets/sponza --work "$WORK" \
  --ship "$WORK/ship" --ks 8 --stop-after check
# The full set: a device's render of it where there is one (it holds every frame, float16), else rendered here.
EVALSET="${SPONZA_EVALSET:-}"
if [ -z "$EVALSET" ]; then
  if [ -f runs/evalsets/sponza/manifest.json ]; then EVALSET=runs/evalsets/sponza; else EVALSET="$WORK/evalset"; fi
fi
stage "full evaluation set: $EVALSET"
if [ "$EVALSET" = "$WORK/evalset" ]; then again diviewer evalset --scene sponza --out "$EVALSET"; fi
if [ ! -f "$WORK/eval_full_shipped.json" ]; then
  stage "the shipped model on the full evaluation set"
  again diviewer eval --evalset "$EVALSET" --model assets/models/sponza.onnx --out "$WORK/eval_full_shipped.json"
fi
margin "$WORK/eval_full_shipped.json" sponza "$WORK/truth_margin_k8.json"
margins() {  # each K of a build, from the build's own scores on the full set
  local work="$1"; shift
  for k in "$@"; do margin "$work/evalset_eval.json" "sponza_k$k" "$work/truth_margin_k$k.json"; done
}
REFINED_BUILD=(diviewer build --scene sponza --recipe "$REFINED/sponza.toml" --evalset "$EVALSET" --work "$REFINED"
               --ship "$REFINED/ship")
stage "build on the 256-spp truth: the refinement, K = 8 and 16"
again "${REFINED_BUILD[@]}" --ks 8 16
margins "$REFINED" 8 16
stage "build on the 256-spp truth: the whole ladder"
again "${REFINED_BUILD[@]}"
margins "$REFINED" 8 16 32
controls_256() {  # SPONZA_CONTROLS_256=1: the shipped model's controls, on the K = 8 the ladder above trained
  # The new K = 8 beside the shipped model as the viewer shows them (each frame at its metered exposure:
  # tools/experiments/metered_scores.py, docs/accuracy.md) and in accuracy.md's figure (tools/make_figures.py, the same
  # two configurations): seconds, and minutes of Mitsuba; a failure is reported and the chain goes on.
  if [ ! -f "$REFINED/metered_k8.json" ] && [ -f "$REFINED/models/sponza_k8.onnx" ]; then
    stage "the 256-spp K = 8 at the viewer's exposure, and its figure"
    python tools/experiments/metered_scores.py --model assets/models/sponza.onnx \
      --model "$REFINED/models/sponza_k8.onnx" --evalset "$EVALSET" --out "$REFINED/metered_k8.json" \
      || stage "no metered scores (above)"
    python tools/make_figures.py --scene sponza --model "$REFINED/models/sponza_k8.onnx" --out-dir "$REFINED/figures" \
      || stage "no figure (above)"
  fi
  # 3a. The stride-pattern lever on it (docs/accuracy.md, "The stride pattern in the shade"): the K = 8 trained on for
  #     3,000 steps at a constant 5e-5, once with the structure term at the scene's exposure (the control) and once at
  #     the mean of the scene's and each frame's metered exposure (`--ssim-exposure both`), scored beside the K = 8 on
  #     the full evaluation set (WORK/eval_full_lever.json) and at the viewer's exposure (WORK/metered_lever.json):
  #     whether the lever holds on a converged model of the cleaner truth, before the 512-spp ladder trains (~25 min
  #     here). A failure is reported and the chain goes on.
  lever_run() {
    local run="$REFINED/lever_$1"
    if [ -f "$run/last.ckpt" ]; then
      diviewer train --out "$run" --data "$REFINED/data_256spp" --resume --max-steps 3000
    else
      diviewer train --data "$REFINED/data_256spp" --out "$run" --recipe "$REFINED/sponza.toml" --k 8 \
        --ssim-exposure "$1" --init-from "$REFINED/train_k8/best.ckpt" --lr 5e-5 --lr-decay none --max-steps 3000 \
        --val-every-steps 3000 --save-every 500
    fi
  }
  lever() {
    local arm models=("$REFINED/models/sponza_k8.onnx")
    for arm in scene both; do
      models+=("$REFINED/models/sponza_lever_$arm.onnx")
      again lever_run "$arm" || return 1
      [ -f "${models[-1]}" ] || diviewer export "$REFINED/lever_$arm/last.ckpt" --out "${models[-1]}" --int8-weights \
        || return 1
    done
    local args=() m
    for m in "${models[@]}"; do args+=(--model "$m"); done
    again diviewer eval --evalset "$EVALSET" "${args[@]}" --out "$REFINED/eval_full_lever.json" \
      && python tools/experiments/metered_scores.py "${args[@]}" --evalset "$EVALSET" \
           --out "$REFINED/metered_lever.json"
  }
  if [ ! -f "$REFINED/metered_lever.json" ] && [ -f "$REFINED/train_k8/best.ckpt" ]; then
    stage "the stride-pattern lever on the 256-spp K = 8 (--ssim-exposure both against its control)"
    lever || stage "the lever test failed (above); on to the control run"
  fi
  # 3b. The recipe against itself without the structure term, on the same 256-spp truth: K = 8 with `--ssim-weight 0`
  #     (the recipe's term since 2026-11-29, when the model trained with it on the 64-spp truth shipped: docs/sponza.md,
  #     "The frame's edge"), the recipe's whole schedule (~1 h here), best.ckpt by the validation split's SSIM as the
  #     build picks, exported as the recipe exports, scored with the recipe's K = 8 on the full evaluation set
  #     (WORK/eval_full_l1.json) and its truth margin: whether the term still pays on a cleaner truth, before the
  #     512-spp ladder trains with it (the 512-spp build takes other [train] settings until its first K trains:
  #     docs/build.md). A failure is reported and the chain goes on to the 512-spp refinement.
  l1_run() {
    local run="$REFINED/l1_k8" resume=()
    [ -f "$run/last.ckpt" ] && resume=(--resume)
    diviewer train --data "$REFINED/data_256spp" --out "$run" --recipe "$REFINED/sponza.toml" --k 8 --ssim-weight 0 \
      "${resume[@]}"
  }
  l1_ablation() {  # each step only after the one before succeeded (errexit does not hold inside `f || ...`)
    local model="$REFINED/models/sponza_l1_k8.onnx"
    again l1_run \
      && { [ -f "$model" ] || diviewer export "$REFINED/l1_k8/best.ckpt" --out "$model" --int8-weights; } \
      && again diviewer eval --evalset "$EVALSET" --model "$REFINED/models/sponza_k8.onnx" --model "$model" \
           --out "$REFINED/eval_full_l1.json" \
      && margin "$REFINED/eval_full_l1.json" sponza_l1_k8 "$REFINED/truth_margin_l1_k8.json"
  }
  if [ ! -f "$REFINED/truth_margin_l1_k8.json" ]; then
    stage "K = 8 without the structure term on the 256-spp truth (the recipe's control)"
    l1_ablation || stage "the control run failed (above); on to the 512-spp truth"
  fi
}
if [ "${SPONZA_CONTROLS_256:-0}" = 1 ]; then
  controls_256
else
  stage "the 256-spp K = 8's controls: skipped (SPONZA_CONTROLS_256=1 runs them; docs/data/sponza256 holds them)"
fi
stage "the 512-spp truth: the 256-spp set refined (256 samples a frame), checked"
again diviewer build --scene sponza --recipe "$TWICE/sponza.toml" --evalset "$EVALSET" --work "$TWICE" \
  --ship "$TWICE/ship" --ks 8 --stop-after check
LADDER_BUILD=(diviewer build --scene sponza --recipe "$LADDER/sponza.toml" --evalset "$EVALSET" --work "$LADDER"
              --ship "$LADDER/ship")
stage "build on the 768-spp truth: the refinement, K = 8 and 16"
again "${LADDER_BUILD[@]}" --ks 8 16
margins "$LADDER" 8 16
stage "build on the 768-spp truth: the whole ladder"
again "${LADDER_BUILD[@]}"
margins "$LADDER" 8 16 32
stage "done"
