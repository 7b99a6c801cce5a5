"""diviewer from a script: load a scene, render a frame headless with the shipped model, then score that model on
two frames of the scene's shipped compact evaluation set against the path-traced truth.

Usage: python docs/examples/script_api.py [SCENE]   (default cornell; run from the repository's root)
"""

import itertools
import sys
from pathlib import Path

import numpy as np

import diviewer
from diviewer.metrics import psnr

ROOT = Path(__file__).resolve().parents[2]


def main(scene_name: str = "cornell") -> None:
    model = ROOT / "assets" / "models" / f"{scene_name}.onnx"
    scene = diviewer.load_scene(scene_name)
    frame = diviewer.render_frame(scene, size=64, model=model)  # the scene's default view, 64x64
    for name, image in frame.items():
        print(f"{name:8s} {'x'.join(map(str, image.shape))} mean {float(np.mean(image)):.4f}")
    gain = float(np.mean(frame["neural"])) / max(float(np.mean(frame["direct"])), 1e-12)
    print(f"the model's image holds {gain:.2f}x the direct light's mean (the indirect light it adds)")

    frames = diviewer.iter_frames(ROOT / "assets" / "evalsets" / scene_name, model, log=lambda *_: None)
    for f in itertools.islice(frames, 2):
        truth = f.tonemapped(f.truth)
        print(f"frame {f.index} ({f.key}, {f.shape[0]}x{f.shape[1]}): tone-mapped PSNR against the path tracer: "
              f"model {psnr(f.tonemapped(f.output), truth):.2f} dB, "
              f"direct light alone {psnr(f.tonemapped(f.inputs['direct']), truth):.2f} dB")


if __name__ == "__main__":
    main(*sys.argv[1:2])
