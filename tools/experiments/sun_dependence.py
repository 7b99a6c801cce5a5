"""How much a frame's indirect light depends on where the light is: the best a network blind to the light's
direction could do, against the path tracer.

Usage: python tools/experiments/sun_dependence.py [--evalset assets/evalsets/sponza] [--split moved_camera]
           [--angles 5] [--res 114x64] [--spp 256] [--cache C.npz] [--out OUT.json]

The networks see the G-buffer, the GL direct light and the light's strength (encoding 2), and encoding 3 adds
where each pixel is (the camera); none sees the light's direction. Where the frame shows sunlit surfaces the
direct-light buffer tells the network much of it, but in a frame of shade it cannot know which side of the scene
the sun lights. For each frame of the split this renders the path tracer's full and direct-only images at
``--angles`` light directions evenly across the scene file's range (the light turned about its range's axis,
``diviewer.scene.lights.rotate_light``; the frame's own strength), and scores, tone-mapped as `diviewer eval`
does (the set's exposure):

- ``blind``: each angle's direct light plus the indirect light averaged over the angles, against that angle's
  full image: what a network that knows everything but the light's direction could at best output (its L2
  optimum over a uniform prior on the angle);
- ``noise``: the same angle rendered with a second seed against the first: how far the path tracer's own noise
  caps the score at ``--spp``.

A frame whose ``blind`` score is far below the issue's 33 dB needs the light's direction as an input. The
renders are kept in ``--cache`` (resumable, one frame at a time).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def angles(lo: float, hi: float, n: int) -> list[float]:
    """``n`` angles evenly across ``[lo, hi]`` (ends included; one: the middle)."""
    return [0.5 * (lo + hi)] if n == 1 else [float(a) for a in np.linspace(lo, hi, n)]


def evalset_scene(evalset: Path):
    """An evaluation set's manifest, its scene (the file it names where present, else the shipped one by name) and
    its tone map's exposure."""
    from diviewer.scene import load_scene

    manifest = json.loads((evalset / "manifest.json").read_text())
    scene = load_scene(manifest["scene_file"] if Path(manifest["scene_file"]).is_file() else manifest["scene"])
    return manifest, scene, float(manifest["evalset"]["tonemap"]["exposure"])


def blind_scores(full: np.ndarray, direct: np.ndarray, exposure: float) -> list[float]:
    """Per angle (axis 0 of ``full`` and ``direct``, (A, H, W, 3) radiance): tone-mapped PSNR of that angle's direct
    light plus the mean indirect light over every angle, against its full image."""
    from diviewer.metrics import psnr, tonemap

    indirect = (full - direct).mean(axis=0)
    return [float(psnr(tonemap(d + indirect, exposure), tonemap(f, exposure))) for f, d in zip(full, direct)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--evalset", type=Path, default=Path("assets/evalsets/sponza"))
    ap.add_argument("--split", default="moved_camera")
    ap.add_argument("--angles", type=int, default=5)
    ap.add_argument("--res", default="114x64")
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--cache", type=Path)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args(argv)
    import dataclasses

    from diviewer.metrics import psnr, tonemap
    from diviewer.reference.mitsuba import MitsubaFrame
    from diviewer.scene.lights import power_field, rotate_light
    from diviewer.scene.loader import config_from_dict

    manifest, scene, exposure = evalset_scene(a.evalset)
    w, h = (int(v) for v in a.res.lower().split("x"))
    frames = [f for f in manifest["frame_list"] if f["split"] == a.split]
    if not frames:
        raise SystemExit(f"{a.evalset}: no frames in split {a.split!r}")
    cache = dict(np.load(a.cache)) if a.cache and a.cache.is_file() else {}
    centre = scene.bounds().mean(axis=0)
    rows = []
    for f in frames:
        config = config_from_dict(scene, f["config"])
        base = scene.default
        full, direct = [], []
        ranged = [d.name for d in base.lights if d.name in scene.ranges.lights]
        if not ranged:
            raise SystemExit(f"{scene.name}: no light has a range of directions ([ranges.lights]): nothing to turn")
        light_angles = {name: angles(*scene.ranges.lights[name].angle, a.angles) for name in ranged}
        names = list(light_angles)
        n = a.angles
        for i in range(n):
            lights = []
            for light, d in zip(config.lights, base.lights):  # the default light turned, at the frame's strength
                turned = rotate_light(d, scene.ranges.lights[d.name].axis, light_angles[d.name][i], centre) \
                    if d.name in light_angles else d
                lights.append(dataclasses.replace(turned, **{power_field(d): getattr(light, power_field(light))}))
            cfg = dataclasses.replace(config, lights=tuple(lights))
            key = f"{f['index']}_{i}"
            if f"full_{key}" not in cache:
                mf = MitsubaFrame(scene, cfg, w, h)
                cache[f"full_{key}"] = mf.full(a.spp, 1 + i)
                cache[f"direct_{key}"] = mf.direct(a.spp, 1 + i)
                if i == n // 2:
                    cache[f"second_{key}"] = mf.full(a.spp, 1000 + i)
                if a.cache:
                    np.savez(a.cache.with_suffix(".tmp.npz"), **cache)
                    a.cache.with_suffix(".tmp.npz").replace(a.cache)
            full.append(cache[f"full_{key}"])
            direct.append(cache[f"direct_{key}"])
        full_a, direct_a = np.stack(full), np.stack(direct)
        mid = f"{f['index']}_{n // 2}"
        noise = float(psnr(tonemap(cache[f"second_{mid}"], exposure), tonemap(cache[f"full_{mid}"], exposure)))
        sunlit = [float((d.max(axis=-1) > 0).mean()) for d in direct_a]
        scores = blind_scores(full_a, direct_a, exposure)
        rows.append({"index": f["index"], "angles": light_angles, "blind_psnr_tm": scores,
                     "blind_mean": float(np.mean(scores)), "noise_psnr_tm": noise, "sunlit_fraction": sunlit})
        print(f"frame {f['index']}: blind {' '.join(f'{s:.2f}' for s in scores)} (mean {np.mean(scores):.2f}) dB; "
              f"noise {noise:.2f} dB; sunlit pixels {' '.join(f'{s:.2f}' for s in sunlit)}", flush=True)
    record = {"evalset": str(a.evalset), "split": a.split, "resolution": [w, h], "spp": a.spp, "angles": a.angles,
              "lights": names, "exposure": exposure, "frames": rows,
              "blind_mean_over_frames": float(np.mean([r["blind_mean"] for r in rows]))}
    print(f"{a.split}: a light-blind network at best {record['blind_mean_over_frames']:.2f} dB tone-mapped "
          f"(mean over {len(rows)} frames and {a.angles} angles)")
    if a.out:
        from diviewer.outputs import write_json

        write_json(a.out, record)  # strict JSON (a frame's inf PSNR as null), written atomically
    return 0


if __name__ == "__main__":
    sys.exit(main())
