"""How much exact occlusion culling could take off Sponza's G-buffer: per camera, the triangles the frustum test
draws (per static chunk, as the renderer culls today, and per cluster of 128 triangles), the triangles left once
every cluster hidden behind the frame's final depth is dropped (an oracle: the best a two-phase occlusion cull
that tests cluster boxes against a depth pyramid can do), and optionally the G-buffer's time both ways.

Usage: python tools/experiments/occlusion_probe.py [--size 384] [--path-steps 20] [--time] [--out J.json]

Cameras: the scene file's default and ``--path-steps`` points along its camera walk. Each static chunk
(`diviewer.gl.culling.split_mesh`) is cut into clusters of at most 128 triangles by the same halving along the
longest side (`spatial_groups`); a cluster counts as hidden when its box's nearest point lies behind the farthest final depth over
every pixel its box can cover (a max-depth pyramid, one pixel of slack). ``--time`` draws the default view's
G-buffer of each camera three ways: as the renderer does (the chunks in the frustum), the clusters in the frustum
only, and the oracle's clusters only, the last two from an index buffer per chunk made for the camera (a best
case: no multi-draw, no per-frame upload); medians of 8 each, and the CPU cost of the pyramid and the box test.
Stop other jobs first. The oracle needs the
final depth before drawing, so a real cull pays at least one depth read and a second draw phase on top.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

CLUSTER = 128
_CORNERS = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], np.float64)


def clusters_of(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Boxes (C, 2, 3), triangle counts (C,) and face groups of a chunk's clusters."""
    from diviewer.gl.culling import spatial_groups

    groups = spatial_groups(vertices[faces].mean(axis=1), CLUSTER)
    boxes = np.array([[vertices[faces[g]].reshape(-1, 3).min(0), vertices[faces[g]].reshape(-1, 3).max(0)]
                      for g in groups])
    return boxes, np.array([len(g) for g in groups]), groups


def max_pyramid(depth: np.ndarray) -> list[np.ndarray]:
    """Levels of the farthest depth (0 = nothing drawn = infinitely far), each half the last, odd edges padded far."""
    d = np.where(depth > 0.0, depth, np.inf).astype(np.float32)
    levels = [d]
    while d.shape[0] > 1 or d.shape[1] > 1:
        p = np.full((-(-d.shape[0] // 2) * 2, -(-d.shape[1] // 2) * 2), np.inf, np.float32)
        p[:d.shape[0], :d.shape[1]] = d
        d = np.maximum(np.maximum(p[0::2, 0::2], p[1::2, 0::2]), np.maximum(p[0::2, 1::2], p[1::2, 1::2]))
        levels.append(d)
    return levels


def hidden(boxes: np.ndarray, view: np.ndarray, clip: np.ndarray, levels: list[np.ndarray]) -> np.ndarray:
    """Boxes wholly behind the depth over every pixel they can cover (boxes reaching the camera plane never)."""
    n = len(boxes)
    corners = boxes[:, 0, None, :] + _CORNERS[None] * (boxes[:, 1] - boxes[:, 0])[:, None, :]
    hom = np.concatenate([corners, np.ones((n, 8, 1))], axis=2)
    depth = -(hom @ view[2])
    c = hom @ clip.T
    front = np.all(c[..., 3] > 1e-6, axis=1) & np.all(depth > 0.0, axis=1)
    out = np.zeros(n, bool)
    if not front.any():
        return out
    c = c[front]
    h, w = levels[0].shape
    x = (c[..., 0] / c[..., 3] * 0.5 + 0.5) * w - 0.5
    y = (c[..., 1] / c[..., 3] * 0.5 + 0.5) * h - 0.5
    x0 = np.clip(np.floor(x.min(1)) - 1, 0, w - 1).astype(np.int64)
    x1 = np.clip(np.ceil(x.max(1)) + 1, 0, w - 1).astype(np.int64)
    y0 = np.clip(np.floor(y.min(1)) - 1, 0, h - 1).astype(np.int64)
    y1 = np.clip(np.ceil(y.max(1)) + 1, 0, h - 1).astype(np.int64)
    level = np.clip(np.ceil(np.log2(np.maximum(np.maximum(x1 - x0, y1 - y0), 1))), 0, len(levels) - 1).astype(int)
    far = np.full(len(x0), np.inf)
    for k in np.unique(level):
        s = np.flatnonzero(level == k)
        img = levels[k]
        a0, a1, b0, b1 = x0[s] >> k, x1[s] >> k, y0[s] >> k, y1[s] >> k
        far[s] = np.maximum(np.maximum(img[b0, a0], img[b0, a1]), np.maximum(img[b1, a0], img[b1, a1]))
    out[np.flatnonzero(front)] = depth[front].min(axis=1) > far * (1.0 + 1e-4)
    return out


def timed(ctx, fn) -> float:
    """Median milliseconds of 8 runs of ``fn`` after one warm-up, each between two glFinish."""
    out = []
    for _ in range(9):
        ctx.finish()
        t = time.perf_counter()
        fn()
        ctx.finish()
        out.append(time.perf_counter() - t)
    return float(np.median(out[1:]) * 1e3)


def subset_draws(ctx, r, scene, static, per_chunk, owner, keep) -> list[tuple]:
    """Per static chunk with kept clusters: a GPU mesh of the chunk's vertices and just those clusters' triangles (a
    best case: no multi-draw), its program and material."""
    from diviewer.gl.resources import GpuMesh
    from diviewer.scene.model import Mesh

    draws = []
    for j, (_, (gmesh, material, _, _)) in enumerate(static):
        mine = np.flatnonzero(keep[owner == j])
        if len(mine) == 0:
            continue
        groups = per_chunk[j][2]
        faces = np.frombuffer(gmesh.ibo.read(), "u4").reshape(-1, 3)
        v = np.frombuffer(gmesh.vbo.read(), "f4").reshape(-1, 8)  # GpuMesh.STRIDE_FORMAT: position, normal, uv
        sub = GpuMesh(ctx, Mesh("subset", v[:, :3], v[:, 3:6], np.concatenate([faces[groups[k]] for k in mine]),
                                v[:, 6:8]))
        mat = scene.materials[material]
        prog = r.shaders.program("gbuffer.glsl", {"ALPHA_TEST": 1} if mat.is_masked else {})
        draws.append((sub, prog, mat, material))
    draws.sort(key=lambda d: d[2].is_masked)  # opaque first, as the renderer
    return draws


def draw_subset(ctx, r, scene, draws, view, proj) -> None:
    """The G-buffer pass of ``subset_draws`` (the renderer's uniforms; static geometry is in world space)."""
    import moderngl

    from diviewer.gl.resources import set_uniform
    from diviewer.scene import camera as cam

    fbo = r._gbuffer_fbo_dark
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
    ctx.enable_only(moderngl.DEPTH_TEST)
    for sub, prog, mat, material in draws:
        set_uniform(prog, "m_proj", proj)
        set_uniform(prog, "m_view", view)
        set_uniform(prog, "m_model", np.eye(4))
        set_uniform(prog, "m_normal", cam.normal_matrix(view))
        set_uniform(prog, "u_albedo", tuple(mat.albedo))
        set_uniform(prog, "u_emission", tuple(mat.emission))
        tex = r.gpu.textures.get(material)
        set_uniform(prog, "u_has_texture", tex is not None)
        if tex is not None:
            tex.use(location=0)
            set_uniform(prog, "u_albedo_map", 0)
        if mat.is_masked:
            set_uniform(prog, "u_alpha_cutoff", float(mat.alpha_cutoff))
        sub.vao(prog).render(moderngl.TRIANGLES)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=384, help="square G-buffer size (768x768 at render scale 0.5: 384)")
    ap.add_argument("--path-steps", type=int, default=20, help="cameras along the walk, besides the default")
    ap.add_argument("--time", action="store_true", help="also time the default view's G-buffer both ways")
    ap.add_argument("--out", type=Path, default=None, help="write the rows as JSON")
    args = ap.parse_args()

    from diviewer.gl.context import create_context
    from diviewer.gl.culling import boxes_visible, frustum_planes
    from diviewer.gl.renderer import Renderer
    from diviewer.scene.loader import load_scene
    from diviewer.scene.sampler import camera_on_path

    ctx = create_context("egl")
    scene = load_scene("sponza")
    r = Renderer(ctx, scene, args.size, args.size)
    r.render(scene.default)
    items, chunk_boxes, _ = r._draw_list(scene.default)
    static = [(i, it) for i, it in enumerate(items) if it[2] is None]
    per_chunk = []
    for _, (gmesh, *_rest) in static:
        idx = np.frombuffer(gmesh.ibo.read(), "u4").reshape(-1, 3)
        verts = np.frombuffer(gmesh.vbo.read(), "f4").reshape(-1, 8)[:, :3].astype(np.float64)
        per_chunk.append(clusters_of(verts, idx))
    boxes = np.concatenate([b for b, _, _ in per_chunk])
    tris = np.concatenate([t for _, t, _ in per_chunk])
    owner = np.concatenate([np.full(len(t), j) for j, (_, t, _) in enumerate(per_chunk)])
    chunk_tris = np.array([it[0].triangles for _, it in static])

    cameras = [("default", scene.default)]
    for s in np.linspace(0.0, 1.0, args.path_steps, endpoint=False):
        cameras.append((f"path {s:.2f}", dataclasses.replace(scene.default, camera=camera_on_path(scene, float(s)))))
    rows = []
    for name, config in cameras:
        r.render(config)
        view, clip = r.frame_view.view, r.frame_view.proj @ r.frame_view.view
        depth = np.frombuffer(r.textures["depth"].read(), "f4").reshape(args.size, args.size)
        planes = frustum_planes(clip)
        chunk_in = boxes_visible(planes, np.array([chunk_boxes[i] for i, _ in static]))
        in_frustum = boxes_visible(planes, boxes) & chunk_in[owner]
        seen = in_frustum & ~hidden(boxes, view, clip, max_pyramid(depth))
        row = {"camera": name, "chunk_frustum": int(chunk_tris[chunk_in].sum()),
               "cluster_frustum": int(tris[in_frustum].sum()), "oracle": int(tris[seen].sum()),
               "clusters_in_frustum": int(in_frustum.sum()), "clusters_hidden": int((in_frustum & ~seen).sum())}
        rows.append(row)
        print(f"{name:>10}: chunks in frustum {row['chunk_frustum']:>7} triangles, clusters {row['cluster_frustum']:>7},"
              f" not hidden {row['oracle']:>7} ({row['oracle'] / max(row['chunk_frustum'], 1):.0%});"
              f" {row['clusters_hidden']} of {row['clusters_in_frustum']} clusters hidden")
    result = {"size": args.size, "cluster_triangles": CLUSTER, "rows": rows}

    if args.time:
        result["time_ms"] = []
        for (name, config), row in zip(cameras, rows):
            r.render(config)
            view, proj = r.frame_view.view, r.frame_view.proj
            clip = proj @ view
            depth = np.frombuffer(r.textures["depth"].read(), "f4").reshape(args.size, args.size)
            t0 = time.perf_counter()
            levels = max_pyramid(depth)
            t1 = time.perf_counter()
            chunk_in = boxes_visible(frustum_planes(clip), np.array([chunk_boxes[i] for i, _ in static]))
            in_frustum = boxes_visible(frustum_planes(clip), boxes) & chunk_in[owner]
            seen = in_frustum & ~hidden(boxes, view, clip, levels)
            t2 = time.perf_counter()
            times = {"chunks": timed(ctx, lambda: r._gbuffer_pass(r.frame_view))}
            for way, keep in (("clusters", in_frustum), ("oracle", seen)):
                draws = subset_draws(ctx, r, scene, static, per_chunk, owner, keep)
                times[way] = timed(ctx, lambda: draw_subset(ctx, r, scene, draws, view, proj))
                for sub, *_ in draws:
                    sub.release()
            times.update(pyramid=(t1 - t0) * 1e3, box_test=(t2 - t1) * 1e3)
            result["time_ms"].append({"camera": name, **times})
            print(f"{name:>10}: G-buffer {times['chunks']:.1f} ms as today ({row['chunk_frustum']} triangles), "
                  f"{times['clusters']:.1f} ms per-cluster frustum ({row['cluster_frustum']}), {times['oracle']:.1f} ms"
                  f" oracle ({row['oracle']}); pyramid {times['pyramid']:.1f} ms, box test {times['box_test']:.1f} ms")
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
