#!/usr/bin/env bash
# Pack what `diviewer build` (tools/device_lease.sh) made in /tmp/dv into $OUT (the device tool brings back 8
# files of <= 16 MiB): results.tar.gz (state, log, ladder, curves, metrics, cards, evaluations, manifests,
# thumbnails, the shipped folder's card and ladder) and the exported models that fit, the shipped one first,
# then the ladder's smallest first (or the models named after the work folder); a model over 16 MB comes back
# in parts (MODEL.onnx.part00, part01, ...: cat them together).
# Usage: bash tools/device_pack.sh [WORK [MODEL.onnx ...]]
set -uo pipefail
W=${1:-/tmp/dv}
shift || true
cd "$W" || exit 1
files=()
for p in build.json build.log ladder.json train_k*/metrics.csv train_k*/curves.png models/*.json evalset_eval.json \
         evalset/manifest.json evalset/summary.json data/thumbs/*.png evalset/thumbs/*.png ship/*.json ship/*.png \
         ship/*.csv recipe.toml ladder.log logs/*.log probe_k*/metrics.csv test_split.json \
         eval_compact.json; do
  [ -e "$p" ] && files+=("$p")
done
python3 - "$W" <<'EOF'
import json, sys, pathlib
w = pathlib.Path(sys.argv[1])
for m in w.glob("data/manifest.json"):  # the manifest without its frame list (which the settings rebuild)
    d = json.loads(m.read_text()); d["frame_list"] = f"{len(d.get('frame_list', []))} frames"
    m.with_name("manifest_head.json").write_text(json.dumps(d, indent=1))
EOF
for p in data/manifest_head.json; do [ -e "$p" ] && files+=("$p"); done
tar czf "$OUT/results.tar.gz" "${files[@]}"
n=1
if [ $# -gt 0 ]; then models=("$@"); else models=($(ls ship/*.onnx 2>/dev/null) $(ls -S -r models/*.onnx 2>/dev/null)); fi
for m in "${models[@]}"; do
  [ $n -le 7 ] || break
  if [ "$(stat -c %s "$m")" -le 16000000 ]; then cp "$m" "$OUT/"; n=$((n + 1)); continue; fi
  parts=$(( ($(stat -c %s "$m") + 15999999) / 16000000 ))  # too big for one file back: in parts (cat them)
  [ $((n + parts)) -le 8 ] || continue
  split -b 16000000 -d "$m" "$OUT/$(basename "$m").part"; n=$((n + parts))
done
ls -la "$OUT"
