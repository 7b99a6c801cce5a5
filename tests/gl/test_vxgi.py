"""VXGI pass on a headless EGL context, small grids: zero without light, energy, colour bleeding,
draw-order independence, caching, and the error against the path tracer."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.gl.renderer import Renderer
from diviewer.gl.vxgi import VXGIPass, VXGISettings, cone_layout
from diviewer.scene import camera as cam
from diviewer.scene import load_scene, sample_config
from diviewer.scene.loader import parse_scene
from diviewer.scene.model import PointLight
from scenes import emissive_tile

RES = 32
GRID = VXGISettings(resolution=32, trace_scale=1)


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


def run_vxgi(ctx, scene, config=None, settings=GRID, size=(RES, RES), names=("indirect", "vxgi", "vxgi_indirect", "ao")):
    r = Renderer(ctx, scene, *size)
    v = VXGIPass(ctx, r, settings)
    try:
        frame = r.frame(config)
        v.run(config)
        out = {n: v.read(n) for n in names}
        out["grid"] = v.read_grid()
        return frame, out
    finally:
        v.release()
        r.release()


def world_points(frame, camera, w, h):
    rays = cam.pixel_rays_view(w, h, camera.fov)
    m = cam.view_to_world(camera.view_matrix())
    return (rays * frame["depth"][..., None]) @ m[:3, :3].T + m[:3, 3]


def test_cone_weights_cover_the_hemisphere():
    for cones, aperture in ((1, 120.0), (6, 60.0), (9, 45.0), (16, 40.0)):
        dirs, w = cone_layout(cones, aperture)
        assert dirs.shape == (cones, 3) and np.all(dirs[:, 2] > 0)
        np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, rtol=1e-6)
        assert abs(w.sum() - 1.0) < 1e-6 and np.all(w > 0)
    _, w6 = cone_layout(6, 60.0)
    assert 0.24 < w6[0] < 0.3 and np.allclose(w6[1:], w6[1], atol=1e-3)  # near the usual 1/4 and 3/20


@pytest.mark.parametrize("field, value", [("resolution", 48), ("cones", 0), ("aperture", 180.0), ("trace_scale", 0),
                                          ("step", 0.0)])
def test_settings_are_checked(field, value):
    with pytest.raises(DiviewerError, match=f"vxgi.{field}"):
        dataclasses.replace(GRID, **{field: value}).validate()


@pytest.mark.slow
def test_light_off_gives_zero_indirect(ctx, cornell):
    cfg = dataclasses.replace(cornell.default, lights=())
    frame, out = run_vxgi(ctx, cornell, cfg)
    assert np.all(out["indirect"] == 0.0) and np.all(out["vxgi_indirect"] == 0.0)
    assert np.all(out["grid"][..., :3] == 0.0) and out["grid"][..., 3].max() == 1.0  # geometry, no light
    np.testing.assert_array_equal(out["vxgi"], frame["direct"])


@pytest.mark.parametrize("seed", [1, 2])
def test_indirect_finite_and_non_negative(ctx, cornell, seed):
    cfg = sample_config(cornell, seed, "train")
    for settings in (GRID, dataclasses.replace(GRID, trace_scale=2, cones=9, aperture=45.0, step=0.7)):
        frame, out = run_vxgi(ctx, cornell, cfg, settings)
        for name in ("indirect", "vxgi", "vxgi_indirect", "ao"):
            assert np.all(np.isfinite(out[name])), name
            assert out[name].min() >= 0.0, name
        assert out["ao"].max() <= 1.0
        lit = frame["depth"] > 0
        assert out["indirect"][lit].mean() > 0.01  # the sun lights the box: some light bounces
        np.testing.assert_allclose(out["vxgi"], frame["direct"] + out["vxgi_indirect"], rtol=1e-5, atol=1e-6)


@pytest.mark.slow
def test_colour_bleeding_next_to_the_coloured_walls(ctx, cornell):
    """Under a white sun, the white floor beside the red wall gets redder indirect light, beside the green greener."""
    cfg = cornell.default
    cfg = dataclasses.replace(cfg, lights=(dataclasses.replace(cfg.lights[0], color=(1.0, 1.0, 1.0)),))
    size = 48
    frame, out = run_vxgi(ctx, cornell, cfg, size=(size, size))
    p = world_points(frame, cfg.camera, size, size)
    floor = (frame["depth"] > 0) & (np.abs(p[..., 1]) < 0.01) & (p[..., 2] < 0.5)
    near_red, near_green = floor & (p[..., 0] < -0.6), floor & (p[..., 0] > 0.6)
    assert near_red.sum() > 10 and near_green.sum() > 10
    red = out["indirect"][near_red].mean(axis=0)
    green = out["indirect"][near_green].mean(axis=0)
    assert red[0] > red[1] and red[0] > red[2], red
    assert green[1] > green[0] and green[1] > green[2], green


@pytest.mark.slow
def test_draw_order_leaves_the_grid_unchanged(ctx, cornell):
    cfg = sample_config(cornell, 5, "train")
    f0, base = run_vxgi(ctx, cornell, cfg)
    for order in (cfg.objects[::-1], tuple(np.random.default_rng(0).permutation(np.array(cfg.objects, dtype=object)))):
        f1, out = run_vxgi(ctx, cornell, dataclasses.replace(cfg, objects=tuple(order)))
        np.testing.assert_array_equal(out["grid"], base["grid"])
        # The G-buffer itself may differ where coplanar faces meet (the depth test's tie goes to the
        # first drawn); wherever it is the same, so is the traced light.
        same = (f0["depth"] == f1["depth"]) & np.all(f0["normal"] == f1["normal"], axis=-1)
        assert same.mean() > 0.95
        np.testing.assert_array_equal(out["indirect"][same], base["indirect"][same])
    assert base["grid"][..., :3].max() > 0.0


def glowing_box():
    """A closed box whose walls glow with radiance 1 and reflect nothing: every surface inside sees 1."""
    walls = [((0, -1.05, 0), (2.2, 0.1, 2.2)), ((0, 1.05, 0), (2.2, 0.1, 2.2)), ((-1.05, 0, 0), (0.1, 2.2, 2.2)),
             ((1.05, 0, 0), (0.1, 2.2, 2.2)), ((0, 0, -1.05), (2.2, 2.2, 0.1)), ((0, 0, 1.05), (2.2, 2.2, 0.1))]
    return parse_scene({
        "scene": {"name": "furnace"},
        "camera": {"position": [0, 0, 0.9], "target": [0, 0, -1], "up": [0, 1, 0], "fov": 90.0},
        "materials": {"glow": {"albedo": [0.0, 0.0, 0.0], "emission": [1.0, 1.0, 1.0]}},
        "meshes": {f"w{i}": {"shape": "box", "size": list(s)} for i, (_, s) in enumerate(walls)},
        "objects": [{"name": f"w{i}", "mesh": f"w{i}", "material": "glow", "position": list(p)}
                    for i, (p, _) in enumerate(walls)],
        "lights": [],
    })


def test_the_grid_holds_an_emission_textures_pattern(ctx):
    """Voxelization reads the emission texture per fragment: the tile's left half (texture 1) puts 4x the radiance
    of its right half (0.25) into the grid; without the texture both halves hold the same."""
    scene = emissive_tile(emission=(2.0, 1.0, 0.5))
    plain = dataclasses.replace(scene, materials={**scene.materials, "glow": dataclasses.replace(
        scene.materials["glow"], emission_texture=None)})
    for s, ratio in ((scene, 4.0), (plain, 1.0)):
        red = run_vxgi(ctx, s, names=())[1]["grid"][..., 0]  # (z, y, x); the grid is centred on x = 0, the seam
        half = red.shape[2] // 2
        assert red.max() == pytest.approx(2.0)
        assert red[..., :half].sum() == pytest.approx(ratio * red[..., half:].sum(), rel=1e-3)


@pytest.mark.parametrize("resolution", [32, 64])
def test_furnace_cones_gather_all_the_light(ctx, resolution):
    """Inside a glowing box the indirect light is the walls' radiance (1); cones lose little of it.

    Measured: mean 0.93 (32^3) and 0.89 (64^3), 0.57-0.64 in the worst pixel (a corner): a cone
    sampling a wall between two trilinear samples sees it partly transparent and passes out of the box.
    The plain mean of coverage in the mips (instead of directional compositing) gave 0.2-0.4."""
    _, out = run_vxgi(ctx, glowing_box(), settings=dataclasses.replace(GRID, resolution=resolution))
    ind = out["indirect"]
    assert 0.85 < ind.mean() <= 1.0 and ind.min() > 0.5, (ind.mean(), ind.min())
    assert np.median(ind) > 0.85


def test_grid_is_rebuilt_only_when_something_changes(ctx, cornell):
    r = Renderer(ctx, cornell, 16, 16)
    v = VXGIPass(ctx, r, GRID)
    try:
        cfg = cornell.default
        for config, expected in [(cfg, ("static", "dynamic", "inject")), (cfg, ()),
                                 (cfg.replace_object("center", rotation=(10.0, 20.0, 30.0)), ("dynamic", "inject")),
                                 (cfg.replace_light("sun", irradiance=2.0), ("dynamic", "inject")),
                                 (cfg.replace_light("sun", irradiance=2.0), ())]:
            r.render(config)
            v.run(config)
            assert v.updated == expected
        assert v.fragment_counts["static"] > 1000 and v.fragment_counts["dynamic"] > 10
        # a light change alone re-injects without voxelizing
        config = cfg.replace_light("sun", irradiance=3.0)
        r.render(config)
        v.run(config)
        assert v.updated == ("inject",)
    finally:
        v.release()
        r.release()


def test_grid_is_lit_by_whole_maps_and_again_when_the_sun_comes_to_rest(ctx, cornell):
    """While a VXGI pass lives, its renderer draws a moving sun's map whole (the injection reads it over the whole
    grid, not only the view's footprint), and the light is injected again when the map is drawn again at its full
    size as the sun comes to rest; the renderer's footprint is back at the pass's release."""
    r = Renderer(ctx, cornell, 16, 16)
    r.moving_shadow_size = 256
    v = VXGIPass(ctx, r, GRID)
    try:
        assert not r.shadow_footprint
        cfg = cornell.default
        turned = cfg.replace_light("sun", direction=(0.35, -0.42, -0.84))
        for config, expected in [(cfg, ("static", "dynamic", "inject")), (turned, ("inject",)), (turned, ("inject",)),
                                 (turned, ())]:
            r.render(config)
            v.run(config)
            assert v.updated == expected and not r.shadow_pass.maps["sun"].footprint
    finally:
        v.release()
        assert r.shadow_footprint
        r.release()


@pytest.mark.slow
def test_lower_trace_resolution_stays_close(ctx, cornell):
    cfg = cornell.default
    _, full = run_vxgi(ctx, cornell, cfg, size=(48, 48))
    _, half = run_vxgi(ctx, cornell, cfg, dataclasses.replace(GRID, trace_scale=2), size=(48, 48))
    a, b = full["vxgi_indirect"], half["vxgi_indirect"]
    assert abs(a.mean() - b.mean()) < 0.05 * a.mean()
    assert np.abs(a - b).mean() < 0.1 * a.mean()


@pytest.mark.mitsuba
@pytest.mark.slow
def test_closer_to_the_path_tracer_than_direct_light(ctx, cornell, record_property):
    """On a few cornell frames VXGI's error against the path tracer is below direct light's (both recorded)."""
    pytest.importorskip("mitsuba")
    from diviewer.reference import mitsuba as ref

    ref.select_variant()
    errors = {"direct": [], "vxgi": []}
    for seed in (0, 3, 7):
        cfg = sample_config(cornell, seed, "test")
        frame, out = run_vxgi(ctx, cornell, cfg, dataclasses.replace(GRID, trace_scale=2))
        pt = ref.load_frame(cornell, cfg, RES, RES).full(spp=32, seed=seed, max_depth=8)
        errors["direct"].append(float(np.mean((frame["direct"] - pt) ** 2)))
        errors["vxgi"].append(float(np.mean((out["vxgi"] - pt) ** 2)))
    record_property("mse_direct", errors["direct"])
    record_property("mse_vxgi", errors["vxgi"])
    print("MSE against the path tracer (32 spp, 32x32):", errors)
    assert np.mean(errors["vxgi"]) < np.mean(errors["direct"])


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["cornell", "atrium"])
def test_render_command_writes_vxgi(gl_context, tmp_path, scene):
    """`diviewer render --vxgi` writes vxgi.exr = direct + vxgi_indirect.exr, and records the settings."""
    import json

    from diviewer.cli import main
    from diviewer.imageio import read_exr

    out = tmp_path / scene
    assert main(["render", "--scene", scene, "--res", "32", "--out", str(out), "--vxgi", "--vxgi-res", "32"]) == 0
    vxgi, indirect, direct = (read_exr(out / f"{n}.exr") for n in ("vxgi", "vxgi_indirect", "direct"))
    assert vxgi.shape == indirect.shape == (32, 32, 3) and (out / "vxgi.png").is_file()
    assert np.all(np.isfinite(vxgi)) and indirect.min() >= 0.0 and indirect.max() > 0.0
    np.testing.assert_allclose(vxgi, direct + indirect, rtol=1e-5, atol=1e-6)
    record = json.loads((out / "frame.json").read_text())
    assert record["vxgi"]["settings"]["resolution"] == 32 and record["vxgi"]["fragments"]["static"] > 0
    assert main(["render", "--scene", scene, "--res", "32", "--out", str(out), "--vxgi", "--vxgi-res", "48"]) == 2


def sealed_box(sun: bool = True):
    """The glowing box's walls, white and not glowing, under a sun outside: nothing inside is lit."""
    scene = glowing_box()
    data_walls = {o.name: o for o in scene.default.objects}
    return parse_scene({
        "scene": {"name": "sealed"},
        "camera": {"position": [0, 0, 0.9], "target": [0, 0, -1], "up": [0, 1, 0], "fov": 90.0},
        "materials": {"white": {"albedo": [0.8, 0.8, 0.8]}},
        "meshes": {n: {"shape": "box", "size": [float(x) for x in np.ptp(scene.meshes[o.mesh].bounds, axis=0).round(6)]}
                   for n, o in data_walls.items()},
        "objects": [{"name": n, "mesh": n, "material": "white", "position": list(o.position)} for n, o in data_walls.items()],
        "lights": [{"name": "sun", "type": "directional", "direction": [0.5, -0.7, -0.5], "irradiance": 5.0}] if sun else [],
    })


@pytest.mark.slow
def test_thin_walls_leak_little_of_the_light_outside(ctx):
    """Sun on the outside of a closed box with walls 3 voxels thick: the inside should stay dark.

    It does not quite (a known VXGI artefact, see diviewer.gl.vxgi): measured 0.065 mean indirect for
    0.9 on the lit outer faces at 64^3 (0.062 at 128^3: it is the coarse levels, whose voxels reach
    behind a cone's apex to the far side of the wall it starts on); the isotropic grid leaks 0.135,
    and without the lod bias 0.143."""
    scene = sealed_box()
    settings = dataclasses.replace(GRID, resolution=64)
    frame, out = run_vxgi(ctx, scene, settings=settings)
    assert frame["direct"].max() == 0.0  # nothing inside is lit directly
    grid = out["grid"]
    outside = grid[..., :3].max()  # the sunlit outer faces
    assert outside > 0.5
    leak = out["indirect"].mean()
    _, iso = run_vxgi(ctx, scene, settings=dataclasses.replace(settings, anisotropic=False))
    print(f"sealed box: outside radiance {outside:.3f}, indirect inside {leak:.4f} (isotropic {iso['indirect'].mean():.4f})")
    assert leak < 0.1 * outside
    assert iso["indirect"].mean() > 1.5 * leak


@pytest.mark.slow
def test_point_light_inside_the_sealed_box(ctx):
    """A bulb inside the closed box: its shadow-mapped light is injected (the point-light path) and bounces."""
    scene = sealed_box(sun=False)
    cfg = dataclasses.replace(scene.default, lights=(PointLight("bulb", position=(0.3, 0.5, -0.2), intensity=3.0),))
    frame, out = run_vxgi(ctx, scene, cfg, settings=dataclasses.replace(GRID, resolution=32))
    assert frame["direct"].max() > 0.0
    for name in ("indirect", "vxgi"):
        assert np.all(np.isfinite(out[name])) and out[name].min() >= 0.0
    # White walls all round: the bounce is grey and a sizeable share of the direct light.
    ind = out["vxgi_indirect"].mean(axis=(0, 1))
    assert np.allclose(ind, ind.mean(), rtol=1e-3) and ind.mean() > 0.2 * frame["direct"].mean()
