"""Where a capture's training target lies in the network's encoded range: the percentiles of the exposed target (the
indirect light over the albedo and the light scale, times the exposure fitted on the direct light, as the trainer
makes it) and the gain `diviewer train --output-gain` would fit, both on the drawn frames.

Usage: python tools/experiments/target_range.py --data runs/sponza/data [--frames 40] [--seed 0] [--out OUT.json]

``--frames`` train frames drawn (seeded). The encoded values are ``log1p(x) / log1p(radiance_max)`` of those
percentiles: a target whose median encodes to 1e-4 leaves the network almost nothing to resolve it with
(docs/sponza.md, "Where the dark bias comes from"). Measures only.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

PERCENTILES = (50, 90, 99)


def target_range(ds, indices: list[int]) -> dict:
    """The exposed target's luminance percentiles over ``indices`` (a light-scaled, albedo-divided indirect target,
    encoding 2 and later), their encoded values, the exposure and the output gain fitted on the same frames."""
    from diviewer.encoding import Encoding, encode_radiance
    from diviewer.evaluation.scoring import LUMINANCE
    from diviewer.train.config import TrainConfig
    from diviewer.train.targets import exposed_targets, fit_encoding, fit_output_gain
    from diviewer.data.scales import light_scales

    _, train = ds.array("train", indices)
    scales = light_scales(ds, indices)
    enc = fit_encoding(ds, indices, train, scales)
    cfg = TrainConfig(data=ds.root, out=ds.root, target="indirect", divide_albedo=True, output_gain=True)
    gain = fit_output_gain(ds, train, scales, enc, cfg)
    lum = [(t @ LUMINANCE.astype(np.float32)).ravel() for t in exposed_targets(ds, train, scales, enc, cfg)]
    p = np.percentile(np.concatenate(lum), PERCENTILES)
    encoded = encode_radiance(p, Encoding())  # p is exposed already: the curve at exposure 1
    return {"exposure": enc.exposure, "output_gain": gain, "frames": len(indices),
            "exposed": {str(q): float(v) for q, v in zip(PERCENTILES, p)},
            "encoded": {str(q): float(v) for q, v in zip(PERCENTILES, encoded)}}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, required=True)
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    from diviewer.data.dataset import Dataset

    ds = Dataset(a.data)
    idx = sorted(ds.indices("train"))
    pick = sorted(int(i) for i in np.random.default_rng(a.seed).choice(idx, min(a.frames, len(idx)), replace=False))
    r = target_range(ds, pick)
    print(f"{a.data}: exposed target median / 90th / 99th percentile "
          + " / ".join(f"{v:.3g}" for v in r["exposed"].values()) + ", encoded "
          + " / ".join(f"{v:.2g}" for v in r["encoded"].values())
          + f" (exposure {r['exposure']:.4g}); --output-gain would fit {r['output_gain']:.3g}")
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, {"data": str(a.data), "seed": a.seed, **r})
    return 0


if __name__ == "__main__":
    sys.exit(main())
