#!/usr/bin/env bash
# Render scenes' full evaluation sets on a lent CUDA machine, in shards side by side, and bring each back as a
# compact set that keeps every frame (diviewer evalset --compact --frames-per-split N: float16, LZMA zip, the
# ladder's scores without its images), which is what fits the device tool's 64 MiB of files back.
#
# Usage on the device (one call; tools/device_setup.sh is sourced here):
#   bash tools/device_evalsets.sh [--bench] SCENE:SHARDS ...      e.g.  sponza:10 cornell:6
# SCENE is a shipped scene's name or a scene file's path (carry its folder where it is ignored, as runs/ is); its
# files are named after it, slashes and dots as underscores (runs/cornell/v3/cornell.toml: runs_cornell_v3_cornell).
# Each scene renders `diviewer evalset --scene SCENE --out /tmp/ev/SCENE` (the defaults: 24 frames a split,
# 1024 spp twice, ladder 1..256) with --shard k/SHARDS; shard 1 starts first and writes the manifest (and its
# fitted exposure) before the others start; shards still running DEADLINE seconds (420) after the start are
# stopped, and the scene is not packed. The shard that finds every frame present scores the set (summary.json; a
# plain run of the command does it where none did), over every core (--jobs: one process a core, which matters:
# scoring in one process took over 5 minutes a set on the H100 machine of 2026-11-27, its rendering 1-3),
# and the compact copy goes into $OUT as SCENE_evalset.tar (in 15 MB parts SCENE_evalset.tar.partNN where
# larger: cat them together), with logs.tar.gz (logs, summaries, nvidia-smi). --bench adds `diviewer bench` of
# each scene at 768x768 (30 frames, one eval frame a split) on the device's GL and onnxruntime (bench_SCENE.json
# in logs.tar.gz).
# Here, afterwards: cat the parts, tar xf into runs/evalsets/, and `diviewer eval --evalset runs/evalsets/SCENE`.
set -uo pipefail
bench=0
if [ "${1:-}" = "--bench" ]; then bench=1; shift; fi
if [ "${SETUP:-1}" = 1 ]; then . tools/device_setup.sh; fi  # SETUP=0: a machine set up already (a local dry run)
set +e
tag() { local t=${1%.toml}; echo "${t//[\/.]/_}"; }  # a scene name, or a scene file's path as a file name
read -r -a extra <<< "${EVALSET_ARGS:-}"  # e.g. "--res 16 --frames-per-split 1 --spp 4 --ladder 1" for a dry run
mkdir -p /tmp/ev /tmp/evc /tmp/evlog
t0=$(date +%s)
deadline=${DEADLINE:-420}  # seconds after the start when shards still running are stopped (the logs come back)
declare -A pids
for spec in "$@"; do
  scene=${spec%%:*}; n=${spec##*:}; name=$(tag "$scene")
  python3 -m diviewer evalset --scene "$scene" --out "/tmp/ev/$name" "${extra[@]}" --shard "1/$n" > "/tmp/evlog/${name}_1.log" 2>&1 &
  pids[$name]="$!"
  for _ in $(seq 240); do [ -f "/tmp/ev/$name/manifest.json" ] && break; sleep 0.5; done
  for k in $(seq 2 "$n"); do
    python3 -m diviewer evalset --scene "$scene" --out "/tmp/ev/$name" "${extra[@]}" --shard "$k/$n" > "/tmp/evlog/${name}_$k.log" 2>&1 &
    pids[$name]="${pids[$name]} $!"
  done
  echo "$scene: $n shards started at +$(( $(date +%s) - t0 )) s"
done
# The watchers write nowhere the call reads (a sleeping child holding stdout kept the call open to the deadline
# after the work had ended: 7 min for a 30 s dry run) and are stopped when the work ends.
( sleep 60; nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv > /tmp/evlog/nvidia_smi.csv ) \
  > /dev/null 2>&1 &
smi=$!
( sleep "$deadline"; for p in ${pids[@]}; do kill "$p" 2>/dev/null; done ) > /dev/null 2>&1 &
watch=$!
for spec in "$@"; do  # each scene is packed as soon as its own shards end
  scene=${spec%%:*}; name=$(tag "$scene")
  for p in ${pids[$name]}; do wait "$p"; done
  echo "$scene: shards ended at +$(( $(date +%s) - t0 )) s"
  if [ $(( $(date +%s) - t0 )) -ge "$deadline" ]; then echo "$scene: cut by the deadline, not packed"; continue; fi
  if [ ! -f "/tmp/ev/$name/summary.json" ]; then  # the shard that found every frame present scored the set
    python3 -m diviewer evalset --scene "$scene" --out "/tmp/ev/$name" "${extra[@]}" \
      > "/tmp/evlog/${name}_summary.log" 2>&1
    tail -2 "/tmp/evlog/${name}_summary.log"
  fi
  frames=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['settings']['frames_per_split'])" \
           "/tmp/ev/$name/manifest.json")
  python3 -m diviewer evalset --compact "/tmp/ev/$name" --out "/tmp/evc/$name" --frames-per-split "$frames" \
    > "/tmp/evlog/${name}_compact.log" 2>&1 || { tail -5 "/tmp/evlog/${name}_compact.log"; continue; }
  cp "/tmp/ev/$name/summary.json" "/tmp/evlog/${name}_summary.json"
  tar cf "/tmp/${name}_evalset.tar" -C /tmp/evc "$name"
  if [ "$(stat -c %s "/tmp/${name}_evalset.tar")" -le 15000000 ]; then cp "/tmp/${name}_evalset.tar" "$OUT/"
  else split -b 15000000 -d "/tmp/${name}_evalset.tar" "$OUT/${name}_evalset.tar.part"; fi
  echo "$scene packed at +$(( $(date +%s) - t0 )) s"
done
tar czf "$OUT/logs.tar.gz" -C /tmp evlog  # again below with the bench: what a timeout cuts still comes back
if [ $bench = 1 ] && [ $(( $(date +%s) - t0 )) -lt "$deadline" ]; then
  for spec in "$@"; do
    scene=${spec%%:*}; name=$(tag "$scene")
    timeout 150 python3 -m diviewer bench --scene "$scene" --res 768 --frames 30 --untrained-k 16 --vxgi-grids 64 \
      --pt-frames 1 --eval-frames 1 --json "/tmp/evlog/bench_$name.json" > "/tmp/evlog/bench_$name.log" 2>&1
    echo "bench $scene: rc $? at +$(( $(date +%s) - t0 )) s"
  done
fi
for w in $smi $watch; do pkill -P "$w" 2>/dev/null; kill "$w" 2>/dev/null; done
tar czf "$OUT/logs.tar.gz" -C /tmp evlog
ls -la "$OUT"
