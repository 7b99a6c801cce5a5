"""The Mitsuba reference against the GL renderer: same camera (AOVs vs G-buffer, proven to catch camera
mistakes), same radiometry (direct vs GL direct), energy sanity, seeds, refusals, the CLI."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys

import numpy as np
import pytest

pytest.importorskip("mitsuba")
pytestmark = pytest.mark.mitsuba

from diviewer.cli import main  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.gl.renderer import Renderer, RenderSettings  # noqa: E402
from diviewer.imageio import read_exr, read_png  # noqa: E402
from diviewer.reference import mitsuba as ref  # noqa: E402
from diviewer.scene import FrameConfig, Material, Mesh, Object, PointLight, Scene, load_scene  # noqa: E402
from diviewer.scene import camera as cam  # noqa: E402
from diviewer.scene.loader import parse_scene  # noqa: E402
from scenes import emissive_tile  # noqa: E402

W, H = 64, 48
AOV_SPP = 16

# G-buffer agreement, per pixel, on the pixels away from silhouettes and creases. Measured here
# (64x48, 16 spp multijitter): depth within 0.11 % everywhere, normals and albedo to float precision.
# A half-pixel shift breaks the depth check on 54 % (Cornell) / 9 % (atrium) of pixels, a wrong fov by
# 1 degree on ~70 %, a flipped x the albedo check on ~50 % (test_camera_mistakes_are_caught).
DEPTH_REL_TOL = 0.005
NORMAL_TOL = 0.01
ALBEDO_TOL = 1e-3
MIN_AGREEING = 0.99


@pytest.fixture(scope="module", autouse=True)
def variant():
    """llvm_ad_rgb where a working libLLVM >= 16 is found (faster), else scalar_rgb."""
    return ref.select_variant()


@pytest.fixture(scope="module")
def scenes():
    return {"cornell": load_scene("cornell"), "atrium": load_scene("atrium")}


def gl_frame(ctx, scene, config=None, size=(W, H), settings=RenderSettings()):
    r = Renderer(ctx, scene, *size, settings)
    try:
        return r.frame(config or scene.default)
    finally:
        r.release()
        assert ctx.error == "GL_NO_ERROR"


def grow(mask: np.ndarray, r: int = 1) -> np.ndarray:
    """Dilate a boolean mask by r pixels (square neighbourhood)."""
    out = mask.copy()
    p = np.pad(mask, r, mode="edge")
    h, w = mask.shape
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out |= p[r + dy:r + dy + h, r + dx:r + dx + w]
    return out


def edges(g: dict) -> np.ndarray:
    """Pixels whose footprint may straddle a silhouette, crease or material edge (from the G-buffer).

    A Mitsuba pixel averages its whole square, GL samples its centre: they differ legitimately only
    where the square holds two surfaces. Background, normal or albedo changes between neighbours and
    depth jumps over 10 % mark an edge; the image border counts (its outer neighbours are unknown);
    the mask is grown by one pixel.
    """
    d, n, a = g["depth"], g["normal"], g["albedo"]
    e = d <= 0
    e[0, :] = e[-1, :] = e[:, 0] = e[:, -1] = True
    for ax in (0, 1):
        lo = (slice(0, -1), slice(None)) if ax == 0 else (slice(None), slice(0, -1))
        hi = (slice(1, None), slice(None)) if ax == 0 else (slice(None), slice(1, None))
        jump = ((np.abs(n[lo] - n[hi]).max(-1) > 1e-3) | (np.abs(a[lo] - a[hi]).max(-1) > 1e-3)
                | (np.abs(d[lo] - d[hi]) > 0.1 * np.minimum(d[lo], d[hi])))
        e[lo] |= jump
        e[hi] |= jump
    return grow(e, 1)


def agreement(aovs: dict, g: dict, mask: np.ndarray) -> dict:
    """Fraction of masked pixels where each Mitsuba AOV agrees with the G-buffer."""
    rel = np.abs(aovs["depth"] - g["depth"]) / np.maximum(g["depth"], 1e-6)
    dn = np.linalg.norm(aovs["normal"] - g["normal"], axis=-1)
    da = np.abs(aovs["albedo"] - g["albedo"]).max(-1)
    return {"depth": float(np.mean(rel[mask] <= DEPTH_REL_TOL)), "normal": float(np.mean(dn[mask] <= NORMAL_TOL)),
            "albedo": float(np.mean(da[mask] <= ALBEDO_TOL))}


@pytest.fixture(scope="module")
def gbuffers(gl_context, scenes):
    with gl_context:  # current even if an earlier test made and released a context of its own
        return {name: gl_frame(gl_context, s) for name, s in scenes.items()}


# --- camera: AOVs against the G-buffer -------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["cornell", "atrium"])
def test_aovs_match_gbuffer(scenes, gbuffers, name):
    s, g = scenes[name], gbuffers[name]
    aovs = ref.render_aovs(s, s.default, W, H, spp=AOV_SPP, seed=0)
    assert aovs["depth"].shape == (H, W) and aovs["normal"].shape == aovs["albedo"].shape == (H, W, 3)
    # same coverage: background is background in both (silhouette pixels aside)
    mask = ~edges(g)
    assert mask.sum() >= 250, f"too few pixels away from edges to compare ({mask.sum()})"
    assert np.array_equal(aovs["depth"][mask] > 0, g["depth"][mask] > 0)
    a = agreement(aovs, g, mask)
    assert min(a.values()) >= MIN_AGREEING, a


def _yaw(m: np.ndarray, degrees: float) -> np.ndarray:
    r = np.identity(4)
    r[:3, :3] = cam.axis_angle((0, 1, 0), degrees)
    return m @ r


def _half_pixel_deg(config) -> float:
    """The angle of half a pixel at the image centre (a half-pixel horizontal shift there)."""
    return math.degrees(math.atan(math.tan(math.radians(config.camera.fov) / 2) / (H / 2) * 0.5))


CAMERA_TO_WORLD = ref.camera_to_world
MISTAKES = {
    "half_pixel_shift": lambda c: (lambda cfg: _yaw(CAMERA_TO_WORLD(cfg), _half_pixel_deg(cfg)), c),
    "flip_x": lambda c: (lambda cfg: CAMERA_TO_WORLD(cfg) @ np.diag([-1.0, 1, 1, 1]), c),
    "flip_rows": lambda c: (lambda cfg: CAMERA_TO_WORLD(cfg) @ np.diag([1.0, -1, 1, 1]), c),
    "fov_plus_2deg": lambda c: (None, dataclasses.replace(c, camera=dataclasses.replace(c.camera, fov=c.camera.fov + 2))),
    "fov_minus_2deg": lambda c: (None, dataclasses.replace(c, camera=dataclasses.replace(c.camera, fov=c.camera.fov - 2))),
}


@pytest.mark.parametrize("name", ["cornell", "atrium"])
@pytest.mark.parametrize("mistake", sorted(MISTAKES))
def test_camera_mistakes_are_caught(scenes, gbuffers, monkeypatch, name, mistake):
    """The AOV check above has teeth: break the Mitsuba camera on purpose and it must fail."""
    s, g = scenes[name], gbuffers[name]
    to_world, config = MISTAKES[mistake](s.default)
    if to_world is not None:
        monkeypatch.setattr(ref, "camera_to_world", to_world)
    # A fresh frame, not the cache (its key does not know about the broken camera).
    aovs = ref.MitsubaFrame(s, config, W, H).aovs(AOV_SPP, 0)
    a = agreement(aovs, g, ~edges(g))
    assert min(a.values()) < MIN_AGREEING, f"{mistake} went unnoticed: {a}"


def test_texture_rows_match_gl(ctx):
    """A textured quad: GL samples t = 0 at the image's bottom row; the Mitsuba albedo must agree."""
    tex = np.zeros((4, 4, 3), np.float32)
    tex[:2, :2] = (1.0, 0.0, 0.0)   # top-left red
    tex[:2, 2:] = (0.0, 1.0, 0.0)   # top-right green
    tex[2:, :] = (0.0, 0.0, 1.0)    # bottom blue
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    quad = Mesh("quad", v, np.tile(np.float32([0, 0, 1]), (4, 1)), np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
                uvs=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32))
    mat = Material("tex", albedo=(0.5, 1.0, 1.0), texture=tex)
    config = FrameConfig(camera=dataclasses.replace(load_scene("cornell").default.camera, position=(0, 0, 2.5),
                                                    target=(0, 0, 0)),
                         lights=(), objects=(Object("quad", "quad", "tex"),))
    scene = Scene("textured", None, "", {"quad": quad}, {"tex": mat}, config)
    g = gl_frame(ctx, scene, size=(32, 32))
    a = ref.MitsubaFrame(scene, config, 32, 32).aovs(AOV_SPP, 0)
    # away from the texel boundaries (bilinear blends there; GL uses mipmaps, Mitsuba does not)
    hit = (g["depth"] > 0) & ~edges(g)
    solid = hit & (np.abs(g["albedo"] - np.round(g["albedo"] * 2) / 2).max(-1) < 1e-3)
    assert solid.sum() > 50
    np.testing.assert_allclose(a["albedo"][solid], g["albedo"][solid], atol=0.02)
    # and the picture is the right way up: red top-left (albedo 0.5 scales red), blue at the bottom
    top_left, bottom = a["albedo"][:10, :10], a["albedo"][-10:, :]
    assert top_left[..., 0].mean() > 0.3 > top_left[..., 2].mean()
    assert bottom[..., 2].mean() > 0.8 > bottom[..., 0].mean()


# --- radiometry: direct light against the GL direct pass -------------------------------------------------------

def _point_config(scene):
    return dataclasses.replace(scene.default, lights=(PointLight("bulb", position=(0.3, 1.6, 0.4), intensity=2.0),))


# Allowed difference, per pixel relative to GL: 1e-3 for the directional light (measured 5e-7: the
# cosine is constant over a plane's pixel), 2 % for the point light (measured 1.5 %: Mitsuba averages
# I cos / r^2 over the pixel's square, GL takes the centre, and r is small near the ceiling).
@pytest.mark.parametrize("light,rtol", [("sun", 1e-3), ("point", 0.02)])
def test_direct_matches_gl_direct(ctx, scenes, light, rtol):
    """Mitsuba's path length 2 against the GL direct pass (shadow-mapped) on the Cornell box.

    The only systematic differences allowed are the shadow map's: PCF-softened and biased shadow
    edges (penumbra pixels, light leaking near contacts) against Mitsuba's exact hard shadows. So the
    comparison runs on pixels GL sees fully lit (shadowed == unshadowed render) or fully dark, one pixel
    away from any change of that class and from geometric edges.
    """
    s = scenes["cornell"]
    config = s.default if light == "sun" else _point_config(s)
    size = (64, 64)
    g = gl_frame(ctx, s, config, size)
    unshadowed = gl_frame(ctx, s, config, size, RenderSettings(shadows=False))["direct"].mean(-1)
    shadowed = g["direct"].mean(-1)
    vis = np.where(unshadowed > 0, shadowed / np.maximum(unshadowed, 1e-12), 0.0)
    lit, dark = vis > 0.999, vis < 0.001
    geo = edges(g)
    lit &= ~grow(~lit) & ~geo
    dark &= ~grow(~dark) & ~geo
    assert lit.sum() > 400 and dark.sum() > 150
    m = ref.render_direct(s, config, *size, spp=16, seed=0)
    rel = np.abs(m - g["direct"]).max(-1) / np.maximum(g["direct"].max(-1), 1e-6)
    assert np.mean(rel[lit] <= rtol) >= MIN_AGREEING, np.quantile(rel[lit], [0.5, 0.99, 1.0])
    assert np.abs(m[dark]).max() < 1e-6


def test_emissive_box_radiance_matches_gl(ctx):
    """A closed emissive box (black albedo) shows exactly its radiance in both renderers."""
    data = {
        "camera": {"position": [0, 0, 3], "target": [0, 0, 0], "fov": 40},
        "materials": {"glow": {"albedo": [0, 0, 0], "emission": [2.0, 1.0, 0.5]}, "grey": {"albedo": [0.5, 0.5, 0.5]}},
        "meshes": {"box": {"shape": "box", "size": [1.0, 1.0, 1.0]}, "wall": {"shape": "box", "size": [6, 6, 0.1]}},
        "objects": [{"name": "lamp", "mesh": "box", "material": "glow", "rotation": [20, 30, 0]},
                    {"name": "wall", "mesh": "wall", "material": "grey", "position": [0, 0, -2]}],
    }
    scene = parse_scene(data)
    g = gl_frame(ctx, scene, size=(32, 32))
    m = ref.render_direct(scene, scene.default, 32, 32, spp=16, seed=0)
    lamp = (np.abs(g["albedo"]).max(-1) == 0) & (g["depth"] > 0) & ~edges(g)
    assert lamp.sum() > 20
    np.testing.assert_allclose(m[lamp], np.broadcast_to([2.0, 1.0, 0.5], m[lamp].shape), rtol=1e-5)
    np.testing.assert_allclose(g["direct"][lamp], m[lamp], rtol=1e-5)


def test_an_emission_texture_shows_its_pattern_as_in_gl(ctx):
    """A tile glowing by a texture whose left half is 4x its right: Mitsuba's area emitter reads the texture at the
    mesh's uvs, so its direct render is 4x brighter on the left as GL's direct pass is; both agree per pixel away
    from the seam (where GL takes the pixel centre and Mitsuba the pixel's square) and in mean over the tile."""
    scene = emissive_tile(emission=(2.0, 1.0, 0.5))
    g = gl_frame(ctx, scene, size=(48, 48))
    m = ref.render_direct(scene, scene.default, 48, 48, spp=16, seed=0)
    tile = (g["albedo"].max(-1) == 0.0) & (g["depth"] > 0) & ~edges(g)
    cols = np.nonzero(tile.any(axis=0))[0]
    left, right = np.zeros_like(tile), np.zeros_like(tile)
    left[:, cols[2:len(cols) // 3]] = True
    right[:, cols[-(len(cols) // 3):-2]] = True
    for half, want in ((tile & left, [2.0, 1.0, 0.5]), (tile & right, [0.5, 0.25, 0.125])):
        assert half.sum() > 100
        np.testing.assert_allclose(m[half], np.broadcast_to(want, m[half].shape), rtol=1e-3)
        np.testing.assert_allclose(g["direct"][half], m[half], rtol=1e-3)
    assert m[tile & left].mean() > 3.9 * m[tile & right].mean()
    assert abs(m[tile].mean() / g["direct"][tile].mean() - 1.0) < 0.01  # measured 1e-6 (llvm_ad_rgb, 16 spp)


# --- energy ----------------------------------------------------------------------------------------------------

def test_light_off_is_black(scenes):
    s = scenes["cornell"]
    off = s.default.replace_light("sun", irradiance=0.0)
    img = ref.render_full(s, off, 32, 32, spp=4, seed=0)
    assert img.shape == (32, 32, 3) and img.dtype == np.float32
    assert np.all(img == 0.0)


def test_doubling_the_light_doubles_the_image(scenes):
    """Same seed, same paths: twice the irradiance is twice every pixel (to float rounding)."""
    s = scenes["cornell"]
    a = ref.render_full(s, s.default, 32, 32, spp=8, seed=3)
    b = ref.render_full(s, s.default.replace_light("sun", irradiance=2 * s.default.lights[0].irradiance), 32, 32,
                        spp=8, seed=3)
    assert a.max() > 0
    np.testing.assert_allclose(b, 2.0 * a, rtol=1e-5, atol=1e-7)


@pytest.fixture(scope="module")
def cornell_gi(scenes):
    s = scenes["cornell"]
    frame = ref.load_frame(s, s.default, W, H)
    full = frame.full(64, 5)
    direct = frame.direct(64, 5)
    return full, direct


def test_indirect_is_non_negative(cornell_gi):
    """full - direct with the same seed: the direct part of each path is the same sample, so the rest
    (bounces >= 2) is a sum of non-negative terms; allow float rounding only."""
    full, direct = cornell_gi
    indirect = full - direct
    assert indirect.min() >= -1e-5 * full.max()
    assert indirect.mean() > 0.05 * full.mean()


def test_colour_bleeding_from_the_walls(gbuffers, scenes, cornell_gi):
    """White surfaces near the red wall receive more red than green indirect light, and vice versa."""
    full, direct = cornell_gi
    indirect = full - direct
    g = gbuffers["cornell"]
    camera = scenes["cornell"].default.camera
    p_view = cam.pixel_rays_view(W, H, camera.fov) * g["depth"][..., None]
    m = cam.view_to_world(camera.view_matrix())
    x = (p_view @ m[:3, :3].T + m[:3, 3])[..., 0]
    white = (np.abs(g["albedo"] - 0.73).max(-1) < 1e-3) & ~edges(g)
    near_red, near_green = white & (x < -0.6), white & (x > 0.6)
    assert near_red.sum() > 20 and near_green.sum() > 20
    r_side, g_side = indirect[near_red].mean(0), indirect[near_green].mean(0)
    assert r_side[0] > 1.2 * r_side[1], r_side
    assert g_side[1] > 1.2 * g_side[0], g_side


# --- seeds and the noise floor ---------------------------------------------------------------------------------

def test_seeds(scenes):
    s = scenes["cornell"]
    a = ref.render_full(s, s.default, 32, 32, spp=4, seed=7)
    b = ref.render_full(s, s.default, 32, 32, spp=4, seed=7)
    c = ref.render_full(s, s.default, 32, 32, spp=4, seed=8)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # different noise, same picture
    assert abs(float(a.mean()) - float(c.mean())) < 0.05 * float(a.mean())


def test_noise_floor_improves_with_spp(scenes):
    s = scenes["cornell"]
    lo = ref.noise_floor(s, s.default, 32, 32, spp=4)
    hi = ref.noise_floor(s, s.default, 32, 32, spp=32)
    assert lo["seeds"] == [1, 2] and lo["peak"] == 1.0
    assert 10 < lo["psnr"] < hi["psnr"] < 80
    assert 0 < lo["ssim"] < hi["ssim"] < 1
    # 8x the samples: about 9 dB less noise (variance ~ 1/spp)
    assert hi["psnr"] - lo["psnr"] == pytest.approx(10 * math.log10(8), abs=3.0)


# --- refusals and variants -------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class SpotLight:
    name: str
    position: tuple = (0.0, 1.0, 0.0)
    color: tuple = (1.0, 1.0, 1.0)
    kind: str = "spot"


def test_unknown_light_type_is_refused(scenes):
    s = scenes["cornell"]
    config = dataclasses.replace(s.default, lights=(*s.default.lights, SpotLight("torch")))
    with pytest.raises(DiviewerError, match=r"light 'torch' is of type 'spot'"):
        ref.to_mitsuba_dict(s, config, 16, 16, spp=1, seed=0)


def test_open_emissive_mesh_is_refused():
    """Mitsuba's area emitters are one-sided; GL shows emission on both sides of an open surface."""
    data = {
        "materials": {"glow": {"emission": [1.0, 1.0, 1.0]}},
        "meshes": {"panel": {"shape": "plane", "size": [1.0, 1.0]}},
        "objects": [{"name": "ceiling_light", "mesh": "panel", "material": "glow"}],
    }
    scene = parse_scene(data)
    with pytest.raises(DiviewerError, match=r"'ceiling_light'.*emissive material 'glow'.*open mesh 'panel'"):
        ref.to_mitsuba_dict(scene, scene.default, 16, 16, spp=1, seed=0)


def test_old_libllvm_is_not_tried(monkeypatch, tmp_path):
    """drjit aborts the process with LLVM 15, so a libLLVM older than 16 is refused before any attempt."""
    import mitsuba

    old = tmp_path / "libLLVM-15.so"
    old.write_bytes(b"")
    monkeypatch.setenv("DRJIT_LIBLLVM_PATH", str(old))
    from diviewer.reference import variant

    monkeypatch.setattr(variant, "_probe_llvm", lambda path: pytest.fail("probed an LLVM 15"))
    info = variant._choose_llvm(mitsuba)
    assert info.variant == "scalar_rgb" and "LLVM 15" in info.reason


def test_cuda_variant_is_chosen_only_where_it_renders(monkeypatch):
    """cuda_ad_rgb first where the build has it and a GPU renders with it; else the llvm/scalar choice."""
    import mitsuba

    from diviewer.reference import variant as v

    fake = type("FakeMitsuba", (), {"variants": staticmethod(lambda: ["scalar_rgb", "llvm_ad_rgb", "cuda_ad_rgb"])})
    monkeypatch.setattr(v, "_cuda_result", None)
    monkeypatch.setattr(v, "_has_cuda_driver", lambda: False)
    assert v._choose_cuda(fake) is None, "no CUDA driver: not even probed"
    probed = []
    monkeypatch.setattr(v, "_cuda_result", None)
    monkeypatch.setattr(v, "_has_cuda_driver", lambda: True)
    monkeypatch.setattr(v, "_probe", lambda variant, env, what: probed.append(variant) or "no device")
    assert v._choose_cuda(fake) is None and probed == ["cuda_ad_rgb"], "a failed probe falls back"
    monkeypatch.setattr(v, "_cuda_result", None)
    monkeypatch.setattr(v, "_probe", lambda variant, env, what: None)
    info = v._choose_cuda(fake)
    assert info.variant == "cuda_ad_rgb" and "GPU" in info.reason
    monkeypatch.setattr(v, "_cuda_result", None)
    monkeypatch.setattr(v, "_has_cuda_driver", lambda: False)
    assert v.select_variant() in ("llvm_ad_rgb", "scalar_rgb"), "this machine has no GPU"
    assert mitsuba.variant() in ("llvm_ad_rgb", "scalar_rgb")


def test_variant_option_picks_the_variant(tmp_path, monkeypatch):
    """`--variant scalar_rgb` renders the reference with scalar_rgb and records it in frame.json."""
    monkeypatch.delenv("DIVIEWER_MITSUBA_VARIANT", raising=False)
    try:
        assert main(["render", "--scene", "cornell", "--res", "16", "--out", str(tmp_path), "--reference", "pt",
                     "--spp", "1", "--variant", "scalar_rgb"]) == 0
        assert json.loads((tmp_path / "frame.json").read_text())["reference"]["variant"] == "scalar_rgb"
    finally:
        os.environ.pop("DIVIEWER_MITSUBA_VARIANT", None)
        ref.select_variant()  # back to this module's variant for the tests after this one


def test_variant_is_reported(variant):
    info = ref.variant_info()
    assert info.variant == variant in ref.VARIANTS and info.reason
    assert (info.libllvm is not None) == (variant == "llvm_ad_rgb")


def test_retarget_renders_as_a_fresh_load(scenes):
    """load_frame keeps the loaded scene when only camera and lights move; the images are a fresh load's."""
    from diviewer.scene import sample_config

    s = scenes["cornell"]
    moved = dataclasses.replace(sample_config(s, 3), objects=s.default.objects)
    # a pose and lights only: cornell's sampled cameras also draw a field of view, which needs a fresh load
    moved = dataclasses.replace(moved, camera=dataclasses.replace(moved.camera, position=(0.1, 1.1, 3.3),
                                                                  fov=s.default.camera.fov))
    first = ref.load_frame(s, s.default, 24, 16)
    again = ref.load_frame(s, moved, 24, 16)
    assert again is first and again.config == moved
    fresh = ref.MitsubaFrame(s, moved, 24, 16)
    np.testing.assert_array_equal(again.full(4, 1), fresh.full(4, 1))
    np.testing.assert_array_equal(again.direct(4, 1), fresh.direct(4, 1))
    assert ref.load_frame(s, sample_config(s, 4), 24, 16) is not first  # another object pose: a fresh load


# --- the command -----------------------------------------------------------------------------------------------

@pytest.mark.slow
def test_cli_reference_writes_pt_buffers(gl_context, tmp_path):
    out = tmp_path / "frame"
    assert main(["render", "--scene", "cornell", "--res", "32", "--out", str(out), "--reference", "pt",
                 "--spp", "8", "--noise-floor"]) == 0
    full, direct, indirect = (read_exr(out / f"{n}.exr") for n in ("pt", "pt_direct", "pt_indirect"))
    assert full.shape == (32, 32, 3)
    np.testing.assert_allclose(direct + indirect, full, atol=1e-6)
    for n in ("pt", "pt_direct", "pt_indirect"):
        assert read_png(out / f"{n}.png").shape == (32, 32, 3)
    record = json.loads((out / "frame.json").read_text())
    r = record["reference"]
    assert r["variant"] in ref.VARIANTS and r["spp"] == 8 and r["seed"] == 0 and r["max_depth"] == ref.DEFAULT_MAX_DEPTH
    assert r["seconds"]["full"] > 0 and r["noise_floor"]["seeds"] == [0, 1] and r["noise_floor"]["psnr"] > 0
    assert "camera" in record["config"]  # the GL record is kept
    one_pass = r["variant"].startswith("llvm")  # cornell's sun: one pass on a JIT variant (split_path)
    assert r["pt_estimator"] == ("one_pass" if one_pass else "two_passes")
    assert r["integrator"] == ("diviewer_split_path" if one_pass else "path")


def test_cli_without_mitsuba_names_the_train_extra(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # `import mitsuba` now raises ImportError
    out = tmp_path / "frame"
    assert main(["render", "--scene", "cornell", "--res", "16", "--out", str(out), "--reference", "pt"]) == 2
    err = capsys.readouterr().err
    assert "mitsuba" in err and "diviewer[train]" in err and "Traceback" not in err
    assert not out.exists(), "the missing extra should be reported before any rendering"
