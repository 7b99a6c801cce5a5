#!/usr/bin/env bash
# Render a refinement job's extra samples on a lent CUDA machine (tools/device_refine.py, diviewer.data.refine_extras)
# and bring them back in packs that fit the device tool's files: tars of whole frames, <= 15 MB each (~75 Sponza
# frames at 128x128), 7 a call (the 8th file is the logs).
#
#   bash tools/device_refine.sh JOB SHARDS SECONDS   set up (tools/device_setup.sh), render the job's frames in SHARDS
#                                                    processes side by side, none begun SECONDS after the start;
#                                                    pack them all in /tmp/packs, and return the first 7
#   SETUP=0 bash tools/device_refine.sh --more       the next 7 packs (the machine still warm: a call within 30 s)
# carry: .gl .whl .carry and the job's folder (runs/ is ignored). Here: cat nothing; `tar xf` each pack into one
# folder, then `diviewer data refine SRC --spp N --out OUT --extras FOLDER`.
set -uo pipefail
if [ "${SETUP:-1}" = 1 ]; then . tools/device_setup.sh; fi  # SETUP=0: a machine set up already (or a local dry run)
set +e
mkdir -p /tmp/packs /tmp/refine_log
send() {  # the next 7 packs not yet sent, and the logs
  local n=0
  for p in /tmp/packs/extras_*.tar; do
    [ -e "$p" ] || continue
    [ -e "$p.sent" ] && continue
    [ $n -lt 7 ] || break
    cp "$p" "$OUT/" && touch "$p.sent" && n=$((n + 1))
  done
  left=$(for p in /tmp/packs/extras_*.tar; do [ -e "$p" ] && [ ! -e "$p.sent" ] && echo "$p"; done | wc -l)
  echo "sent $n packs; $left left on this machine (SETUP=0 bash tools/device_refine.sh --more)" \
    | tee -a /tmp/refine_log/packs.log
  tar czf "$OUT/refine_logs.tar.gz" -C /tmp refine_log
}
if [ "${1:-}" = "--more" ]; then send; exit 0; fi
job=$1; shards=$2; seconds=$3
t0=$(date +%s)
deadline=$((t0 + seconds))
pids=()
for k in $(seq "$shards"); do
  python3 tools/device_refine.py render "$job" --out /tmp/extras --shard "$k/$shards" --deadline "$deadline" \
    > "/tmp/refine_log/shard_$k.log" 2>&1 &
  pids+=("$!")
done
( sleep 60; nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv > /tmp/refine_log/nvidia_smi.csv ) \
  > /dev/null 2>&1 &
for p in "${pids[@]}"; do wait "$p"; done
echo "shards ended at +$(( $(date +%s) - t0 )) s: $(ls /tmp/extras/*.json 2>/dev/null | wc -l) frames" \
  | tee /tmp/refine_log/render.log
for k in $(seq "$shards"); do tail -n 1 "/tmp/refine_log/shard_$k.log"; done >> /tmp/refine_log/render.log
# Packs of whole frames (array and sidecar together), in index order, each under 15 MB.
(cd /tmp/extras && ls *.json 2>/dev/null | sort) > /tmp/refine_log/frames.txt
python3 - <<'PY'
import os, tarfile
names = open("/tmp/refine_log/frames.txt").read().split()
pack, size, n = [], 0, 0
def flush():
    global pack, size, n
    if pack:
        with tarfile.open(f"/tmp/packs/extras_{n:03d}.tar", "w") as t:
            for s in pack:
                for f in (s[:-5] + ".npy", s):
                    t.add(os.path.join("/tmp/extras", f), arcname=f"extras/{f}")
        n += 1
    pack, size = [], 0
for s in names:
    b = os.path.getsize(os.path.join("/tmp/extras", s[:-5] + ".npy")) + os.path.getsize(os.path.join("/tmp/extras", s)) + 2048
    if size + b > 15_000_000:
        flush()
    pack.append(s); size += b
flush()
print(f"{len(names)} frames in {n} packs")
PY
send
ls -la "$OUT"
