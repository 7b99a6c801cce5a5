"""Make assets/sponza/ from the full Sponza in shared/scenes/sponza: base-colour textures only, downscaled.

Usage: python tools/make_sponza_assets.py [--src ../shared/scenes/sponza] [--size 512] [--quality 90]
       python tools/make_sponza_assets.py --measure   (albedo error of the shipped textures vs full size)

The renderers use diffuse albedo only, so normal maps are dropped. Each base-colour texture is resized
(Lanczos, in sRGB as stored) so that its longer side is at most --size; textures without an alpha
channel become JPEG, the three whose alpha is the cut-out mask (plants, chains) stay PNG. The glTF is
rewritten to name the new files and nothing else; Sponza.bin is copied byte for byte. The same inputs
give the same files (Pillow's encoders are deterministic).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
# The shared folder sits beside the main checkout (../shared) or two levels up from a worktree.
DEFAULT_SRC = next((d / "shared" / "scenes" / "sponza" for d in (ROOT, ROOT.parent, ROOT.parents[1])
                    if (d / "shared" / "scenes" / "sponza" / "Sponza.gltf").is_file()),
                   ROOT.parent / "shared" / "scenes" / "sponza")
DEFAULT_OUT = ROOT / "assets" / "sponza"


def compact(src: Path, out: Path, size: int, quality: int) -> dict:
    """Write the compact copy; returns {file: bytes} of what was written."""
    gltf = json.loads((src / "Sponza.gltf").read_text())
    used = sorted({gltf["textures"][m["pbrMetallicRoughness"]["baseColorTexture"]["index"]]["source"]
                   for m in gltf["materials"] if "baseColorTexture" in m.get("pbrMetallicRoughness", {})})
    if out.exists():
        shutil.rmtree(out)
    (out / "textures").mkdir(parents=True)
    new_images, image_index = [], {}
    for i in used:
        img_entry = gltf["images"][i]
        im = Image.open(src / img_entry["uri"])
        im.load()
        scale = min(1.0, size / max(im.size))
        if scale < 1.0:
            im = im.resize((max(1, round(im.width * scale)), max(1, round(im.height * scale))), Image.LANCZOS)
        stem = Path(img_entry["uri"]).stem
        if im.mode == "RGBA":
            name, mime = f"textures/{stem}.png", "image/png"
            im.save(out / name, optimize=True)
        else:
            name, mime = f"textures/{stem}.jpg", "image/jpeg"
            im.convert("RGB").save(out / name, quality=quality, subsampling=0, optimize=True)
        image_index[i] = len(new_images)
        new_images.append({"mimeType": mime, "name": img_entry.get("name", stem), "uri": name})
    # One texture per kept image; materials keep only their base colour.
    texture_of = {}
    new_textures = []
    for m in gltf["materials"]:
        pbr = m.get("pbrMetallicRoughness", {})
        m.pop("normalTexture", None)
        if "baseColorTexture" in pbr:
            source = gltf["textures"][pbr["baseColorTexture"]["index"]]["source"]
            if source not in texture_of:
                texture_of[source] = len(new_textures)
                new_textures.append({"source": image_index[source]})
            pbr["baseColorTexture"] = {"index": texture_of[source]}
    gltf["images"], gltf["textures"] = new_images, new_textures
    gltf["asset"].setdefault("extras", {})["compacted"] = (
        f"base-colour textures only, longer side <= {size} px, JPEG (quality {quality}) where there is no alpha; "
        f"made by diviewer's tools/make_sponza_assets.py from the full asset")
    (out / "Sponza.gltf").write_text(json.dumps(gltf, indent=1) + "\n")
    shutil.copyfile(src / "Sponza.bin", out / "Sponza.bin")
    licence = (src / "LICENSE.md").read_text()
    (out / "LICENSE.md").write_text(
        licence.rstrip() + "\n\n## Compacted copy shipped with diviewer\n\n"
        f"This folder is made from the asset above by `tools/make_sponza_assets.py`: `Sponza.bin` unchanged "
        f"(sha256 {hashlib.sha256((src / 'Sponza.bin').read_bytes()).hexdigest()}); `Sponza.gltf` with the "
        f"normal maps removed and the images renamed; the {len(used)} base-colour textures downscaled to at most "
        f"{size} px, JPEG (quality {quality}) where they have no alpha channel, PNG where the alpha is the cut-out "
        f"mask. `preview.png` is not shipped.\n")
    return {str(p.relative_to(out)): p.stat().st_size for p in sorted(out.rglob("*")) if p.is_file()}


def measure(src: Path, sizes=(256, 512), stops=(0.0, 0.3, 0.55, 0.8)) -> list[dict]:
    """G-buffer albedo PSNR (linear and sRGB-encoded, peak 1) of the shipped textures against the full-size
    ones, at camera path positions ``stops`` of the shipped scene, for each square render size."""
    import dataclasses
    import tomllib

    import numpy as np

    from diviewer.gl.context import create_context
    from diviewer.gl.renderer import Renderer
    from diviewer.metrics import psnr
    from diviewer.scene.loader import parse_scene
    from diviewer.scene.sampler import camera_on_path
    from diviewer.scene.colour import linear_to_srgb

    toml = ROOT / "assets" / "scenes" / "sponza.toml"
    data = tomllib.loads(toml.read_text())
    shipped = parse_scene(data, path=toml)
    full = parse_scene({**data, "gltf": {"file": str((src / "Sponza.gltf").resolve())}}, path=toml)
    ctx = create_context("egl")
    rows = []
    for n in sizes:
        ra, rb = Renderer(ctx, shipped, n, n), Renderer(ctx, full, n, n)
        for s in stops:
            config = dataclasses.replace(shipped.default, camera=camera_on_path(shipped, s))
            a, b = ra.frame(config)["albedo"], rb.frame(config)["albedo"]
            rows.append({"res": n, "path": s, "psnr_linear": psnr(a, b), "psnr_srgb": psnr(linear_to_srgb(a), linear_to_srgb(b)),
                         "max_abs": float(np.abs(a - b).max())})
            print(f"{n}x{n} path {s:.2f}: albedo PSNR {rows[-1]['psnr_linear']:.2f} dB linear, "
                  f"{rows[-1]['psnr_srgb']:.2f} dB sRGB", flush=True)
        ra.release()
        rb.release()
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--src", type=Path, default=DEFAULT_SRC)
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--size", type=int, default=512, help="longest texture side, pixels")
    ap.add_argument("--quality", type=int, default=90, help="JPEG quality")
    ap.add_argument("--measure", action="store_true",
                    help="only measure: G-buffer albedo of the shipped textures against the full-size ones")
    a = ap.parse_args(argv)
    if a.measure:
        measure(a.src)
        return
    files = compact(a.src, a.out, a.size, a.quality)
    print(f"{a.out}: {len(files)} files, {sum(files.values()) / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
