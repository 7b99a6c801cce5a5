"""The truth's indirect light filtered over each surface: what the filter keeps (flat and linear light, edges across
creases and steps, pixels without geometry, the direct light), what it removes (noise on a surface), its settings'
refusals, and the derived dataset (its own identity, every other channel as captured, resumable, refusals named)."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.cli import main
from diviewer.data.capture import CaptureSettings, build_manifest, capture
from diviewer.data.dataset import Dataset, identity
from diviewer.data.truth_filter import (TruthFilter, filter_dataset, filter_irradiance, filter_truth,
                                        truth_filter_manifest, view_positions)
from diviewer.errors import DiviewerError
from diviewer.scene import load_scene
from diviewer.train.targets import ALBEDO_FLOOR

TINY = dict(width=32, height=32, spp=4, max_depth=4)
QUIET = dict(log=lambda *_: None)
H = W = 24
FOV = 60.0


def wall(depth: float = 3.0, h: int = H, w: int = W) -> tuple[np.ndarray, np.ndarray]:
    """A wall facing the camera at ``depth``: its normal (view space) and depth planes."""
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    return normal, np.full((h, w), depth, np.float32)


def test_flat_and_linear_light_on_a_plane_pass_unchanged_away_from_the_frame_edge():
    normal, depth = wall()
    flat = np.full((H, W, 3), 0.7, np.float32)
    np.testing.assert_allclose(filter_irradiance(flat, normal, depth, FOV, TruthFilter(levels=3)), flat, rtol=1e-5)
    ramp = np.broadcast_to(np.linspace(0.0, 1.0, W, dtype=np.float32)[None, :, None], (H, W, 3)).copy()
    out = filter_irradiance(ramp, normal, depth, FOV, TruthFilter(levels=2))
    np.testing.assert_allclose(out[6:-6, 6:-6], ramp[6:-6, 6:-6], atol=1e-5)  # the symmetric kernel keeps a slope


def test_noise_on_a_surface_falls_with_each_level():
    normal, depth = wall()
    rng = np.random.default_rng(0)
    noisy = 1.0 + rng.normal(0.0, 0.2, (H, W, 3)).astype(np.float32)
    spread = [float(np.std(filter_irradiance(noisy, normal, depth, FOV, TruthFilter(levels=n))[4:-4, 4:-4]))
              for n in (1, 2)]
    assert spread[0] < 0.2 / 3 and spread[1] < spread[0] * 0.6  # 5x5 B3 taps: noise x ~0.27, then less
    assert abs(float(filter_irradiance(noisy, normal, depth, FOV)[4:-4, 4:-4].mean()) - 1.0) < 0.02


def test_light_does_not_cross_a_crease_nor_a_step_in_depth():
    normal, depth = wall()
    normal[:, W // 2:] = [1.0, 0.0, 0.0]  # a wall at right angles: the crease
    light = np.zeros((H, W, 3), np.float32)
    light[:, :W // 2] = 1.0
    np.testing.assert_array_equal(filter_irradiance(light, normal, depth, FOV, TruthFilter(levels=3)), light)
    normal, depth = wall()
    depth[:, W // 2:] = 6.0  # the same orientation, twice as far: a step
    out = filter_irradiance(light, normal, depth, FOV, TruthFilter(levels=3))
    np.testing.assert_allclose(out, light, atol=1e-6)


def test_a_tilted_plane_still_smooths_and_the_plane_distance_scales_with_depth():
    rng = np.random.default_rng(1)
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 1:] = [np.sin(1.0), np.cos(1.0)]  # a floor seen at a grazing angle: depth varies along y
    # points on the plane n.(p - p0) = 0 through (0, 0, -5): depth where the pixel's ray meets it
    pos = view_positions(np.ones((H, W), np.float32), FOV)
    depth = (5.0 * normal[..., 2] / np.sum(normal * -pos, axis=-1)).astype(np.float32)
    assert np.all(depth > 0) and np.ptp(depth) > 1.0
    noisy = 1.0 + rng.normal(0.0, 0.2, (H, W, 3)).astype(np.float32)
    out = filter_irradiance(noisy, normal, depth, FOV)
    assert float(np.std(out[4:-4, 4:-4])) < 0.2 / 3  # neighbours on the same plane keep their weight


def test_the_range_term_keeps_an_edge_of_the_light_within_a_surface_and_still_smooths_its_noise():
    normal, depth = wall()
    rng = np.random.default_rng(3)
    light = np.full((H, W, 3), 0.2, np.float32)
    light[:, :W // 2] = 1.0  # one wall, a patch of bounced light on its left half
    noisy = light * (1.0 + rng.normal(0.0, 0.05, (H, W, 3))).astype(np.float32)
    plain = filter_irradiance(noisy, normal, depth, FOV, TruthFilter(levels=2))
    ranged = filter_irradiance(noisy, normal, depth, FOV, TruthFilter(levels=2, range_sigma=0.6))
    edge = np.s_[4:-4, W // 2 - 3:W // 2 + 3]
    err = lambda out: float(np.sqrt(np.mean((out[edge] - light[edge]) ** 2)))  # noqa: E731
    assert err(ranged) < 0.6 * err(plain)  # geometry alone blurs the edge; the guide, blurred by one level, less
    inside = np.s_[4:-4, 3:W // 2 - 5]
    assert float(np.std(ranged[inside])) < float(np.std(noisy[inside])) / 2.5  # noise of 5 % within 0.6 x the mean
    np.testing.assert_array_equal(filter_irradiance(noisy, normal, depth, FOV, TruthFilter(levels=2, range_sigma=0.0)),
                                  plain)


def test_filter_truth_keeps_the_direct_light_and_pixels_without_geometry():
    normal, depth = wall()
    depth[:4] = 0.0  # sky
    rng = np.random.default_rng(2)
    albedo = np.full((H, W, 3), 0.5, np.float32)
    albedo[:, :3] = 0.0  # black texels: divided by the floor, multiplied back by it
    direct = rng.uniform(0.0, 2.0, (H, W, 3)).astype(np.float32)
    indirect = 0.3 + rng.normal(0.0, 0.05, (H, W, 3)).astype(np.float32)
    pt = direct + indirect
    out = filter_truth(pt, direct, albedo, normal, depth, FOV)
    np.testing.assert_array_equal(out[:4], pt[:4])
    e = (out - direct)[4:] / np.maximum(albedo[4:], ALBEDO_FLOOR)
    assert np.std(e[4:-4, 8:-4]) < np.std((indirect / 0.5)[8:-4, 8:-4]) / 2
    flat = direct + np.maximum(albedo, ALBEDO_FLOOR) * 0.5  # one irradiance under every texture
    np.testing.assert_allclose(filter_truth(flat, direct, albedo, normal, depth, FOV)[4:], flat[4:], rtol=1e-5)


@pytest.mark.parametrize("table, field", [({"levels": 0}, "levels"), ({"levels": 2.0}, "levels"),
                                          ({"normal_power": -1.0}, "normal_power"), ({"plane": 0.0}, "plane"),
                                          ({"plane": float("nan")}, "plane"), ({"radius": 2}, "radius"),
                                          ({"range_sigma": -0.1}, "range_sigma")])
def test_settings_out_of_range_are_refused_by_name(table, field):
    with pytest.raises(DiviewerError) as err:
        TruthFilter.from_dict(table, "capture.truth_filter")
    assert field in str(err.value) and "capture.truth_filter" in str(err.value)
    with pytest.raises(DiviewerError, match="must be a table"):
        TruthFilter.from_dict(3, "capture.truth_filter")
    assert TruthFilter.from_dict({"levels": 2}).record() == {"levels": 2, "normal_power": 32.0, "plane": 0.01}
    ranged = TruthFilter.from_dict({"levels": 2, "range_sigma": 0.6})
    assert ranged.record() == {"levels": 2, "normal_power": 32.0, "plane": 0.01, "range_sigma": 0.6}
    assert TruthFilter.from_dict(ranged.record()) == ranged  # a card's record reads back as the recipe's table


@pytest.mark.parametrize("argv, option", [(["--levels", "0"], "--levels"), (["--plane", "nan"], "--plane"),
                                          (["--normal-power", "-2"], "--normal-power"),
                                          (["--range-sigma", "-1"], "--range-sigma")])
def test_the_command_refuses_a_setting_out_of_range_in_one_line_naming_the_option(tmp_path, capsys, argv, option):
    assert main(["data", "filter-truth", str(tmp_path / "none"), "--out", str(tmp_path / "out")] + argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{option}: " in err[0] and not (tmp_path / "out").exists()


def test_the_record_is_part_of_the_identity():
    m = build_manifest(load_scene("cornell"), CaptureSettings(frames=4, **TINY))
    assert "truth_filter" not in identity(m)
    assert identity({**m, "truth_filter": {"levels": 1}})["truth_filter"] == {"levels": 1}


@pytest.mark.mitsuba
def test_filtered_dataset_changes_only_the_full_image_and_resumes(gl_context, tmp_path):
    src, out = tmp_path / "src", tmp_path / "filtered"
    capture("cornell", src, CaptureSettings(frames=3, seed=1, **TINY), **QUIET)
    summary = filter_dataset(src, out, TruthFilter(levels=2), **QUIET)
    assert summary["present"] == 3 and summary["filtered"] == 3
    a, b = Dataset(src), Dataset(out)
    rec = b.manifest["truth_filter"]
    assert b.check() == [] and b.hash != a.hash and rec["from_hash"] == a.hash and rec["levels"] == 2
    assert b.manifest["truth_filter_from"] == str(src)
    scene = load_scene("cornell")
    from diviewer.scene.loader import config_from_dict

    changed = 0.0
    for f in a.frames:
        fa, fb = a.load(f["index"]), b.load(f["index"])
        for name in ("depth", "normal", "albedo", "direct", "pt_direct"):
            np.testing.assert_array_equal(fa[name], fb[name])
        fov = config_from_dict(scene, f["config"]).camera.fov
        expect = filter_truth(fa["pt"], fa["pt_direct"], fa["albedo"], fa["normal"], fa["depth"], fov,
                              TruthFilter(levels=2)).astype(np.float16).astype(np.float32)
        np.testing.assert_array_equal(fb["pt"], expect)
        changed += float(np.abs(fb["pt"] - fa["pt"]).sum())
    assert changed > 0.0  # 4 spp: the truth is noisy, the filter changes it
    assert filter_dataset(src, out, TruthFilter(levels=2), **QUIET)["filtered"] == 0  # resumed: nothing left
    with pytest.raises(DiviewerError, match="filtered already") as err:
        truth_filter_manifest(b, TruthFilter())
    assert "truth_filter" in str(err.value)
    with pytest.raises(DiviewerError, match="both the source and the output"):
        filter_dataset(src, src, **QUIET)
    with pytest.raises(DiviewerError, match="differs in: truth_filter"):  # the folder holds another filter's dataset
        filter_dataset(src, out, TruthFilter(levels=1), **QUIET)
    assert main(["data", "filter-truth", str(src), "--levels", "2", "--out", str(out)]) == 0
