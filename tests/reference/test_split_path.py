"""The one-pass ground truth (diviewer.reference.split_path): its direct light is the two passes' to round-off, its
full light estimates the same image, cut-outs pass light and paths as volpath's null interactions, and frames with
area lights keep the two passes."""

from __future__ import annotations


import numpy as np
import pytest

pytest.importorskip("mitsuba")
pytestmark = pytest.mark.mitsuba

from diviewer.reference import mitsuba as ref  # noqa: E402
from diviewer.reference import split_path  # noqa: E402
from diviewer.scene import load_scene  # noqa: E402
from diviewer.scene.loader import parse_scene  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def variant():
    v = ref.select_variant()
    if not v.startswith(("llvm", "cuda")):
        pytest.skip(f"the one pass runs on Mitsuba's JIT variants only, not {v}")
    return v


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


def test_the_direct_light_is_the_two_passes_to_round_off(cornell):
    """Both draw the first vertex's light sample with the same random numbers: the same direct image."""
    frame = ref.load_frame(cornell, cornell.default, 32, 32)
    full, direct, how = frame.full_and_direct(16, 3)
    assert how == split_path.ONE_PASS and full.shape == direct.shape == (32, 32, 3)
    two = frame.direct(16, 3)
    assert two.max() > 0
    np.testing.assert_array_equal(frame.full_light(16, 3), full)  # the full light alone: the same render
    np.testing.assert_allclose(direct, two, rtol=1e-5, atol=1e-7 * two.max())
    indirect = full - direct  # the later bounces of the same paths: never negative
    assert indirect.min() >= -1e-6 * full.max() and indirect.mean() > 0.05 * full.mean()


def test_the_full_light_estimates_the_two_passes_image(cornell):
    """On cornell's default frame the frame means of full and indirect light of the one pass and of the two passes
    agree within the seeds' spread (|z| well under 4), and per pixel the z scores are centred with unit spread."""
    from oracles import split_path_compare, split_path_renders

    frame, seeds = ref.load_frame(cornell, cornell.default, 24, 24), range(1, 7)
    row = split_path_compare(split_path_renders(frame, 16, seeds, True), split_path_renders(frame, 16, seeds, False))
    for name in ("full", "indirect"):
        r = row[name]
        assert abs(r["z"]) < 4 and abs(r["relative_difference"]) < 0.02, (name, r)
        assert abs(r["pixel_z_mean"]) < 0.2 and 0.7 < r["pixel_z_std"] < 1.6, (name, r)
    assert row["direct"]["same_seed_max_difference"] < 1e-4


def _scene(objects: list[dict], materials: dict, **extra):
    data = {"camera": {"position": [0, 3, 2], "target": [0, 0, 0], "fov": 50},
            "meshes": {"floor": {"shape": "box", "size": [4, 0.1, 4]}, "quad": {"shape": "box", "size": [3, 0.02, 3]}},
            "materials": materials, "objects": objects,
            "lights": [{"name": "sun", "type": "directional", "direction": [0.3, -1.0, 0.2], "irradiance": 3.0}],
            **extra}
    return parse_scene(data)


def test_a_cut_out_passes_the_light_and_the_path_as_volpath_does(tmp_path):
    """A quad between the sun, the camera and a floor, cut away entirely by its mask: the one pass renders what the
    two passes (volpath) render, and the floor as bright as without the quad; uncut, the quad is what is seen."""
    from PIL import Image

    floor = {"name": "floor", "mesh": "floor", "material": "grey"}
    quad = {"name": "quad", "mesh": "quad", "material": "cut", "position": [0, 1.0, 0]}
    grey = {"grey": {"albedo": [0.6, 0.5, 0.4]}}
    frames = {}
    for name, alpha in (("cut", 0), ("uncut", 255)):
        rgba = np.full((4, 4, 4), 255, np.uint8)
        rgba[..., 3] = alpha
        Image.fromarray(rgba, "RGBA").save(tmp_path / f"{name}.png")
        scene = _scene([floor, quad], {**grey, "cut": {"albedo": [1, 1, 1], "texture": str(tmp_path / f"{name}.png"),
                                                        "alpha_cutoff": 0.5}})
        assert scene.materials["cut"].is_masked
        frames[name] = ref.load_frame(scene, scene.default, 24, 24)
    without = _scene([floor], grey)
    frames["without"] = ref.load_frame(without, without.default, 24, 24)
    one = {k: f.full_and_direct(16, 1) for k, f in frames.items()}
    cut = frames["cut"]
    np.testing.assert_allclose(one["cut"][0], cut.full(16, 1), rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(one["cut"][1], cut.direct(16, 1), rtol=1e-4, atol=1e-6)
    lit = one["without"][1].mean()
    assert lit > 0 and abs(one["cut"][1].mean() / lit - 1) < 1e-3
    assert one["uncut"][1].mean() > 1.5 * lit, "uncut, the camera sees the white quad in the sun instead"


def test_area_lights_and_the_sky_keep_the_two_passes():
    """An emissive surface needs MIS, which the one pass does not do: its frames are rendered as before."""
    glow = _scene([{"name": "floor", "mesh": "floor", "material": "grey"},
                   {"name": "lamp", "mesh": "quad", "material": "glow", "position": [0, 1.0, 0]}],
                  {"grey": {"albedo": [0.5, 0.5, 0.5]}, "glow": {"albedo": [0, 0, 0], "emission": [1, 1, 1]}})
    assert not split_path.supports(glow, glow.default)
    frame = ref.load_frame(glow, glow.default, 16, 16)
    full, direct, how = frame.full_and_direct(4, 2)
    assert how == split_path.TWO_PASSES
    np.testing.assert_array_equal(full, frame.full(4, 2))
    np.testing.assert_array_equal(direct, frame.direct(4, 2))
    np.testing.assert_array_equal(frame.full_light(4, 2), full)
