"""A dataset's refinement rendered on a lent accelerator, a range of frames at a time (`diviewer.data.refine_extras`).

Here (writes the job the device call carries; the dataset stays here):
    python tools/device_refine.py job --data runs/sponza/data --spp 256 --frames 1800:3400 --out runs/refine_job/job.json.xz
There (tools/device_refine.sh runs it in shards against a deadline and packs what they made):
    python3 tools/device_refine.py render runs/refine_job/job.json.xz --out /tmp/extras --shard 3/12 --deadline 1764370000
Here, after the call, with the packs unpacked into DIR:
    diviewer data refine runs/sponza256/data --spp 256 --out runs/sponza256/data_256spp --extras DIR
(SRC as the build names it: `diviewer build` refines WORK/data into WORK/data_SPPspp and then finds these done).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diviewer.data.capture import parse_shard  # noqa: E402
from diviewer.data.refine_extras import render_extras, write_job  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402


def frame_range(text: str) -> tuple[int, int]:
    """``A:B`` (frames with A <= index < B) as a pair; refused, naming the option, otherwise."""
    try:
        a, b = (int(x) for x in text.split(":"))
    except ValueError:
        a = b = -1
    if not 0 <= a < b:
        raise DiviewerError(f"--frames must be A:B with 0 <= A < B, got '{text}'", field="--frames")
    return a, b


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    j = sub.add_parser("job", help="write the refinement's job for a range of frames")
    j.add_argument("--data", type=Path, required=True, help="the dataset to refine")
    j.add_argument("--spp", type=int, required=True, help="the refined count (above the dataset's)")
    j.add_argument("--frames", required=True, help="A:B: the present frames with A <= index < B")
    j.add_argument("--out", type=Path, required=True, help="the job file (LZMA JSON)")
    r = sub.add_parser("render", help="render a job's extra samples (this shard's frames) into a folder")
    r.add_argument("job", type=Path)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--shard", default=None, help="k/n: every n-th frame of the job starting at the k-th")
    r.add_argument("--deadline", type=float, default=None, help="no frame begun after this Unix time")
    a = ap.parse_args(argv)
    try:
        if a.cmd == "job":
            first, stop = frame_range(a.frames)
            n = write_job(a.data, a.spp, first, stop, a.out)
            print(f"job of {n} frames ({a.data} to {a.spp} spp, frames {first}..{stop - 1}): {a.out} "
                  f"({a.out.stat().st_size / 1e6:.2f} MB)")
        else:
            s = render_extras(a.job, a.out, parse_shard(a.shard), a.deadline)
            print(f"done: {s['present']} of {s['frames']} frames of the shard in {a.out} ({s['rendered']} rendered "
                  f"in {s['seconds']:.0f} s)")
    except DiviewerError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
