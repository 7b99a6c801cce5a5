"""The shipped Sponza scene (glTF import, textures, alpha masks) and alpha cut-out in every renderer."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.gl.renderer import Renderer, RenderSettings
from diviewer.paths import assets_dir
from diviewer.scene import DirectionalLight, FrameConfig, Material, Mesh, Object, Scene, load_scene
from diviewer.scene.gltf import load_texture
from diviewer.scene.loader import parse_scene

MASKED = {"PotPlant1", "Chain", "Plants"}


@pytest.fixture(scope="module")
def sponza():
    return load_scene("sponza")


def test_shipped_sponza_loads(sponza):
    objs = sponza.default.objects
    assert len(objs) == 170 and len(sponza.meshes) == 44 and len(sponza.materials) == 24
    assert sum(len(sponza.meshes[o.mesh].faces) for o in objs) == 262087  # as placed (116k unique)
    assert all(m.texture is not None and m.texture.dtype == np.float32 for m in sponza.materials.values())
    assert {k for k, m in sponza.materials.items() if m.is_masked} == MASKED
    # the file's doubleSided: the three cut-out sheets; the rest have an inside the camera never sees
    assert {k for k, m in sponza.materials.items() if m.double_sided} == MASKED
    for k in MASKED:
        m = sponza.materials[k]
        assert m.alpha.shape == m.texture.shape[:2] and m.alpha_cutoff == 0.5
        assert 0.2 < float((m.alpha < 0.5).mean()) < 0.9  # a real cut-out mask, not all in or out
    lo, hi = sponza.bounds()
    assert np.allclose(hi - lo, (51.0, 21.3, 31.4), atol=0.5)
    assert sponza.ranges.camera is not None and len(sponza.ranges.camera.test_stretches) == 3
    assert sponza.ranges.lights["sun"].angle[0] < sponza.ranges.lights["sun"].angle[1]


@pytest.fixture
def sponza_copy(tmp_path):
    dst = tmp_path / "sponza"
    shutil.copytree(assets_dir() / "sponza", dst)
    scene = tmp_path / "s.toml"
    text = (assets_dir() / "scenes" / "sponza.toml").read_text().replace('"../sponza/Sponza.gltf"', '"sponza/Sponza.gltf"')
    scene.write_text(text)
    return scene, dst


def test_missing_texture_is_named(sponza_copy):
    scene, dst = sponza_copy
    (dst / "textures" / "vase_plant.png").unlink()
    with pytest.raises(DiviewerError, match=r"texture file not found: .*vase_plant\.png.*"):
        load_scene(scene)


def test_corrupt_texture_is_named(sponza_copy):
    scene, dst = sponza_copy
    (dst / "textures" / "lion.jpg").write_bytes(b"\xff\xd8\xff not a jpeg at all")
    with pytest.raises(DiviewerError, match=r"lion\.jpg") as info:
        load_scene(scene)
    assert "baseColorTexture" in str(info.value) and "Sponza.gltf" in str(info.value)


def test_toml_alpha_cutoff_needs_an_alpha_channel(tmp_path):
    from PIL import Image

    Image.new("RGB", (2, 2), (255, 0, 0)).save(tmp_path / "rgb.png")
    data = {"materials": {"m": {"texture": "rgb.png", "alpha_cutoff": 0.5}},
            "meshes": {"b": {"shape": "box"}}, "objects": [{"mesh": "b", "material": "m"}]}
    with pytest.raises(DiviewerError, match=r"materials\.m\.alpha_cutoff.*alpha channel"):
        parse_scene(data, path=tmp_path / "s.toml")


# --- alpha cut-out: a checker-masked quad in front of a wall ---------------------------------------------------

QUAD_Z, WALL_Z, FOV = -2.0, -4.0, 40.0
RED, GREEN = (1.0, 0.0, 0.0), (0.2, 0.6, 0.2)


def checker_scene(tmp_path) -> Scene:
    """Camera at the origin looking down -z; a wall; before it a red quad whose alpha is a 4x4 checker."""
    from PIL import Image

    rgba = np.zeros((4, 4, 4), np.uint8)
    rgba[..., 0] = 255
    rgba[..., 3] = np.where((np.add.outer(np.arange(4), np.arange(4)) % 2) == 0, 255, 0)  # top-left kept
    Image.fromarray(rgba, "RGBA").save(tmp_path / "checker.png")
    tex, alpha = load_texture(tmp_path / "checker.png")
    h = np.tan(np.radians(FOV) / 2) * -QUAD_Z / 2  # half the view's half-height: the middle 16 pixels
    v = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], np.float32)
    quad = Mesh("quad", v, np.tile(np.float32([0, 0, 1]), (4, 1)), np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
                uvs=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32))
    s = 4.0 * np.tan(np.radians(FOV) / 2) * -WALL_Z
    wall = Mesh("wall", v / h * s, quad.normals, quad.faces, uvs=None)
    materials = {"cut": Material("cut", albedo=(1.0, 1.0, 1.0), texture=tex, alpha=alpha, alpha_cutoff=0.5),
                 "wall": Material("wall", albedo=GREEN)}
    config = FrameConfig(camera=cam_default(), lights=(DirectionalLight("sun", direction=(0.0, 0.0, -1.0), irradiance=2.0),),
                         objects=(Object("quad", "quad", "cut", position=(0, 0, QUAD_Z)),
                                  Object("wall", "wall", "wall", position=(0, 0, WALL_Z))))
    return Scene("checker", None, "", {"quad": quad, "wall": wall}, materials, config)


def cam_default():
    from diviewer.scene.model import Camera

    return Camera(position=(0, 0, 0), target=(0, 0, -1), up=(0, 1, 0), fov=FOV, near=0.1, far=20.0)


def texel_centres(n: int):
    """The 2 x 2 pixels at the middle of each texel as (rows, cols) per texel, and whether it is kept."""
    rows, cols = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
    kept = (rows + cols) % 2 == 0
    q = n // 4  # the quad spans pixels n/4 .. 3n/4; a texel is n/8 pixels
    mid = lambda k: q + k * (n // 8) + n // 16 - 1  # noqa: E731
    ys = np.stack([mid(rows), mid(rows), mid(rows) + 1, mid(rows) + 1], -1)
    xs = np.stack([mid(cols), mid(cols) + 1, mid(cols), mid(cols) + 1], -1)
    return (ys, xs), kept


SLANT = (0.5, 0.0, -1.0)
"""A light that moves +1 in x from the quad to the wall: the checker's shadow falls on visible wall."""


def slanted(scene: Scene) -> FrameConfig:
    return scene.default.replace_light("sun", direction=tuple(np.divide(SLANT, np.linalg.norm(SLANT))))


def expected_shadow(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Wall pixels (outside the quad's image) that the slanted light reaches (lit) or not (dark), judged
    at the pixel centre and only where the shadow ray crosses the quad plane away from texel edges."""
    t = np.tan(np.radians(FOV) / 2)
    c = (np.arange(n) + 0.5) / n * 2 - 1
    x, y = np.meshgrid(c * t * -WALL_Z, -c * t * -WALL_Z)          # wall point of each pixel centre
    qx, qy = x - SLANT[0] * (QUAD_Z - WALL_Z) / -SLANT[2], y          # where its shadow ray meets the quad plane
    h = t * -QUAD_Z / 2
    u, v = (qx + h) / (2 * h) * 4, (h - qy) / (2 * h) * 4              # texel coordinates, rows from the top
    on_quad = (u > 0) & (u < 4) & (v > 0) & (v < 4)
    safe = (np.abs(u - np.round(u)) > 0.3) & (np.abs(v - np.round(v)) > 0.3)
    kept = on_quad & ((np.floor(u) + np.floor(v)) % 2 == 0)
    seen = np.maximum(np.abs(x), np.abs(y)) > 2 * h * 1.05            # not behind the quad in the image
    return seen & safe & ~kept, seen & safe & kept


def check_cutout(albedo, depth, n):
    """Texel centres show the quad where the alpha keeps it and the wall through the holes."""
    (ys, xs), kept = texel_centres(n)
    for i in range(4):
        for j in range(4):
            y, x = ys[i, j], xs[i, j]
            want, d = (RED, -QUAD_Z) if kept[i, j] else (GREEN, -WALL_Z)
            np.testing.assert_allclose(albedo[y, x], np.broadcast_to(want, (len(y), 3)), atol=2e-3, err_msg=f"texel {i},{j}")
            np.testing.assert_allclose(depth[y, x], d, rtol=2e-3, err_msg=f"texel {i},{j}")


def check_shadow(direct, n):
    lit, dark = expected_shadow(n)
    assert lit.sum() > 20 and dark.sum() > 20
    full = np.float32(GREEN) / np.pi * 2.0 * -SLANT[2] / np.linalg.norm(SLANT)
    np.testing.assert_allclose(direct[lit], np.broadcast_to(full, (lit.sum(), 3)), rtol=2e-3)
    assert np.abs(direct[dark]).max() < 1e-3 * full.max()


def test_alpha_cutout_gbuffer_and_shadow_map(ctx, tmp_path):
    scene = checker_scene(tmp_path)
    r = Renderer(ctx, scene, 64, 64, RenderSettings(shadow_size=1024, pcf_radius=0))
    try:
        g = r.frame()
        check_cutout(g["albedo"], g["depth"], 64)
        # The checker's shadow on the wall: light through the cut-out texels, none through the kept ones.
        check_shadow(r.frame(slanted(scene))["direct"], 64)
    finally:
        r.release()


@pytest.mark.mitsuba
@pytest.mark.slow
def test_alpha_cutout_mitsuba(tmp_path):
    pytest.importorskip("mitsuba")
    from diviewer.reference import mitsuba as ref

    ref.select_variant()
    scene = checker_scene(tmp_path)
    a = ref.MitsubaFrame(scene, scene.default, 64, 64).aovs(16, 0)
    check_cutout(a["albedo"], a["depth"], 64)
    check_shadow(ref.MitsubaFrame(scene, slanted(scene), 64, 64).direct(16, 0), 64)


@pytest.mark.mitsuba
def test_alpha_cutout_mitsuba_scalar(tmp_path):
    """The see-through AOVs also run one ray at a time under scalar_rgb (the variant without a libLLVM)."""
    pytest.importorskip("mitsuba")
    from diviewer.reference import mitsuba as ref

    scene = checker_scene(tmp_path)
    ref.select_variant("scalar_rgb")
    try:
        a = ref.MitsubaFrame(scene, scene.default, 16, 16).aovs(4, 0)
    finally:
        ref.select_variant()
    check_cutout(a["albedo"], a["depth"], 16)


# --- Sponza: the Mitsuba cross-checks of tests/reference/test_mitsuba.py, at tiny size ------------------------

@pytest.mark.mitsuba
@pytest.mark.slow
def test_sponza_mitsuba_matches_gl(ctx, sponza):
    """On a Sponza frame (48x32, 16 spp): Mitsuba's depth and normals match the G-buffer, its albedo the
    textured G-buffer albedo, and its direct light the GL direct pass, lit and shadowed.

    Textures make the per-pixel albedo differ legitimately: GL takes one trilinear (mipmapped) sample at
    the pixel centre, Mitsuba averages bilinear samples over the pixel. Measured here: albedo per-pixel
    median difference 0.016 and means within 0.2 %; direct light on fully lit pixels per-pixel median
    2.5 % and means within 0.01 %; shadowed pixels exactly 0 in both.
    """
    pytest.importorskip("mitsuba")
    import dataclasses

    from diviewer.reference import mitsuba as ref
    from reference.test_mitsuba import agreement, grow

    ref.select_variant()
    camera = dataclasses.replace(sponza.default.camera, position=(-3.0, 9.0, 0.5), target=(3.0, 4.0, -0.5))
    config = dataclasses.replace(sponza.default, camera=camera)  # the courtyard floor in the noon sun
    w, h = 48, 32
    r = Renderer(ctx, sponza, w, h)
    g = r.frame(config)
    r.settings = RenderSettings(shadows=False)
    unshadowed = r.frame(config)["direct"].mean(-1)
    r.release()
    # pixels away from silhouettes and creases (geometry only: textures change albedo everywhere)
    d, n = g["depth"], g["normal"]
    e = d <= 0
    e[0, :] = e[-1, :] = e[:, 0] = e[:, -1] = True
    for lo, hi in (((slice(0, -1), slice(None)), (slice(1, None), slice(None))),
                   ((slice(None), slice(0, -1)), (slice(None), slice(1, None)))):
        jump = (np.abs(n[lo] - n[hi]).max(-1) > 1e-3) | (np.abs(d[lo] - d[hi]) > 0.1 * np.minimum(d[lo], d[hi]))
        e[lo] |= jump
        e[hi] |= jump
    flat = ~grow(e, 1)
    assert flat.sum() > 300
    a = ref.render_aovs(sponza, config, w, h, spp=16, seed=0)
    agree = agreement(a, g, flat)
    assert agree["depth"] >= 0.99 and agree["normal"] >= 0.99, agree
    diff = np.abs(a["albedo"] - g["albedo"]).max(-1)[flat]
    assert np.median(diff) < 0.03
    assert abs(a["albedo"][flat].mean() / g["albedo"][flat].mean() - 1) < 0.01

    vis = np.where(unshadowed > 0, g["direct"].mean(-1) / np.maximum(unshadowed, 1e-12), 0.0)
    lit, dark = vis > 0.999, vis < 0.001
    lit &= ~grow(~lit) & flat
    dark &= ~grow(~dark) & flat
    assert lit.sum() > 100 and dark.sum() > 30
    m = ref.render_direct(sponza, config, w, h, spp=16, seed=0)
    rel = np.abs(m - g["direct"]).max(-1) / np.maximum(g["direct"].max(-1), 1e-6)
    assert np.median(rel[lit]) < 0.05 and abs(m[lit].mean() / g["direct"][lit].mean() - 1) < 0.01
    assert np.mean(m[dark].max(-1) < 1e-3 * m.max()) >= 0.99


# --- the G-buffer and the path tracer cut the same holes (issue 29 item 6) ----------------------------------
def fine_mask_scene(tmp_path, texels: int) -> Scene:
    """checker_scene's geometry with a white quad cut by a ``texels`` x ``texels`` one-texel checker, before a
    black wall: a pixel's albedo is the quad's coverage of it."""
    from PIL import Image

    rgba = np.full((texels, texels, 4), 255, np.uint8)
    rgba[..., 3] = np.where((np.add.outer(np.arange(texels), np.arange(texels)) % 2) == 0, 255, 0)
    Image.fromarray(rgba, "RGBA").save(tmp_path / f"fine{texels}.png")
    tex, alpha = load_texture(tmp_path / f"fine{texels}.png")
    base = checker_scene(tmp_path)
    materials = {"cut": Material("cut", albedo=(1.0, 1.0, 1.0), texture=tex, alpha=alpha, alpha_cutoff=0.5),
                 "wall": Material("wall", albedo=(0.0, 0.0, 0.0))}
    return Scene("fine", None, "", base.meshes, materials, base.default)


@pytest.mark.slow
@pytest.mark.parametrize("texels", [16, 100])  # 2 pixels a texel (magnified), 3.125 texels a pixel (minified)
def test_gbuffer_and_path_tracer_agree_on_a_fine_checker_mask(ctx, tmp_path, texels):
    """At every pixel centre the G-buffer and Mitsuba's rays stop at the same surface (the same nearest-texel
    test), and the coverage they give the quad agrees: per pixel where texels are larger than pixels, over
    the quad where they are smaller (one sample at the centre against the pixel's area)."""
    pytest.importorskip("mitsuba")
    from diviewer.reference import mitsuba as ref
    from oracles import centre_depth
    ref.select_variant()
    scene, n = fine_mask_scene(tmp_path, texels), 64
    r = Renderer(ctx, scene, n, n, RenderSettings(shadows=False))
    try:
        g = r.frame()
    finally:
        r.release()
    quad = np.zeros((n, n), bool)
    quad[n // 4: 3 * n // 4, n // 4: 3 * n // 4] = True
    gl_cover = np.isclose(g["depth"], -QUAD_Z, rtol=1e-3)
    assert not gl_cover[~quad].any()
    assert 0.4 < gl_cover[quad].mean() < 0.6, "the G-buffer cuts about half the quad away"
    centre = centre_depth(scene, scene.default, n, n)
    assert np.array_equal(np.isclose(centre, -QUAD_Z, rtol=1e-3), gl_cover), "the same surface at every pixel centre"
    assert np.isclose(centre[quad & ~gl_cover], -WALL_Z, rtol=1e-3).all(), "through the holes both see the wall"
    mi_cover = ref.MitsubaFrame(scene, scene.default, n, n).aovs(16, 0)["albedo"].mean(-1)  # the quad's share
    if texels <= n // 2:
        assert np.abs(mi_cover - gl_cover)[quad].max() < 0.02
    else:
        assert abs(mi_cover[quad].mean() - 0.5) < 0.02, "the pixel areas see half the texels"
        assert abs(gl_cover[quad].mean() - mi_cover[quad].mean()) < 0.06
