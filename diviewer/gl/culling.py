"""What a pass draws: the static geometry in spatial chunks, each with its bounding box, culled against the
pass's frustum (the camera's, or a light's). No GL calls here: the GPU copies live in resources.GpuScene.

Sponza's static geometry merged per material is 24 draws that cover the whole atrium, so every pass drew
all 262k triangles wherever the camera looked. Each material's triangles are split here into chunks of at
most ``CHUNK_TRIANGLES`` (halving along the longest side of their centroids' box), so a frustum test on the
chunks' boxes leaves out what is behind or beside the camera. The test is conservative (a box is dropped
only when it lies wholly outside one plane), so culling changes which draws run, never a pixel.
"""

from __future__ import annotations

import numpy as np

from diviewer.scene.model import FrameConfig, Mesh, Scene

CHUNK_TRIANGLES = 8192
"""Most triangles in one static chunk: small enough to cull by, large enough to keep draws few (Sponza: ~60)."""


def spatial_groups(centroids: np.ndarray, max_items: int) -> list[np.ndarray]:
    """Indices into ``centroids`` (N, 3) cut into compact groups of at most ``max_items``: a group too large is
    halved along the longest side of its centroids' box (stable, so equal keys keep their order). In order of each
    group's smallest index, the indices within a group ascending."""
    groups, todo = [], [np.arange(len(centroids))]
    while todo:
        idx = todo.pop()
        if len(idx) <= max_items:
            groups.append(np.sort(idx))
            continue
        c = centroids[idx]
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = np.argsort(c[:, axis], kind="stable")
        half = len(idx) // 2
        todo += [idx[order[half:]], idx[order[:half]]]
    return sorted(groups, key=lambda g: int(g[0]))


def split_mesh(mesh: Mesh, max_triangles: int = CHUNK_TRIANGLES) -> list[Mesh]:
    """``mesh`` cut into spatially compact pieces of at most ``max_triangles`` triangles (vertices re-indexed
    per piece); the pieces' triangles, in their original order within each piece, are exactly the mesh's."""
    faces = np.asarray(mesh.faces)
    if len(faces) <= max_triangles:
        return [mesh]
    out = []
    for i, idx in enumerate(spatial_groups(mesh.vertices[faces].mean(axis=1), max_triangles)):
        f = faces[idx]
        used, inverse = np.unique(f.ravel(), return_inverse=True)
        out.append(Mesh(f"{mesh.name}#{i}", mesh.vertices[used], mesh.normals[used],
                        inverse.reshape(f.shape).astype(np.uint32),
                        mesh.uvs[used] if mesh.uvs is not None else None, source=mesh.source))
    return out


def box_corners(bounds) -> np.ndarray:
    """The 8 corners (8, 3) of a box (2, 3), x-major: [x, y, z] for x in (lo, hi) for y ... for z ...; two corners
    one bit apart in their index share an edge."""
    b = np.asarray(bounds, np.float64)
    return np.array([[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def world_box(bounds: np.ndarray, model: np.ndarray | None) -> np.ndarray:
    """The world-space box (2, 3) of an object-space box under ``model`` (None: the box is world-space)."""
    if model is None:
        return np.asarray(bounds, np.float64)
    w = box_corners(bounds) @ model[:3, :3].T + model[:3, 3]
    return np.stack([w.min(axis=0), w.max(axis=0)])


def frustum_planes(clip: np.ndarray) -> np.ndarray:
    """The six planes (6, 4) of the frustum of a world-to-clip matrix, ``n . p + d >= 0`` inside (Gribb and
    Hartmann's rows; works for perspective and orthographic matrices alike)."""
    m = np.asarray(clip, np.float64)
    planes = np.array([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2], m[3] - m[2]])
    return planes / np.maximum(np.linalg.norm(planes[:, :3], axis=1, keepdims=True), 1e-30)


def boxes_visible(planes: np.ndarray, boxes: np.ndarray, margin: float = 1e-4) -> np.ndarray:
    """Which boxes (N, 2, 3) are not wholly outside any plane: per box, the corner furthest along each plane's
    normal must lie inside it (``margin`` in world units of slack against round-off)."""
    return np.all(_furthest_inside(planes, boxes[:, 0, :], boxes[:, 1, :]) >= -margin, axis=1)


def _furthest_inside(planes: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N, P): how far inside each plane (P, 4) each box's (lo, hi: (N, 3)) corner furthest along its normal lies."""
    n = planes[:, :3]
    far = np.where(n[None, :, :] >= 0.0, hi[:, None, :], lo[:, None, :])  # (N, P, 3)
    return np.einsum("npk,pk->np", far, n) + planes[None, :, 3]


def shadow_casters(boxes: np.ndarray, camera_clip: np.ndarray, direction, bounds: np.ndarray,
                   margin: float) -> np.ndarray:
    """Which boxes (N, 2, 3) can shade what the camera of ``camera_clip`` (world to clip) sees, lit by a sun whose
    light travels along ``direction``: a box's shadow is the box swept along it until the sweep leaves the scene's
    ``bounds``, and a box whose sweep lies wholly outside one plane of the camera's frustum shades nothing in view.
    ``margin`` (world units) widens each box first: a visible point's shadow lookup reads the map a few texels
    beside it (its normal offset, the filter's taps). Conservative, as `boxes_visible`: a dropped caster changes no
    lookup of a visible point, for one beyond that point never shadows it and one before it sweeps through it."""
    d = np.asarray(direction, np.float64) / max(float(np.linalg.norm(direction)), 1e-30)
    lo, hi, b = boxes[:, 0, :] - margin, boxes[:, 1, :] + margin, np.asarray(bounds, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):  # per axis, the longest way any point of a box has left
        travel = np.where(d > 0, (b[1] - lo) / d, np.where(d < 0, (b[0] - hi) / d, np.inf))
    reach = np.maximum(travel.min(axis=1), 0.0)
    planes = frustum_planes(camera_clip)  # the sweep reaches further inside the planes whose normal has d in it
    ahead = _furthest_inside(planes, lo, hi) + reach[:, None] * np.maximum(planes[:, :3] @ d, 0.0)[None, :]
    return np.all(ahead >= -1e-4, axis=1)


def static_objects(scene: Scene, config: FrameConfig) -> list | None:
    """The objects the scene's ranges never move, where a frame draws them merged (`draw_list`): more than one, all
    of them in the frame unchanged; else None."""
    static = [o for o in scene.default.objects if o.name not in scene.ranges.objects]
    return static if len(static) > 1 and set(static) <= set(config.objects) else None


def draw_list(scene: Scene, config: FrameConfig, gpu, static: list | None) -> list[tuple]:
    """(GPU mesh, material, model matrix or None for world space, world box, object name or None) per draw, opaque
    first.

    The objects that the scene's ranges never move (``static``, `static_objects`) are drawn from their geometry
    merged per material and cut into chunks, which ``gpu`` (a resources.GpuScene) holds uploaded
    (``GpuScene.set_static``); the moving objects are drawn one by one.
    """
    items = []
    if static is not None:
        static_set = set(static)
        items = [(m, material, None, m.bounds, None) for material, m in gpu.static]
        moving = [o for o in config.objects if o not in static_set]
    else:
        moving = config.objects
    for o in moving:
        gmesh, m = gpu.meshes[o.mesh], o.matrix()
        items.append((gmesh, o.material, m, world_box(gmesh.bounds, m), o.name))
    items.sort(key=lambda it: scene.materials[it[1]].is_masked)  # opaque first: early depth test
    return items


def draw_order(boxes: np.ndarray, keep: np.ndarray, masked: np.ndarray, eye: np.ndarray | None) -> np.ndarray:
    """The indices of the kept boxes in drawing order. With a camera position ``eye``: unmasked (opaque) items
    front to back by each world box's nearest point, then the alpha-masked ones the same way, so that the depth
    test rejects hidden fragments before they are shaded (llvmpipe tests depth early unless a shader
    discards). Without one (a shadow map), the list's order."""
    idx = np.flatnonzero(keep)
    if eye is None or len(idx) < 2:
        return idx
    near = np.clip(eye, boxes[idx, 0], boxes[idx, 1])
    dist = np.linalg.norm(near - eye, axis=1)
    return idx[np.lexsort((dist, masked[idx]))]
