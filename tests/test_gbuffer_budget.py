"""tools/experiments/gbuffer_budget.py's vertex clustering, on a flat grid and a folded one with known answers."""

from __future__ import annotations

import numpy as np

from diviewer.scene.model import Mesh
from tool_modules import load_tool


def grid(n: int, fold: bool = False) -> Mesh:
    """A unit square of n x n quads (2 n^2 triangles) at z = 0, facing +z; ``fold``: the right half bent up to face
    -x, the crease at x = 0.5 split (its vertices duplicated with each side's normal), uvs = (x, y)."""
    xs = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(xs, xs, indexing="xy")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    normals = np.tile([0.0, 0.0, 1.0], (x.size, 1))
    i = np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]
    quads = np.stack([i, i + 1, i + n + 2, i + n + 1], axis=-1).reshape(-1, 4)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    if fold:
        right = verts[:, 0] >= 0.5
        # Duplicate the crease's right copies so the two sides keep their own normals.
        crease = np.flatnonzero(np.isclose(verts[:, 0], 0.5))
        dup = {int(v): len(verts) + k for k, v in enumerate(crease)}
        verts = np.concatenate([verts, verts[crease]])
        normals = np.concatenate([normals, normals[crease]])
        right = np.concatenate([right, np.ones(len(crease), bool)])
        on_right = verts[faces].mean(axis=1)[:, 0] > 0.5
        faces[on_right] = np.vectorize(lambda v: dup.get(int(v), int(v)))(faces[on_right])
        verts[right, 2] = verts[right, 0] - 0.5
        verts[right, 0] = 0.5
        normals[right] = [-1.0, 0.0, 0.0]
    return Mesh("grid", verts.astype(np.float32), normals.astype(np.float32), faces.astype(np.uint32),
                verts[:, :2].astype(np.float32))


FOOTPRINT = 1e-3
"""A pixel's footprint per unit distance (a 1000-pixel frame of a ~53-degree field of view)."""


def test_near_triangles_are_kept_exactly():
    tool = load_tool("experiments/gbuffer_budget")
    mesh = grid(8)
    out = tool.simplify(mesh, np.array([0.5, 0.5, 1.0]), FOOTPRINT, 0.5)  # cells of 0.5 mm: below the 2 mm floor
    assert len(out.faces) == len(mesh.faces)
    np.testing.assert_array_equal(out.vertices[out.faces], mesh.vertices[mesh.faces])


def test_far_grid_collapses_to_its_cells():
    tool = load_tool("experiments/gbuffer_budget")
    mesh = grid(64)  # quads of 1/64 = 15.6 mm
    # At 100 units a pixel is 0.1 units, so half a pixel is 50 mm: the level below it has cells of 2^5 = 32 mm,
    # about 2 x 2 quads each.
    out = tool.simplify(mesh, np.array([0.5, 0.5, 100.0]), FOOTPRINT, 0.5)
    assert 0 < len(out.faces) < len(mesh.faces) // 4
    assert np.all(np.abs(out.vertices[:, 2]) < 1e-6)  # still flat
    assert np.allclose(out.normals, [0.0, 0.0, 1.0])
    assert out.vertices[:, :2].min() >= 0.0 and out.vertices[:, :2].max() <= 1.0  # cell means stay inside


def test_creases_keep_the_fold_sharp():
    tool = load_tool("experiments/gbuffer_budget")
    mesh = grid(64, fold=True)
    eye = np.array([0.0, 0.5, 100.0])
    loose = tool.simplify(mesh, eye, FOOTPRINT, 2.0)
    kept = tool.simplify(mesh, eye, FOOTPRINT, 2.0, creases=True)
    unit = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    # With creases kept every normal is one of the two sides'; clustering across the fold averages some.
    assert np.all(np.abs(kept.normals @ unit.T).max(axis=1) > 0.999)
    assert np.any(np.abs(loose.normals @ unit.T).max(axis=1) < 0.99)
    assert len(kept.faces) >= len(loose.faces)
