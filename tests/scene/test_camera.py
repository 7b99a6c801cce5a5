"""The camera conventions the renderers and the tools share: view rays, the view's inverse, and the world
position a G-buffer's depth stands for (as direct.glsl and tests/oracles.py reconstruct it)."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.scene import camera as cam
from oracles import world_buffers


def test_view_to_world_inverts_the_view():
    view = cam.look_at((0.3, 1.2, 3.0), (0.1, 0.9, -0.5), (0.0, 1.0, 0.0))
    np.testing.assert_allclose(cam.view_to_world(view) @ view, np.identity(4), atol=1e-12)


@pytest.mark.parametrize("crop_xy", [(0, 0), (50, 0), (100, 0)])
def test_world_buffers_project_back_to_their_pixels(crop_xy):
    """A crop's reconstructed world points, projected with the full render's view and projection, land on the
    centres of the crop's pixels at their depths; world normals turned back by the view are the view normals."""
    rng = np.random.default_rng(0)
    sw, sh, size = 228, 128, 128
    camera = {"position": [-0.4, 1.4, 3.9], "target": [0.2, 1.3, 0.4], "up": [0.0, 1.0, 0.0], "fov": 41.0}
    depth = rng.uniform(0.5, 6.0, (size, size)).astype(np.float32)
    depth[:5] = 0.0  # background rows
    n_view = rng.normal(size=(size, size, 3))
    n_view /= np.linalg.norm(n_view, axis=-1, keepdims=True)
    pos, n_world = world_buffers(depth, n_view, camera, (sw, sh), crop_xy, np.zeros(3), 100.0)
    assert pos.shape == n_world.shape == (size, size, 3) and pos.dtype == np.float32
    assert not pos[:5].any() and not n_world[:5].any()
    p = pos[5:].astype(np.float64) * 100.0
    view = cam.look_at(camera["position"], camera["target"], camera["up"])
    clip = np.concatenate([p, np.ones(p.shape[:-1] + (1,))], -1) @ (cam.perspective(41.0, sw / sh, 0.1, 50.0) @ view).T
    ndc = clip[..., :2] / clip[..., 3:]
    col = (ndc[..., 0] + 1) / 2 * sw - 0.5 - crop_xy[0]
    row = (1 - ndc[..., 1]) / 2 * sh - 0.5 - crop_xy[1]
    rows, cols = np.mgrid[5:size, 0:size]
    np.testing.assert_allclose(col, cols, atol=2e-3)
    np.testing.assert_allclose(row, rows, atol=2e-3)
    np.testing.assert_allclose(clip[..., 3], depth[5:], rtol=1e-5)  # clip w is the view depth -z
    np.testing.assert_allclose(n_world[5:] @ view[:3, :3].T, n_view[5:], atol=1e-6)


def test_world_buffers_clip_positions_outside_the_box():
    camera = {"position": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0], "fov": 60.0}
    depth = np.full((4, 4), 50.0, np.float32)
    normal = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (4, 4, 1))
    pos, _ = world_buffers(depth, normal, camera, (4, 4), (0, 0), np.zeros(3), 1.0)
    assert pos.min() >= -1.0 and pos.max() <= 1.0 and (np.abs(pos) == 1.0).any()


@pytest.mark.parametrize("x0,pad", [(0, (0, 0)), (37, (0, 0)), (50, (14, 0)), (100, (3, 7))])
def test_camera_params_give_the_renders_rays_on_crops_and_the_edge_rays_on_padding(x0, pad):
    """The rays the parameters describe are `pixel_rays_view` of the whole render at the crop's pixels, and on
    the padding the nearest frame pixel's ray (as padding replicates edge pixels)."""
    sw, sh, w, h = 228, 128, 100, 128
    pos, tgt, up, fov = (0.3, 1.2, 3.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 41.0
    p = cam.camera_params(pos, tgt, up, fov, w, h, x0=x0, source=(sw, sh), pad=pad)
    assert p.shape == (cam.CAMERA_PARAMS,) and p.dtype == np.float32
    px, py = pad
    cols, rows = np.arange(w + 2 * px), np.arange(h + 2 * py)
    c = np.clip(cols, p[16], p[17]) + 0.5
    r = np.clip(rows, p[18], p[19]) + 0.5
    rx, ry = p[12] * c + p[13], p[14] * r + p[15]
    want = cam.pixel_rays_view(sw, sh, fov)
    src_c = np.clip(cols - px, 0, w - 1) + x0
    src_r = np.clip(rows - py, 0, h - 1)
    np.testing.assert_allclose(rx, want[0, src_c, 0], atol=1e-5)
    np.testing.assert_allclose(ry, want[src_r, 0, 1], atol=1e-5)
    m = cam.view_to_world(cam.look_at(pos, tgt, up))
    np.testing.assert_allclose(p[:9].reshape(3, 3), m[:3, :3], atol=1e-6)
    np.testing.assert_allclose(p[9:12], m[:3, 3], atol=1e-6)
