"""Tiny datasets written without a renderer: a capture's manifest of cornell (its real frame list and scene) with
frames of plausible buffers (a wall facing the camera, a noisy truth), for the derived-dataset tools' checks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.data.capture import CaptureSettings, build_manifest
from diviewer.data.dataset import Dataset, write_frame
from diviewer.scene import load_scene

SIZE = 16


def tiny_capture(root: Path, frames: int = 3, seed: int = 0, **manifest_extra) -> Dataset:
    """A cornell capture of ``frames`` SIZE x SIZE frames at ``root``, every frame present and sound; the manifest
    gets ``manifest_extra`` (an evaluation set's ``kind``, a derivation's record)."""
    settings = CaptureSettings(frames=frames, width=SIZE, height=SIZE, spp=4, max_depth=4, seed=seed)
    manifest = {**build_manifest(load_scene("cornell"), settings), **manifest_extra}
    root.mkdir(parents=True, exist_ok=True)
    imageio.write_text(root / "manifest.json", json.dumps(manifest, indent=1))
    (root / "frames").mkdir(exist_ok=True)
    ds = Dataset(root)
    rng = np.random.default_rng(seed)
    for f in ds.frames:
        arr = np.zeros((SIZE, SIZE, ds.num_channels), np.float32)
        sl = ds.slices
        arr[..., sl["depth"]] = 3.0
        arr[..., sl["normal"]] = (0.0, 0.0, 1.0)
        arr[..., sl["albedo"]] = 0.5
        direct = rng.uniform(0.0, 1.0, (SIZE, SIZE, 3))
        arr[..., sl["direct"]] = direct
        arr[..., sl["pt_direct"]] = direct
        arr[..., sl["pt"]] = direct + 0.2 + rng.normal(0.0, 0.05, (SIZE, SIZE, 3))
        write_frame(ds, f["index"], arr.astype(ds.dtype), {"index": f["index"], "split": f["split"]})
    return ds


def flip_byte(path: Path, offset: int = -7) -> None:
    """One byte of a file changed (``offset`` from its start, or from its end where negative)."""
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x5A
    path.write_bytes(bytes(data))
