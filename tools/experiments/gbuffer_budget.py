"""Where Sponza's G-buffer time goes on a software rasterizer, and whether a simplified far mesh would cut it.

Usage: python tools/experiments/gbuffer_budget.py [--sizes 16,307,768] [--lod 0.5,1] [--creases] [--frames 12]
       [--out J.json]

For the scene file's default view (down the whole atrium, the worst case for culling) the G-buffer pass alone is
drawn ``--frames`` times at each square size, and for each size the script reports the median wall time and the
CPU time each thread spent per pass: the calling thread (llvmpipe's front end: vertex shading, clipping,
triangle setup and binning) and llvmpipe's rasterizer threads (``llvmpipe-N``: per-tile rasterization and the
fragment shader), read from /proc/self/task/*/stat. At 16x16 almost no fragment work is left, so that row is the
front end's floor. The sum of the CPU times over the cores is the least wall time any overlap of the two could
reach on this machine.

``--lod F`` redraws at the largest size with the static geometry simplified by vertex clustering (Rossignac and
Borrel): each triangle goes to the level whose cell is at most F pixels' footprint at its centroid's distance
from the camera (cells 1 mm x 2^k), its vertices snap to their cell's mean (normal and uv averaged), and the
triangles that collapse are dropped (``--creases``: also with vertices keyed by a normal bucket and a uv cell,
so creases and texture seams stay). It reports the triangles drawn, the time, and the share of G-buffer pixels
(depth, normal, albedo) that moved by more than 0.01 and 0.1 against the full mesh. This is the best case for a
level-of-detail scheme: the levels are chosen for this one camera, with no per-frame selection cost.
Stop other jobs first (SIGSTOP) when the times matter.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def thread_cpu() -> dict[str, float]:
    """CPU seconds (user + system) per thread name of this process, summed over threads of the same name; the
    process's first thread (the one that calls GL) is "main"."""
    tick = os.sysconf("SC_CLK_TCK")
    out: dict[str, float] = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            stat = (task / "stat").read_text()
        except OSError:
            continue
        name = "main" if task.name == str(os.getpid()) else stat[stat.index("(") + 1:stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2:].split()
        out[name] = out.get(name, 0.0) + (int(fields[11]) + int(fields[12])) / tick
    return out


def simplify(mesh, eye: np.ndarray, footprint: float, frac: float, creases: bool = False):
    """``mesh`` with each triangle's vertices clustered in cells of at most ``frac`` pixels at its distance;
    ``creases``: vertices cluster only with those of the same normal bucket (rounded 1.5 n) and uv cell (1/16)."""
    from diviewer.scene.model import Mesh

    faces = mesh.faces.astype(np.int64)
    verts = mesh.vertices.astype(np.float64)
    cell = np.linalg.norm(verts[faces].mean(axis=1) - eye, axis=1) * footprint * frac
    level = np.where(cell < 2e-3, -1, np.floor(np.log2(np.maximum(cell, 1e-9) / 1e-3))).astype(int)
    uvs = mesh.uvs if mesh.uvs is not None else np.zeros((len(verts), 2), np.float32)
    pv, pn, puv, pf, base = [], [], [], [], 0
    for k in np.unique(level):
        f = faces[level == k]
        used, inverse = np.unique(f.ravel(), return_inverse=True)
        if k < 0:
            cid, n = inverse.reshape(-1, 3), len(used)
            pv.append(verts[used]), pn.append(mesh.normals[used]), puv.append(uvs[used])
        else:
            key = [np.floor(verts[used] / (1e-3 * 2.0 ** k))]
            if creases:
                key += [np.round(mesh.normals[used] * 1.5), np.floor(uvs[used] * 16)]
            _, group = np.unique(np.concatenate(key, axis=1).astype(np.int64), axis=0, return_inverse=True)
            group = group.ravel()
            n = int(group.max()) + 1
            count = np.bincount(group, minlength=n)[:, None]
            sums = [np.zeros((n, a.shape[1])) for a in (verts, mesh.normals, uvs)]
            for s, a in zip(sums, (verts[used], mesh.normals[used], uvs[used])):
                np.add.at(s, group, a)
            pv.append(sums[0] / count)
            pn.append(sums[1] / np.maximum(np.linalg.norm(sums[1], axis=1, keepdims=True), 1e-12))
            puv.append(sums[2] / count)
            cid = group[inverse].reshape(-1, 3)
            cid = cid[(cid[:, 0] != cid[:, 1]) & (cid[:, 1] != cid[:, 2]) & (cid[:, 0] != cid[:, 2])]
        pf.append(cid + base)
        base += n
    return Mesh(mesh.name, np.concatenate(pv).astype(np.float32), np.concatenate(pn).astype(np.float32),
                np.concatenate(pf).astype(np.uint32),
                np.concatenate(puv).astype(np.float32) if mesh.uvs is not None else None, source="merged")


def small_triangles(scene, size: int) -> tuple[int, int]:
    """Of the static triangles wholly in front of the default camera with a vertex inside the frame: how many, and
    how many cover less than half a pixel at ``size`` x ``size``."""
    from diviewer.gl.resources import merge_static

    config = scene.default
    clip = config.camera.projection(1.0) @ config.camera.view_matrix()
    static = [o for o in config.objects if o.name not in scene.ranges.objects]
    seen = small = 0
    for mesh in merge_static(scene.meshes, static).values():
        v = np.c_[mesh.vertices, np.ones(len(mesh.vertices))] @ clip.T
        p = v[:, :2] / np.maximum(v[:, 3:], 1e-6) * 0.5 * size
        f = mesh.faces
        inside = (v[f, 3] > config.camera.near).all(axis=1) & (np.abs(p[f]).max(axis=2).min(axis=1) < size / 2)
        e1, e2 = p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        seen += int(inside.sum())
        small += int((inside & (area < 0.5)).sum())
    return seen, small


def measure(scene, size: int, frames: int, lod: float | None, creases: bool = False) -> tuple[dict, dict]:
    """One fresh context: the G-buffer pass ``frames`` times; its row and its depth, normal and albedo images."""
    from diviewer.gl import resources
    from diviewer.gl.context import create_context
    from diviewer.gl.renderer import FrameView, Renderer

    config = scene.default
    merge = resources.merge_static
    if lod is not None:
        eye = np.linalg.inv(config.camera.view_matrix())[:3, 3]
        footprint = 2.0 * np.tan(np.radians(config.camera.fov) / 2.0) / size
        resources.merge_static = lambda meshes, objs: {k: simplify(m, eye, footprint, lod, creases)
                                                       for k, m in merge(meshes, objs).items()}
    try:
        ctx = create_context("egl")
        r = Renderer(ctx, scene, size, size)
        r.render(config, direct=False)
        ctx.finish()
        frame = FrameView(config, config.camera.view_matrix(), config.camera.projection(1.0), r._bounds[2])
        walls = []
        cpu0 = thread_cpu()
        for _ in range(frames):
            r.drawn = {}
            t = time.perf_counter()
            r._gbuffer_pass(frame)
            ctx.finish()
            walls.append(time.perf_counter() - t)
        cpu1 = thread_cpu()
        images = {k: r.read(k) for k in ("depth", "normal", "albedo")}
        ctx.release()
    finally:
        resources.merge_static = merge
    raster = sum(cpu1[k] - cpu0.get(k, 0.0) for k in cpu1 if k.startswith("llvmpipe"))
    row = {"size": size, "lod_pixels": lod, "creases_kept": creases, "triangles": r.drawn["gbuffer"][1], "draws": r.drawn["gbuffer"][0],
           "wall_ms": round(1000 * float(np.median(walls)), 1),
           "front_end_cpu_ms": round(1000 * (cpu1["main"] - cpu0["main"]) / frames, 1),
           "raster_cpu_ms": round(1000 * raster / frames, 1)}
    return row, images


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="16,307,768", help="square G-buffer sizes (768x768 at scale 0.4: 307)")
    ap.add_argument("--lod", default="", help="comma-separated cell sizes in pixels for the simplified mesh")
    ap.add_argument("--creases", action="store_true", help="--lod also with creases and uv seams kept")
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON")
    args = ap.parse_args()

    from diviewer.scene.loader import load_scene

    scene = load_scene("sponza")
    sizes = [int(s) for s in args.sizes.split(",")]
    rows, full = [], None
    for size in sizes:
        row, full = measure(scene, size, args.frames, None)
        row["triangles_in_view"], row["under_half_a_pixel"] = small_triangles(scene, size)
        rows.append(row)
        print(row, flush=True)
    lods = [(float(f), False) for f in args.lod.split(",") if f]
    lods += [(f, True) for f, _ in lods] if args.creases else []
    for frac, creases in lods:
        row, images = measure(scene, sizes[-1], args.frames, frac, creases)
        for k, a in full.items():
            d = np.abs(a - images[k])
            d = d.max(axis=-1) if d.ndim == 3 else d
            row[f"{k}_moved_0.01"] = round(float((d > 0.01).mean()), 4)
            row[f"{k}_moved_0.1"] = round(float((d > 0.1).mean()), 4)
        rows.append(row)
        print(row, flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"machine": os.uname().nodename, "cores": os.cpu_count(), "rows": rows},
                                       indent=1) + "\n")


if __name__ == "__main__":
    main()
