"""Analytic checks of the G-buffer, shadow and direct passes on a headless EGL context."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from diviewer.gl.display import DisplayPass
from diviewer.gl.renderer import Renderer, RenderSettings
from diviewer.scene import camera as cam
from diviewer.scene.model import Mesh
from scenes import emissive_tile, facing_plane

RES = 48


def render(ctx, scene, settings=RenderSettings(), config=None, size=(RES, RES)):
    r = Renderer(ctx, scene, *size, settings)
    try:
        return r.frame(config)
    finally:
        r.release()


def world_points(frame, camera, w, h):
    """World-space positions of each pixel from linear depth (the inverse of the G-buffer pass)."""
    rays = cam.pixel_rays_view(w, h, camera.fov)
    p_view = rays * frame["depth"][..., None]
    m = cam.view_to_world(camera.view_matrix())
    return p_view @ m[:3, :3].T + m[:3, 3]


@pytest.mark.parametrize("distance", [0.5, 3.0, 40.0])
def test_plane_depth_normal_albedo(ctx, distance):
    scene = facing_plane(distance=distance)
    f = render(ctx, scene)
    np.testing.assert_allclose(f["depth"], distance, rtol=1e-5)
    np.testing.assert_allclose(f["normal"], np.broadcast_to([0, 0, 1], f["normal"].shape), atol=1e-5)
    np.testing.assert_allclose(f["albedo"], np.broadcast_to([0.5, 0.25, 0.75], f["albedo"].shape), atol=1e-6)


def test_tilted_plane_depth_matches_ray_geometry(ctx):
    """A plane tilted 30 degrees about y: depth per pixel equals the ray/plane intersection."""
    scene = facing_plane(distance=3.0)
    obj = dataclasses.replace(scene.default.objects[0], position=(0, 0, -3.0), rotation=(0, 30, 0))
    cfg = dataclasses.replace(scene.default, objects=(obj,))
    f = render(ctx, scene, config=cfg)
    # front face of the box: plane through (0,0,-3 + 0.25 along its normal) with normal R @ (0,0,1)
    n = cam.euler_xyz((0, 30, 0)) @ np.array([0, 0, 1.0])
    p0 = np.array([0, 0, -3.0]) + 0.25 * n
    rays = cam.pixel_rays_view(RES, RES, 40.0)  # unit -z: depth = t
    t = (p0 @ n) / (rays @ n)
    np.testing.assert_allclose(f["depth"], t, rtol=1e-4)
    np.testing.assert_allclose(f["normal"], np.broadcast_to(n, f["normal"].shape), atol=1e-4)


def test_background_is_zero(ctx):
    scene = facing_plane(distance=3.0)
    cfg = scene.default
    cfg = dataclasses.replace(cfg, camera=dataclasses.replace(cfg.camera, target=(0, 0, 1)))  # look away
    f = render(ctx, scene, config=cfg)
    for name in ("depth", "normal", "albedo", "direct"):
        assert np.all(f[name] == 0.0), name


@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0, 85.0])
def test_lambert_cosine_law_directional(ctx, theta):
    """Radiance = albedo / pi * E * cos(theta), with shadows on (no acne on a lit plane)."""
    E = 2.5
    d = (-math.sin(math.radians(theta)), 0.0, -math.cos(math.radians(theta)))  # travels into the plane
    scene = facing_plane(lights=[{"name": "sun", "type": "directional", "direction": list(d), "irradiance": E}])
    f = render(ctx, scene)
    expected = np.array([0.5, 0.25, 0.75]) / math.pi * E * math.cos(math.radians(theta))
    np.testing.assert_allclose(f["direct"], np.broadcast_to(expected, f["direct"].shape), rtol=1e-4, atol=1e-7)


def test_point_light_inverse_square(ctx):
    I = 7.0
    scene = facing_plane(distance=2.0, lights=[{"name": "bulb", "type": "point", "position": [0.3, -0.2, -0.5],
                                                "intensity": I, "color": [1, 0.5, 0.25]}])
    f = render(ctx, scene)
    p = world_points(f, scene.default.camera, RES, RES)
    to_l = np.array([0.3, -0.2, -0.5]) - p
    r2 = (to_l ** 2).sum(-1)
    cos_t = to_l[..., 2] / np.sqrt(r2)  # plane normal is +z
    expected = np.array([0.5, 0.25, 0.75]) * np.array([1, 0.5, 0.25]) / math.pi * I * (cos_t / r2)[..., None]
    np.testing.assert_allclose(f["direct"], expected, rtol=2e-3)


BLOCKER = (np.array([-0.3, -0.3, -1.8]), np.array([0.3, 0.3, -1.2]))  # a 0.6 m box at z = -1.5


def _occluded_scene(light):
    return facing_plane(
        distance=3.0, fov=70.0, lights=[light],
        extra_meshes={"blocker": {"shape": "box", "size": [0.6, 0.6, 0.6]}},
        extra_objects=[{"name": "blocker", "mesh": "blocker", "material": "occ", "position": [0, 0, -1.5]}])


def _segment_hits_box(p, q, lo, hi):
    """Whether the segments p -> q (arrays of points) pass through the box [lo, hi] (slab test)."""
    d = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - p) / d, (hi - p) / d
    tmin = np.nanmax(np.where(d != 0, np.minimum(t1, t2), -np.inf), axis=-1)
    tmax = np.nanmin(np.where(d != 0, np.maximum(t1, t2), np.inf), axis=-1)
    inside_parallel = np.all((d != 0) | ((p >= lo) & (p <= hi)), axis=-1)
    return inside_parallel & (tmax >= np.maximum(tmin, 0.0)) & (tmin <= 1.0)


@pytest.mark.parametrize("light", [
    {"name": "sun", "type": "directional", "direction": [0.7071, 0.0, -0.7071], "irradiance": 3.0},
    {"name": "bulb", "type": "point", "position": [1.2, 0.3, -0.5], "intensity": 5.0},
])
def test_shadow_behind_occluder(ctx, light):
    """Shadowed pixels are exactly those whose path to the light crosses the box (edges aside)."""
    scene = _occluded_scene(light)
    w = 96
    f = render(ctx, scene, size=(w, w))
    p = world_points(f, scene.default.camera, w, w)
    on_wall = np.abs(p[..., 2] + 3.0) < 1e-3
    if light["type"] == "directional":
        to_light = lambda x: x - 100.0 * np.asarray(light["direction"])
    else:
        to_light = lambda x: np.broadcast_to(np.asarray(light["position"], float), x.shape)
    margin = 0.06  # PCF (3x3 texels) and biases blur the edge by a few centimetres here
    hits = [_segment_hits_box(p + np.array([dx, dy, 0.0]), to_light(p + np.array([dx, dy, 0.0])), *BLOCKER)
            for dx in (-margin, 0, margin) for dy in (-margin, 0, margin)]
    behind = on_wall & np.all(hits, axis=0)
    open_ = on_wall & ~np.any(hits, axis=0)
    assert behind.sum() > 50 and open_.sum() > 50
    lum = f["direct"].sum(-1)
    assert np.all(lum[behind] == 0.0), "a point behind the occluder is lit"
    assert np.all(lum[open_] > 0.0), "a point in the open is in shadow"
    # without shadows the same points are lit
    f2 = render(ctx, scene, RenderSettings(shadows=False), size=(w, w))
    assert np.all(f2["direct"].sum(-1)[behind] > 0.0)


@pytest.mark.parametrize("light", [
    {"name": "sun", "type": "directional", "direction": [0.2, -0.3, -1.0], "irradiance": 0.0},
    {"name": "bulb", "type": "point", "position": [0.0, 0.0, -1.0], "intensity": 0.0},
])
def test_zero_intensity_gives_black(ctx, light):
    f = render(ctx, facing_plane(lights=[light]))
    assert np.all(f["direct"] == 0.0)


def test_emission_is_added_to_direct(ctx):
    scene = facing_plane()
    mat = dataclasses.replace(scene.materials["m"], emission=(1.5, 0.0, 3.0))
    scene = dataclasses.replace(scene, materials={**scene.materials, "m": mat})
    f = render(ctx, scene)
    np.testing.assert_allclose(f["direct"], np.broadcast_to([1.5, 0.0, 3.0], f["direct"].shape), rtol=1e-6)


def test_an_emission_texture_shows_its_pattern_in_the_emission_and_direct_buffers(ctx):
    """The G-buffer writes the material's emission times its emission texture at the pixel's uv: a tile whose
    texture is 1 on its left half and 0.25 on its right glows with the factor there and a quarter of it here."""
    scene = emissive_tile(emission=(2.0, 1.0, 0.5))
    plain = dataclasses.replace(scene.materials["glow"], emission_texture=None)
    r = Renderer(ctx, scene, 64, 64)
    try:
        f = r.frame()
        emission = r.read("emission")
        r.scene = dataclasses.replace(scene, materials={**scene.materials, "glow": plain})
        r.gpu.sync(ctx, r.scene)  # as the viewer does on a material's change: the texture goes
        assert "glow" not in r.gpu.emission_textures
        r.frame()
        uniform = r.read("emission")
    finally:
        r.release()
    tile = (f["albedo"].max(-1) == 0.0) & (f["depth"] > 0)
    cols = np.nonzero(tile.any(axis=0))[0]
    # a third each side, clear of the seam and of the edges (where the repeating texture wraps around)
    left, right, rows = cols[2:len(cols) // 3], cols[-(len(cols) // 3):-2], np.nonzero(tile.any(axis=1))[0][2:-2]
    for side, want in ((left, [2.0, 1.0, 0.5]), (right, [0.5, 0.25, 0.125])):
        patch = emission[rows][:, side]
        np.testing.assert_allclose(patch, np.broadcast_to(want, patch.shape), rtol=1e-3)
        np.testing.assert_allclose(f["direct"][rows][:, side], patch, rtol=1e-6)
    np.testing.assert_allclose(uniform[tile], np.broadcast_to([2.0, 1.0, 0.5], (tile.sum(), 3)))


def test_lights_and_emission_add_up(ctx):
    # The first light writes over the cleared target, later ones and emission add to it: the sum of
    # the parts, frame after frame (no term left over from the previous frame); a scene that emits
    # nothing skips the emission pass.
    sun = {"name": "sun", "type": "directional", "direction": [0.3, -0.2, -1.0], "irradiance": 1.0}
    bulb = {"name": "bulb", "type": "point", "position": [0.2, 0.1, -1.0], "intensity": 0.5}
    parts = [render(ctx, facing_plane(lights=[light]))["direct"] for light in (sun, bulb)]
    scene = facing_plane(lights=[sun, bulb])
    mat = dataclasses.replace(scene.materials["m"], emission=(0.25, 0.5, 0.0))
    glowing = dataclasses.replace(scene, materials={**scene.materials, "m": mat})
    dark = Renderer(ctx, scene, 4, 4)
    assert not dark.emissive
    dark.release()
    r = Renderer(ctx, glowing, RES, RES)
    try:
        assert r.emissive
        for _ in range(2):
            f = r.frame()
            np.testing.assert_allclose(f["direct"], parts[0] + parts[1] + [0.25, 0.5, 0.0], rtol=1e-5, atol=1e-6)
    finally:
        r.release()


def test_emission_target_holds_zeros_when_nothing_emits(ctx):
    # The G-buffer pass leaves the emission target out when no material emits; the target then
    # reads zero, also right after a scene that did emit (the viewer swaps scenes in place).
    glowing_scene = facing_plane()
    mat = dataclasses.replace(glowing_scene.materials["m"], emission=(1.0, 2.0, 3.0))
    glowing_scene = dataclasses.replace(glowing_scene, materials={**glowing_scene.materials, "m": mat})
    r = Renderer(ctx, glowing_scene, RES, RES)
    try:
        r.frame()
        assert r.read("emission").max() == 3.0
        r.scene = facing_plane()
        r.frame()
        assert r.read("emission").max() == 0.0 and r.read("albedo").max() > 0.0
        r.scene = glowing_scene
        r.frame()
        assert r.read("emission").max() == 3.0
    finally:
        r.release()


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_direct_is_linear_in_light_intensity(ctx, scale):
    """Over twelve orders of magnitude the direct buffer scales exactly with the light."""
    base = {"name": "sun", "type": "directional", "direction": [0.3, -0.2, -1.0], "irradiance": 1.0}
    f1 = render(ctx, facing_plane(lights=[base]))
    f2 = render(ctx, facing_plane(lights=[{**base, "irradiance": scale}]))
    np.testing.assert_allclose(f2["direct"], f1["direct"] * scale, rtol=1e-5)


@pytest.mark.parametrize("near,far", [(1e-4, 10.0), (1e-1, 1e4), (2.9, 3.1)])  # far/near up to MAX_FAR_NEAR
def test_extreme_near_far_planes(ctx, near, far):
    f = render(ctx, facing_plane(distance=3.0, near=near, far=far))
    np.testing.assert_allclose(f["depth"], 3.0, rtol=1e-4)


def test_non_square_and_resize(ctx):
    scene = facing_plane(distance=2.0)
    r = Renderer(ctx, scene, 40, 24)
    try:
        f = r.frame()
        assert f["depth"].shape == (24, 40) and f["normal"].shape == (24, 40, 3)
        r.resize(16, 32)
        f = r.frame()
        assert f["direct"].shape == (32, 16, 3)
        np.testing.assert_allclose(f["depth"], 2.0, rtol=1e-5)
    finally:
        r.release()


def test_image_rows_run_top_to_bottom(ctx):
    """A box above the camera's axis appears in the top rows of the returned image."""
    scene = facing_plane(distance=3.0, extra_meshes={"b": {"shape": "box", "size": [0.5, 0.5, 0.5]}},
                         extra_objects=[{"name": "b", "mesh": "b", "material": "occ", "position": [0.6, 0.6, -2.0]}])
    f = render(ctx, scene)
    near = f["depth"] < 2.9
    rows, cols = np.nonzero(near)
    assert rows.mean() < RES / 2, "an object above the axis must be in the top half"
    assert cols.mean() > RES / 2, "an object right of the axis must be in the right half"


def test_composite_tonemaps_and_flags_non_finite(ctx):
    r = Renderer(ctx, facing_plane(), 8, 8)
    comp = DisplayPass(ctx, r.shaders)
    try:
        img = np.zeros((8, 8, 3), np.float32)
        img[0, 0] = [np.nan, 0, 0]
        img[1, 1] = [np.inf, np.inf, np.inf]
        img[2, 2] = [1e30, 1e30, 1e30]
        img[3, 3] = [0.18, 0.18, 0.18]
        out = comp.to_ldr(img)
        assert out.dtype == np.uint8 and out.shape == (8, 8, 3)
        assert tuple(out[0, 0]) == (255, 0, 255) and tuple(out[1, 1]) == (255, 0, 255)
        assert tuple(out[2, 2]) == (255, 255, 255)
        assert tuple(out[4, 4]) == (0, 0, 0)
        assert 0 < out[3, 3, 0] < 255
        brighter = comp.to_ldr(img, exposure=1.0)
        assert brighter[3, 3, 0] > out[3, 3, 0]
    finally:
        comp.release()
        r.release()


def test_display_srgb_matches_scene_colour(ctx):
    """The display's sRGB curve (shaders/tonemap.glsl) and diviewer.scene.colour are the same curve."""
    from diviewer.scene.colour import srgb8

    r = Renderer(ctx, facing_plane(), 16, 16)
    comp = DisplayPass(ctx, r.shaders)
    try:
        ramp = np.linspace(0.0, 1.0, 16 * 16 * 3, dtype=np.float32).reshape(16, 16, 3) ** 2  # dense in the dark end
        out = comp.to_ldr(ramp, exposure=0.0, tonemap="clamp")
        # The GPU rounds float to unorm8 itself: allow one step.
        assert np.abs(out.astype(int) - srgb8(ramp).astype(int)).max() <= 1
    finally:
        comp.release()
        r.release()


@pytest.mark.parametrize("name", ["cornell", "atrium"])
def test_shipped_scenes_render_finite_and_lit(ctx, name):
    from diviewer.scene import load_scene, sample_config

    scene = load_scene(name)
    for config in (scene.default, sample_config(scene, 7, "train"), sample_config(scene, 7, "test")):
        f = render(ctx, scene, config=config, size=(64, 64))
        for k, v in f.items():
            assert np.all(np.isfinite(v)), k
        assert (f["depth"] > 0).mean() > 0.5
        assert f["direct"].max() > 0.0
        n = np.linalg.norm(f["normal"], axis=-1)
        np.testing.assert_allclose(n[f["depth"] > 0], 1.0, atol=1e-3)


def test_mirrored_object_faces_outwards(ctx):
    """A negative scale flips the triangle winding; the G-buffer must still see the outside."""
    scene = facing_plane(distance=3.0, extra_meshes={"b": {"shape": "box", "size": [0.8, 0.8, 0.8]}},
                         extra_objects=[{"name": "b", "mesh": "b", "material": "occ", "position": [0, 0, -1.5],
                                         "scale": [-1, 1, 1]}],
                         lights=[{"name": "sun", "type": "directional", "direction": [0, 0, -1], "irradiance": 1.0}])
    f = render(ctx, scene)
    box = np.abs(f["depth"] - 1.1) < 1e-3  # its front face, 1.5 - 0.4 in front of the camera
    assert box.sum() > 20
    np.testing.assert_allclose(f["normal"][box], np.broadcast_to([0, 0, 1], f["normal"][box].shape), atol=1e-5)
    np.testing.assert_allclose(f["direct"][box], 0.5 / np.pi, rtol=1e-4)


@pytest.mark.parametrize("how", ["sync", "queries"])
def test_passes_are_timed_by_the_shared_timer(ctx, how):
    """Each named pass is one stage of the program's timer: by the wall clock around a GPU sync, or by GL
    timer queries; the frame is the same either way."""
    from diviewer.gl.context import stage_timer

    timer = stage_timer(ctx, sync=how == "sync", queries=how == "queries")
    r = Renderer(ctx, facing_plane(), 16, 16, RenderSettings(shadow_size=64), timer=timer)
    plain = Renderer(ctx, facing_plane(), 16, 16, RenderSettings(shadow_size=64))
    try:
        assert [name for name, _ in r.passes] == ["shadows", "gbuffer", "direct"]
        f = r.frame()
        assert set(timer.times) == {"shadows", "gbuffer", "direct", "readback"}
        assert all(ms >= 0.0 for ms in timer.times.values())
        assert plain.timer.times == {}  # no sync, no queries: GL stages are not timed
        for k, v in plain.frame().items():
            np.testing.assert_array_equal(v, f[k])
    finally:
        plain.release()
        r.release()
        timer.release()


def test_shadow_map_is_cached_until_the_light_or_an_object_moves(ctx):
    """The shadow pass renders a light's map only when the light, an object or the settings changed; the cached
    map gives the same image."""
    scene = facing_plane(lights=[{"name": "sun", "type": "directional", "direction": [0.3, -0.4, -1.0]}],
                         extra_objects=[{"name": "box", "mesh": "wall", "material": "occ", "position": [0, 0, -1.5],
                                         "scale": [0.1, 0.1, 0.1]}])
    r = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=256))
    try:
        config = scene.default
        first = r.frame(config)["direct"]
        assert r.shadow_renders == 1
        np.testing.assert_array_equal(r.frame(config)["direct"], first)  # nothing moved: the cached map
        assert r.shadow_renders == 1
        turned = dataclasses.replace(config.camera, fov=config.camera.fov * 0.9)
        r.frame(dataclasses.replace(config, camera=turned))  # the camera alone: still cached
        assert r.shadow_renders == 1
        r.frame(config.replace_light("sun", direction=(0.35, -0.4, -1.0)))
        assert r.shadow_renders == 2
        r.frame(config.replace_object("box", position=(0.2, 0.0, -1.5)))
        assert r.shadow_renders == 3
        r.frame(config.replace_object("box", position=(0.2, 0.0, -1.5)))
        assert r.shadow_renders == 3
    finally:
        r.release()


PCF_PROBE = """
layout(local_size_x = 64) in;
#define SHADOW_LOOKUP 1
#define DIRECTIONAL 1
#include "direct.glsl"
layout(std430, binding = 0) readonly buffer Queries { vec4 queries[]; };   // uv, reference depth, -
layout(std430, binding = 1) writeonly buffer Results { vec2 results[]; };  // pcf(), the taps' mean
void main() {
    uint k = gl_GlobalInvocationID.x;
    vec2 uv = queries[k].xy;
    float ref = queries[k].z;
    vec2 texel = 1.0 / vec2(textureSize(u_shadow_map, 0));
    float sum = 0.0;
    for (int y = -u_pcf_radius; y <= u_pcf_radius; ++y)
        for (int x = -u_pcf_radius; x <= u_pcf_radius; ++x)
            sum += texture(u_shadow_map, vec3(uv + vec2(x, y) * texel, ref));
    results[k] = vec2(pcf(uv, ref), sum / float((2 * u_pcf_radius + 1) * (2 * u_pcf_radius + 1)));
}
"""


@pytest.mark.parametrize("radius", [0, 1, 2])
def test_gathered_pcf_equals_the_mean_of_bilinear_comparison_taps(ctx, radius):
    # direct.glsl's pcf() sums textureGather comparisons with bilinear weights; it must equal the
    # (2r+1)^2 filtered shadow lookups it replaces, anywhere on the map (edges clamp), for random
    # depths, including references equal to a stored depth (the comparison is <=).
    import moderngl

    from diviewer.gl.shaders import ShaderCache

    rng = np.random.default_rng(radius)
    size = 16
    depths = rng.uniform(0.2, 0.8, (size, size)).astype("f4")
    tex = ctx.depth_texture((size, size), data=depths.tobytes())
    tex.compare_func = "<="
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = False
    n = 1024
    q = np.zeros((n, 4), "f4")
    q[:, :2] = rng.uniform(-0.05, 1.05, (n, 2))
    q[:, 2] = rng.uniform(0.15, 0.85, n)
    q[:64, 2] = depths.ravel()[rng.integers(0, size * size, 64)]  # ties
    cache = ShaderCache(ctx)
    prog = cache.compute_source(PCF_PROBE)
    queries, results = ctx.buffer(q.tobytes()), ctx.buffer(reserve=n * 8)
    try:
        tex.use(location=0)
        prog["u_shadow_map"] = 0
        prog["u_pcf_radius"] = radius
        queries.bind_to_storage_buffer(0)
        results.bind_to_storage_buffer(1)
        prog.run(n // 64)
        ctx.memory_barrier()
        got = np.frombuffer(results.read(), "f4").reshape(n, 2)
    finally:
        for obj in (queries, results, prog, tex):
            obj.release()
    assert got[:, 1].min() < 0.1 and got[:, 1].max() > 0.9  # both lit and shadowed queries
    np.testing.assert_allclose(got[:, 0], got[:, 1], atol=2e-5)


# --- culling --------------------------------------------------------------------------------------------

def test_split_mesh_keeps_every_triangle_in_compact_chunks():
    from diviewer.gl.culling import split_mesh

    rng = np.random.default_rng(0)
    v = rng.uniform(-10, 10, (3000, 3)).astype(np.float32)
    f = rng.integers(0, 3000, (5000, 3)).astype(np.uint32)
    base = Mesh("m", v, np.tile([0, 0, 1], (3000, 1)).astype(np.float32), f,
                rng.uniform(0, 1, (3000, 2)).astype(np.float32))
    chunks = split_mesh(base, 700)
    assert len(chunks) >= 8 and all(len(c.faces) <= 700 for c in chunks)
    assert sum(len(c.faces) for c in chunks) == len(f)
    # The same triangles (positions, normals and uvs of each corner), each in exactly one chunk.
    corners = lambda m: np.concatenate([m.vertices, m.normals, m.uvs], axis=1)[m.faces].reshape(len(m.faces), -1)
    whole = np.unique(corners(base), axis=0)
    parts = np.concatenate([corners(c) for c in chunks])
    np.testing.assert_array_equal(np.unique(parts, axis=0), whole)
    # Compact: each chunk's triangle centres span a small part of the whole's.
    span = lambda m: np.ptp(m.vertices[m.faces].mean(axis=1), axis=0).prod()
    assert max(span(c) for c in chunks) < 0.3 * span(base)
    assert split_mesh(base, 5000) == [base]


def test_frustum_culling_keeps_what_the_camera_sees():
    from diviewer.gl.culling import boxes_visible, frustum_planes

    view = cam.look_at((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))
    clip = cam.perspective(60.0, 1.0, 0.1, 50.0) @ view
    boxes = np.array([
        [[-1, -1, -6], [1, 1, -4]],       # ahead
        [[-1, -1, 4], [1, 1, 6]],         # behind
        [[30, -1, -6], [32, 1, -4]],      # far to the right of the 60 degree cone
        [[-1, -1, -80], [1, 1, -60]],     # beyond the far plane
        [[-50, -50, -3], [50, 50, 3]],    # around the camera
        [[2.5, -1, -6], [4.0, 1, -4]],    # straddling the right plane
    ], np.float64)
    np.testing.assert_array_equal(boxes_visible(frustum_planes(clip), boxes), [True, False, False, False, True, True])
    ortho = cam.orthographic(2.0, 2.0, 0.0, 10.0) @ view
    np.testing.assert_array_equal(boxes_visible(frustum_planes(ortho), boxes[:3]), [True, False, False])


def test_shadow_casters_keep_what_can_shade_the_view():
    """A caster is kept when its box, swept the way the sun's light travels until it leaves the scene's bounds,
    reaches the camera's frustum: above the view under a sun from overhead, or off to the side of it under a slanting
    sun that carries its shadow across; not behind the camera, beneath what it sees, or beside the view."""
    from diviewer.gl.culling import shadow_casters

    view = cam.look_at((0.0, 0.0, 0.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0))
    clip = cam.perspective(60.0, 1.0, 0.1, 50.0) @ view
    bounds = np.array([[-60.0, -60.0, -60.0], [60.0, 60.0, 60.0]])
    box = lambda centre: np.array([np.subtract(centre, 0.5), np.add(centre, 0.5)])
    boxes = np.array([box(c) for c in [
        (0, 10, -5),      # over the view
        (0, 10, 5),       # over the space behind the camera
        (0, -40, -5),     # beneath the view: its shadow falls further down
        (30, 10, -6),     # over the ground far to the right of the view
        (0, 0, -5),       # in the view
        (-12, 10, -5),    # up and to the left
    ]])
    down = (0.0, -1.0, 0.0)
    np.testing.assert_array_equal(shadow_casters(boxes, clip, down, bounds, 0.0),
                                  [True, False, False, False, True, False])
    # A sun slanting to the right carries the left caster's shadow through the view; slanting left, away from it.
    assert shadow_casters(boxes[5:], clip, (1.0, -1.0, 0.0), bounds, 0.0)[0]
    assert not shadow_casters(boxes[5:], clip, (-1.0, -1.0, 0.0), bounds, 0.0)[0]
    # The sweep ends where it leaves the scene: with the floor at y = 5 the shadow of the first never reaches the view.
    low = np.array([[-60.0, 5.0, -60.0], [60.0, 60.0, 60.0]])
    assert not shadow_casters(boxes[:1], clip, down, low, 0.0)[0]
    # The margin keeps a caster whose sweep passes just beside the view (a lookup reads texels beside its point).
    edge = np.tan(np.radians(30.0)) * 5.5  # the right plane's x at the box's far face (z = -5.5)
    beside = np.array([[[edge + 0.05, 9.5, -5.5], [edge + 0.1, 10.5, -4.5]]])
    assert not shadow_casters(beside, clip, down, bounds, 0.0)[0]
    assert shadow_casters(beside, clip, down, bounds, 0.2)[0]


def test_view_in_bounds_is_the_part_of_the_box_the_camera_sees_and_its_map_rectangle():
    """`view_in_bounds`' corners span the frustum clipped to the scene's box: every point in both lies in their hull
    (checked on the axes' ranges), none of them outside either; `footprint_rect` covers their texels plus a margin."""
    from diviewer.gl.culling import frustum_planes
    from diviewer.gl.shadow_fit import fit_directional, footprint_rect, view_in_bounds

    view = cam.look_at((0.0, 1.0, 0.0), (0.0, 1.0, -1.0), (0.0, 1.0, 0.0))
    clip = cam.perspective(60.0, 1.5, 0.1, 200.0) @ view
    bounds = np.array([[-10.0, 0.0, -30.0], [10.0, 8.0, 5.0]])
    p = view_in_bounds(clip, bounds)
    planes = frustum_planes(clip)
    assert len(p) >= 8
    assert np.all(p @ planes[:, :3].T + planes[:, 3] >= -1e-6)
    assert np.all((p >= bounds[0] - 1e-9) & (p <= bounds[1] + 1e-9))
    rng = np.random.default_rng(0)
    q = rng.uniform(bounds[0], bounds[1], (20000, 3))
    q = q[np.all(q @ planes[:, :3].T + planes[:, 3] >= 0.0, axis=1)]
    assert len(q) > 1000
    assert np.all(q.min(axis=0) >= p.min(axis=0) - 1e-9) and np.all(q.max(axis=0) <= p.max(axis=0) + 1e-9)
    # The box ends 30 m ahead, left, right, floor and ceiling: the far plane (200 m) adds nothing beyond it.
    np.testing.assert_allclose(p.min(axis=0), [-10.0, 0.0, -30.0], atol=1e-6)
    assert p.max(axis=0)[2] <= 0.0 + 1e-6  # nothing behind the camera
    assert len(view_in_bounds(clip, bounds + [0.0, 0.0, 40.0])) == 0  # a box wholly behind the camera
    m_light, _, _ = fit_directional(bounds, (0.0, -1.0, 0.0))
    x, y, w, h = footprint_rect(m_light, p, 256, 3.0)
    assert 0 <= x and 0 <= y and x + w <= 256 and y + h <= 256 and 0 < w * h < 256 * 256
    t = (np.c_[q, np.ones(len(q))] @ m_light.T)[:, :2] * 0.5 + 0.5
    assert np.all(t * 256 >= [x, y]) and np.all(t * 256 <= [x + w, y + h])  # every point in view, in the rectangle
    inner = footprint_rect(m_light, p, 256, 0.0)  # the margin widens each side by 3 texels, within the map
    assert (x, y) == (max(inner[0] - 3, 0), max(inner[1] - 3, 0))
    assert (x + w, y + h) == (min(inner[0] + inner[2] + 3, 256), min(inner[1] + inner[3] + 3, 256))
    assert footprint_rect(m_light, p[:0], 256, 3.0) == (0, 0, 0, 0)


def test_sponza_moving_sun_map_holds_only_what_shades_the_view_and_changes_no_pixel(ctx, sponza):
    """While the sun moves (``moving_shadow_size``), its map holds only what can shade the camera's view: from the
    gallery, along the sunlit one across the atrium, fewer triangles and fewer texels than with the footprint off
    (the casters whose shadow can reach the view, the texels over the part of the scene in view), and the same frame
    bit for bit, the map's texels that a visible point reads being the same. At rest the map is drawn again whole."""
    gallery = dataclasses.replace(sponza.default.camera, position=(5.9, 11.8, 4.4), target=(4.8, 11.4, -3.05))
    sun = next(light for light in sponza.default.lights if light.kind == "directional")
    view = dataclasses.replace(sponza.default, camera=gallery)
    turned = [view.replace_light(sun.name, direction=(-0.349 + 0.02 * k, -0.903, -0.251 + 0.01 * k)) for k in range(3)]
    drawn, frames, written = {}, {}, {}
    for footprint in (True, False):
        r = Renderer(ctx, sponza, 48, 48, RenderSettings(shadow_size=512))
        r.moving_shadow_size, r.shadow_footprint = 512, footprint
        try:
            r.frame(turned[0])  # the first map is drawn whole
            for k in (1, 2):
                frames[footprint, k] = r.frame(turned[k])
                drawn[footprint, k] = r.drawn["shadows"][1]
                assert r.shadow_pass.maps[sun.name].footprint is footprint
                written[footprint, k] = (np.frombuffer(r.shadow_pass.maps[sun.name].map.read(), "f4") < 1.0).mean()
            renders = r.shadow_renders
            frames[footprint, "rest"] = r.frame(turned[2])  # the sun rests: a footprint map is not kept
            assert r.shadow_renders == renders + footprint and not r.shadow_pass.maps[sun.name].footprint
        finally:
            r.release()
    for k in (1, 2):
        assert drawn[True, k] < 0.8 * drawn[False, k]
        assert 0.0 < written[True, k] < 0.5 * written[False, k]  # the scissor: only the texels over the view
        assert (frames[True, k]["direct"].max(axis=2) > 0.0).mean() > 0.05  # sunlit pixels in view
        np.testing.assert_array_equal(frames[True, k]["direct"], frames[False, k]["direct"], err_msg=str(k))
    np.testing.assert_array_equal(frames[True, "rest"]["direct"], frames[False, "rest"]["direct"])


def test_sponza_culling_draws_less_at_a_wall_and_changes_no_pixel(ctx, sponza):
    """A camera facing the east wall draws fewer triangles than one looking down the atrium; every buffer is
    bit for bit the same with and without culling."""
    cam0 = sponza.default.camera
    views = {"atrium": sponza.default,
             "wall": dataclasses.replace(sponza.default, camera=dataclasses.replace(cam0, target=(25.0, 5.6, 0.0)))}
    drawn, frames = {}, {}
    for culling in (True, False):
        r = Renderer(ctx, sponza, 48, 48, RenderSettings(shadow_size=256), culling=culling)
        try:
            for name, config in views.items():
                frames[name, culling] = r.frame(config)
                drawn[name, culling] = r.drawn["gbuffer"]
        finally:
            r.release()
    total = drawn["atrium", False][1]
    assert drawn["wall", False][1] == total == drawn["atrium", False][1]  # without culling: everything
    assert drawn["wall", True][1] < 0.25 * drawn["atrium", True][1] <= 0.25 * total
    for name in views:
        assert frames[name, True]["albedo"].std() > 0.01, f"{name}: the view shows nothing"
        for buf in frames[name, True]:
            np.testing.assert_array_equal(frames[name, True][buf], frames[name, False][buf], err_msg=f"{name} {buf}")


def test_sponza_gbuffer_flushed_in_parts_changes_no_pixel(ctx, sponza):
    """The G-buffer flushes every ``flush_every`` draws (glFlush, for the rasterizer's threads to start on the first
    draws): Sponza's atrium view, flushed after every draw, is bit for bit the frame drawn with one flush at the end."""
    from diviewer.gl.context import gl_flush
    from diviewer.gl.renderer import FLUSH_EVERY_DRAWS

    assert gl_flush() is not None and FLUSH_EVERY_DRAWS > 0
    frames, flushes = {}, {}
    for every in (0, 1):
        r = Renderer(ctx, sponza, 48, 48, RenderSettings(shadow_size=256), flush_every=every)
        try:
            frames[every] = r.frame()
            flushes[every], draws = r.flushes, r.drawn["gbuffer"][0]
        finally:
            r.release()
    assert flushes[0] == 0 and flushes[1] == draws - 1 > 10
    assert frames[1]["albedo"].std() > 0.01
    for buf in frames[0]:
        np.testing.assert_array_equal(frames[1][buf], frames[0][buf], err_msg=buf)


def test_single_sided_back_faces_leave_the_gbuffer_not_the_shadows(ctx):
    """Single-sided materials: a closed box seen from outside is bit for bit the two-sided one, from inside it is not
    there; a sheet seen from behind is not in the G-buffer, and its shadow is still on the wall behind it."""
    sun = {"name": "sun", "type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": 3.0}
    scene = facing_plane(distance=3.0, fov=70.0, lights=[sun], extra_meshes={"sheet": {"shape": "plane", "size": 0.6}},
                         extra_objects=[{"name": "sheet", "mesh": "sheet", "material": "occ", "position": [0, 0, -1.5],
                                         "rotation": [-90.0, 0.0, 0.0]}])  # its front faces the wall
    single = dataclasses.replace(scene, materials={k: dataclasses.replace(m, double_sided=False)
                                                   for k, m in scene.materials.items()})
    wall = scene.default.objects[0]
    inside = dataclasses.replace(scene.default, camera=dataclasses.replace(
        scene.default.camera, position=tuple(wall.position), target=(0.0, 0.0, -10.0)))
    frames = {}
    for name, s, back_faces in (("two-sided", scene, False), ("culled", single, False), ("kept", single, True)):
        r = Renderer(ctx, s, 48, 48, RenderSettings(shadow_size=256), back_faces=back_faces)
        try:
            frames[name] = r.frame()
            frames[name, "inside"] = r.frame(inside)
        finally:
            r.release()
    seen, culled, kept = frames["two-sided"], frames["culled"], frames["kept"]
    c = 24  # the centre pixel: the sheet's back face, or the wall through it
    assert seen["depth"][c, c] == pytest.approx(1.5, rel=1e-4) == kept["depth"][c, c]
    assert culled["depth"][c, c] == pytest.approx(3.0, rel=1e-4)
    assert culled["direct"][c, c].max() == 0.0 < culled["direct"][2, 2].min(), "the sheet still shadows the wall"
    hidden = np.abs(culled["depth"] - seen["depth"]) > 1e-3  # the sheet's pixels
    assert 0.01 < hidden.mean() < 0.1
    for buf in seen:
        np.testing.assert_array_equal(culled[buf][~hidden], seen[buf][~hidden], err_msg=buf)
        np.testing.assert_array_equal(kept[buf], seen[buf], err_msg=buf)
    assert (frames["culled", "inside"]["depth"] == 0.0).all(), "inside a single-sided box the camera sees no wall"
    assert (frames["kept", "inside"]["depth"] > 0.0).all() and (frames["two-sided", "inside"]["depth"] > 0.0).all()


def test_sponza_draws_opaque_front_to_back_then_masked_and_changes_no_pixel(ctx, sponza, monkeypatch):
    """The G-buffer pass draws the opaque pieces nearest first and the alpha-masked ones last; the buffers are
    bit for bit those of the list's order."""
    from diviewer.gl import culling, draw

    r = Renderer(ctx, sponza, 48, 48, RenderSettings(shadow_size=256))
    try:
        config = sponza.default
        items, boxes, masked = draw.frame_draw_list(r, config)
        keep = np.ones(len(items), bool)
        assert masked.tolist() == [sponza.materials[it[1]].is_masked for it in items]
        eye = cam.view_to_world(config.camera.view_matrix())[:3, 3]
        order = culling.draw_order(boxes, keep, masked, eye)
        assert sorted(order.tolist()) == list(range(len(items)))
        assert 0 < masked.sum() < len(items) and masked[order].tolist() == sorted(masked[order].tolist())
        dist = [np.linalg.norm(np.clip(eye, boxes[i, 0], boxes[i, 1]) - eye) for i in order if not masked[i]]
        assert dist == sorted(dist)
        assert culling.draw_order(boxes, keep, masked, None).tolist() == list(range(len(items)))  # no camera
        sorted_frame = r.frame(config)
        monkeypatch.setattr(draw, "draw_order", lambda boxes, keep, masked, eye: np.flatnonzero(keep))
        listed = r.frame(config)
        for buf in sorted_frame:
            np.testing.assert_array_equal(sorted_frame[buf], listed[buf], err_msg=buf)
    finally:
        r.release()


def test_the_renderer_takes_the_scenes_shadow_map_size_where_its_settings_name_none(ctx):
    """RenderSettings' shadow_size None is the scene's ``[scene] shadow_size``; a size given wins; settings set later
    resolve the same way; a capture records the size it rendered with."""
    from diviewer.data.capture import CaptureSettings, build_manifest

    scene = dataclasses.replace(facing_plane(), shadow_size=512)
    r = Renderer(ctx, scene, 16, 16)
    try:
        assert r.settings.shadow_size == 512 and r.shadow_pass.face_size == 256
        r.settings = RenderSettings(shadows=False)
        assert r.settings == RenderSettings(shadows=False, shadow_size=512)
    finally:
        r.release()
    given = Renderer(ctx, scene, 16, 16, RenderSettings(shadow_size=64))
    try:
        assert given.settings.shadow_size == 64
    finally:
        given.release()
    manifest = build_manifest(scene, CaptureSettings(frames=1, width=16, height=16, spp=1))
    assert manifest["render_settings"]["shadow_size"] == 512


def test_a_directional_map_is_fitted_to_the_bounds_outline_not_their_sphere():
    """Every corner of the bounds lands inside the light's clip box, touching it on each axis (within the fit's
    padding); the map is never wider than the bounding sphere's square, and the extent returned is its larger side."""
    from diviewer.gl.shadow_fit import fit_directional

    bounds = np.array([[-26.8, 2.3, -16.5], [24.2, 23.6, 14.9]])  # Sponza's
    corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2], 1.0] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    sphere = float(np.linalg.norm(bounds[1] - bounds[0]))
    for direction in ([-0.35, -0.94, 0.0], [-0.35, -0.6, 0.72], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]):
        m, extent, depth_range = fit_directional(bounds, direction)
        c = corners @ m.T
        assert np.allclose(c[:, 3], 1.0)
        assert np.all(np.abs(c[:, :3]) <= 1.0) and np.all(np.abs(c[:, :3]).max(axis=0) > 0.99), direction
        sides = 2.0 / np.linalg.norm(m[:2, :3], axis=1)
        assert extent == pytest.approx(sides.max()) and extent <= sphere + 1e-6
        assert 0.0 < depth_range <= sphere + 1e-6
        # the light looks along its direction: a point further along it lies deeper in the map
        centre = bounds.mean(axis=0)
        d = np.asarray(direction) / np.linalg.norm(direction)
        assert (m @ np.append(centre + d, 1.0))[2] > (m @ np.append(centre, 1.0))[2]
    m, _, _ = fit_directional(bounds, [-0.35, -0.94, 0.0])  # the noon sun: 31 x 55 m of the sphere's 64 x 64
    assert sorted(np.round(2.0 / np.linalg.norm(m[:2, :3], axis=1))) == [31.0, 55.0]


def test_a_moving_sun_renders_its_map_at_the_moving_size_and_the_full_one_when_it_rests(ctx):
    """``moving_shadow_size`` (the viewer's): the first frame and every frame of a light at rest draw the full map;
    each frame the light moved draws the smaller one; the first frame it rests draws the full map again, and that
    frame is exactly what a renderer without the moving size draws."""
    scene = facing_plane(lights=[{"name": "sun", "type": "directional", "direction": [0.3, -0.4, -1.0]}],
                         extra_objects=[{"name": "box", "mesh": "wall", "material": "occ", "position": [0, 0, -1.5],
                                         "scale": [0.1, 0.1, 0.1]}])
    r = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=256))
    plain = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=256))
    r.moving_shadow_size = 32
    try:
        config = scene.default
        sizes = []
        for direction in [None, (0.35, -0.4, -1.0), (0.4, -0.4, -1.0), None, None]:
            if direction is not None:
                config = config.replace_light("sun", direction=direction)
            frame = r.frame(config)["direct"]
            sizes.append((r.shadow_renders, r.shadow_pass.maps["sun"].map.size[0]))
        assert sizes == [(1, 256), (2, 32), (3, 32), (4, 256), (4, 256)]
        np.testing.assert_array_equal(frame, plain.frame(config)["direct"])
        moving = r.frame(config.replace_light("sun", direction=(0.3, -0.4, -1.0)))["direct"]
        assert not np.array_equal(moving, plain.frame(config.replace_light("sun", direction=(0.3, -0.4, -1.0)))["direct"])
    finally:
        plain.release()
        r.release()
