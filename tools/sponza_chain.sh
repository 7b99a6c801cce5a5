#!/usr/bin/env bash
# Sponza's model built on a CPU machine, over as many sessions as it takes (docs/sponza.md): set up
# (tools/setup.sh), then
#   1. the 64-spp capture (assets/recipes/sponza_walk64.toml) and its check: `diviewer build ... --ks 8
#      --stop-after check` (~3.5-4.2 h here; a machine that lost `runs/` starts here, as on 2026-11-29, 2026-11-30,
#      2026-12-01 and 2026-12-02). Its K = 8 shipped from 2026-11-29 to 2026-11-30 and is not trained again;
#   2. the first stop, a filtered 128-spp truth (since 2026-12-03: docs/sponza.md, "A first stop at 128 spp"):
#      assets/recipes/sponza_filtered128.toml in runs/sponza128f, whose data/ links to the 64-spp capture: the
#      refinement to 128 spp (64 samples a frame, ~3.2 h), the filter (minutes), K = 16 alone (`--ks 16`, ~1.4 h),
#      scored on the compact set, and its margin over the filtered truth it trained on, frame by frame on that set
#      (tools/experiments/filtered_truth_margin.py: the set's frames traced again at 2 x 64 spp, filtered as the
#      recipe filters; ~10 min): runs/sponza128f/filtered_margin_k16.json. ~5 h after the capture: an answer
#      to the issue's 6 dB within a day of this machine, which `runs/` has not always outlived;
#   3. the full evaluation set (`diviewer evalset --scene sponza`, 24 frames a split at 1024 spp, ~3 h here; or
#      the same set rendered on a lent device, runs/evalsets/sponza: tools/device_evalsets.sh, compact with every
#      frame, taken where present, as SPONZA_EVALSET names another) and
#      the shipped model's scores on it, with its margin over the 256-spp truth it trained on;
#   4. the ladder on the filtered 256-spp truth (docs/sponza.md, "A filtered truth"):
#      assets/recipes/sponza_filtered.toml in runs/sponza256f, whose data/ links to the 128-spp set of step 2
#      (runs/sponza128f/data_128spp): the refinement to 256 spp (128 samples a frame, ~6.4 h), the filter, then
#      K = 8 and 16 (~2.5 h), scored on the full set, picked and shipped to runs/sponza256f/ship, then
#      K = 32 (~2.7 h). Each K's margin over the filtered truth it trained on, frame by frame on the full set
#      (the set's frames traced again at 4 x 64 spp; ~30 min for the first K, seconds for the next):
#      WORK/filtered_margin_kK.json. The 256-spp ladder on the unfiltered truth (2026-12-02) is recorded in
#      docs/data/sponza256_ladder and is not trained again;
#   5. only with SPONZA_768=1: the unfiltered 256-spp set refined on to 512 (assets/recipes/sponza_walk512.toml in
#      runs/sponza512, whose data/ links to runs/sponza256f/data_256spp; ~14 h here) and 768 (sponza_walk768.toml in
#      runs/sponza768, data/ linked to runs/sponza512/data_512spp; ~14 h), then the ladder on it: the plan before the
#      filter, ~45 h of this machine that `runs/` never outlived (17, 46, 26 and 24 h).
# Every stage resumes where it stopped and skips what is done, so after a session ends the same command goes on:
#   nohup setsid bash tools/sponza_chain.sh > runs/sponza_chain.log 2>&1 &
# Each build reads its recipe as WORK/sponza.toml, a copy under the name its model ships with (the card records the
# recipe's name and file). Stop it with `kill -- -PGID`; pause it with `kill -STOP -- -PGID` (and `-CONT`) while
# timing anything else.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$ROOT"
WORK="${SPONZA_WORK:-runs/sponza}"
FIRST="${SPONZA_FIRST_WORK:-runs/sponza128f}"
FILTERED="${SPONZA_FILTERED_WORK:-runs/sponza256f}"
TWICE="${SPONZA_TWICE_WORK:-runs/sponza512}"
LADDER="${SPONZA_LADDER_WORK:-runs/sponza768}"
mkdir -p "$WORK" "$FIRST" "$FILTERED" "$TWICE" "$LADDER"
cp assets/recipes/sponza_walk64.toml "$WORK/sponza.toml.part" && mv "$WORK/sponza.toml.part" "$WORK/sponza.toml"
cp assets/recipes/sponza_filtered128.toml "$FIRST/sponza.toml.part" && mv "$FIRST/sponza.toml.part" "$FIRST/sponza.toml"
cp assets/recipes/sponza_filtered.toml "$FILTERED/sponza.toml.part" \
  && mv "$FILTERED/sponza.toml.part" "$FILTERED/sponza.toml"
cp assets/recipes/sponza_walk512.toml "$TWICE/sponza.toml.part" && mv "$TWICE/sponza.toml.part" "$TWICE/sponza.toml"
cp assets/recipes/sponza_walk768.toml "$LADDER/sponza.toml.part" && mv "$LADDER/sponza.toml.part" "$LADDER/sponza.toml"
[ -e "$FIRST/data" ] || [ -L "$FIRST/data" ] || ln -s "$(realpath -m "$WORK/data")" "$FIRST/data"
[ -e "$FILTERED/data" ] || [ -L "$FILTERED/data" ] || ln -s "$(realpath -m "$FIRST/data_128spp")" "$FILTERED/data"
[ -e "$TWICE/data" ] || [ -L "$TWICE/data" ] || ln -s "$(realpath -m "$FILTERED/data_256spp")" "$TWICE/data"
[ -e "$LADDER/data" ] || [ -L "$LADDER/data" ] || ln -s "$(realpath -m "$TWICE/data_512spp")" "$LADDER/data"
links_to() {  # links_to LINK TARGET WHY: refused, naming the link, if it leads elsewhere (a runs/ of another plan)
  [ "$(realpath -m "$1")" = "$(realpath -m "$2")" ] && return 0
  echo "[sponza_chain] $1: links to $(realpath -m "$1"), not $2 that $3; move that folder aside" >&2
  exit 1
}
links_to "$FIRST/data" "$WORK/data" "sponza_filtered128.toml refines (refine_from = 64)"
links_to "$FILTERED/data" "$FIRST/data_128spp" "sponza_filtered.toml refines (refine_from = 128)"
links_to "$TWICE/data" "$FILTERED/data_256spp" "sponza_walk512.toml refines (refine_from = 256)"
links_to "$LADDER/data" "$TWICE/data_512spp" "sponza_walk768.toml refines (refine_from = 512)"

stage() { echo "[sponza_chain] $(date -u '+%F %T') $*"; }
# A stage that fails is run once more after a minute (it resumes where it stopped): an unattended chain should not
# wait for the next session over a passing fault (on 2026-11-28 a build crashed when the code was edited under it,
# its process holding one module of the old code and one of the new). A second failure stops the chain.
again() { "$@" || { stage "failed (exit $?), once more in 60 s: $*"; sleep 60; "$@"; }; }

# A model's margin over an unfiltered training truth, frame by frame (tools/experiments/truth_margin.py, seconds),
# from a `diviewer eval` JSON on the full set: margin EVAL KEY OUT, again whenever the scores are newer.
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
# A model's margin over the filtered truth it trained on, from a build's scores: filtered_margin WORK K PASSES RENDERS.
# The set's frames are traced at PASSES x 64 spp once (RENDERS) and filtered as the build's recipe does (--recipe).
filtered_margin() {
  local scores="$1/evalset_eval.json" out="$1/filtered_margin_k$2.json"
  [ -f "$scores" ] && ! [ "$out" -nt "$scores" ] || return 0
  stage "the filtered truth's margin over K = $2 ($scores)"
  python tools/experiments/filtered_truth_margin.py --eval "$scores" --model-key "sponza_k$2" \
    --recipe "$1/sponza.toml" --pass-spp 64 --passes "$3" --counts "$3" --renders "$4" --out "$out" \
    || stage "no filtered margin for K = $2 (above)"
}
stage "the first stop: K = 16 on the filtered 128-spp truth, scored on the compact set"
again diviewer build --scene sponza --recipe "$FIRST/sponza.toml" --evalset assets/evalsets/sponza --work "$FIRST" \
  --ship "$FIRST/ship" --ks 16
filtered_margin "$FIRST" 16 2 runs/filtered_truth_renders
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
margin "$WORK/eval_full_shipped.json" sponza "$WORK/truth_margin_shipped.json"

FILTERED_BUILD=(diviewer build --scene sponza --recipe "$FILTERED/sponza.toml" --evalset "$EVALSET" --work "$FILTERED"
                --ship "$FILTERED/ship")
stage "build on the filtered 256-spp truth: the refinement, the filter, K = 8 and 16"
again "${FILTERED_BUILD[@]}" --ks 8 16
filtered_margin "$FILTERED" 16 4 runs/filtered_truth_renders_full
filtered_margin "$FILTERED" 8 4 runs/filtered_truth_renders_full
stage "build on the filtered 256-spp truth: the whole ladder"
again "${FILTERED_BUILD[@]}"
for k in 32 16 8; do filtered_margin "$FILTERED" "$k" 4 runs/filtered_truth_renders_full; done
if [ "${SPONZA_768:-0}" != 1 ]; then
  stage "done (SPONZA_768=1 refines the unfiltered set on to 512 and 768 spp and trains the ladder on it)"
  exit 0
fi
margins() {  # each K of a build, from the build's own scores on the full set
  local work="$1"; shift
  for k in "$@"; do margin "$work/evalset_eval.json" "sponza_k$k" "$work/truth_margin_k$k.json"; done
}
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
