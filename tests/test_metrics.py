"""Image metrics against reference implementations (scikit-image, flip-evaluator) and at their extremes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diviewer import metrics


def _image(seed: int, shape=(32, 40, 3), scale: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]] / 16.0
    smooth = 0.5 + 0.4 * np.sin(xx + 2 * yy)[..., None] * np.array([1.0, 0.7, 0.4])[: shape[2]]
    return scale * (smooth + 0.05 * rng.standard_normal(shape))


@pytest.mark.parametrize("channels", [1, 3])
def test_ssim_matches_scikit_image(channels):
    skm = pytest.importorskip("skimage.metrics")
    a = _image(0, (48, 40, channels))
    b = a + 0.1 * np.random.default_rng(1).standard_normal(a.shape)
    ours = metrics.ssim(a, b, data_range=1.0)
    theirs = skm.structural_similarity(a, b, data_range=1.0, channel_axis=-1, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False)
    assert abs(ours - theirs) < 1e-3
    assert 0.2 < ours < 0.95  # a real difference, not a trivial agreement at 1


def test_ssim_extremes_stay_in_range_and_finite():
    a = _image(2)
    const = np.full_like(a, 0.3)
    assert metrics.ssim(const, const) == pytest.approx(1.0)
    assert metrics.ssim(np.zeros_like(a), np.zeros_like(a)) == pytest.approx(1.0)
    for ref, test in [(np.zeros_like(a), a), (a, np.zeros_like(a)), (const, a), (a, -a), (a * 1e150, a * 1.01e150),
                      (a * 1e-200, a), (a * 1e300, np.zeros_like(a))]:
        s = metrics.ssim(ref, test)
        assert math.isfinite(s) and -1.0 <= s <= 1.0
    # scale invariance when the data range scales along: the huge case is the unit case
    assert metrics.ssim(a * 1e150, a * 1.01e150, data_range=1e150) == pytest.approx(metrics.ssim(a, a * 1.01), abs=1e-9)
    assert metrics.psnr(a, a) == math.inf


def test_flip_matches_flip_evaluator_and_labels_modes():
    flip_evaluator = pytest.importorskip("flip_evaluator")
    ref = np.abs(_image(3)).astype(np.float32)
    test = np.abs(ref * 1.2 + 0.02).astype(np.float32)
    _, expected_hdr, _ = flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False)
    assert metrics.flip(ref, test, "HDR") == pytest.approx(expected_hdr, abs=1e-5)
    ldr_ref, ldr_test = np.clip(ref, 0, 1), np.clip(test, 0, 1)
    _, expected_ldr, _ = flip_evaluator.evaluate(ldr_ref, ldr_test, "LDR", applyMagma=False)
    assert metrics.flip(ldr_ref, ldr_test, "LDR") == pytest.approx(expected_ldr, abs=1e-5)
    assert 0 < expected_ldr < 1 and 0 < expected_hdr < 1
    with pytest.raises(ValueError):
        metrics.flip(ref, test, "SDR")


@pytest.mark.slow
def test_flip_extremes():
    pytest.importorskip("flip_evaluator")
    a = np.abs(_image(4)).astype(np.float32)
    black = np.zeros_like(a)
    assert metrics.flip(a, a, "HDR") == 0.0 and metrics.flip(black, black, "HDR") == 0.0
    for ref, test in [(black, a), (a, black), (a * 1e-30, a * 1.1e-30), (a * 1e30, a * 1.1e30), (a, -a)]:
        for mode in metrics.FLIP_MODES:
            v = metrics.flip(ref, test, mode)
            assert math.isfinite(v) and 0.0 <= v <= 1.0
    assert metrics.flip(black, a, "HDR") > 0.1  # light where the reference has none is a visible error
    # HDR-FLIP picks its exposures from the reference, so a common scale does not change it
    assert metrics.flip(a * 1e30, a * 1.1e30, "HDR") == pytest.approx(metrics.flip(a, a * 1.1, "HDR"), abs=1e-4)


def _flat_gbuffer(h=32, w=32):
    depth = np.full((h, w), 2.0)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    albedo = np.full((h, w, 3), 0.73)
    return depth, normal, albedo


def test_flat_mask_keeps_planes_and_drops_edges():
    depth, normal, albedo = _flat_gbuffer()
    yy, xx = np.mgrid[0:32, 0:32]
    depth = 1.0 / (0.5 + 0.01 * xx + 0.003 * yy)  # a tilted plane under perspective: 1/z affine
    albedo[:, 20:] = (0.63, 0.065, 0.05)  # a material edge
    depth[:8] = 0.0  # background
    m = metrics.flat_mask(depth, normal, albedo)
    assert m[10:30, 2:18].all()
    assert not m[:9].any() and not m[:, 19:21].any() and not m[:, 0].any() and not m[-1].any()
    direct = np.full((32, 32, 3), 0.8)
    direct[:, :10] = 0.0  # a shadow edge between columns 9 and 10
    with_light = metrics.flat_mask(depth, normal, albedo, direct)
    assert not with_light[:, 9:11].any() and with_light[10:30, 2:8].all() and with_light[10:30, 12:18].all()
    curved = 1.0 / (0.5 + 0.01 * xx + 0.003 * yy + 0.05 * ((xx - 16.0) / 16.0) ** 2)  # a bulge is not a plane
    assert not metrics.flat_mask(curved, normal, albedo)[12:28, 4:12].any()


def test_checkerboard_ratio_sees_a_checker_and_gives_one_for_identical_images():
    depth, normal, albedo = _flat_gbuffer()
    mask = metrics.flat_mask(depth, normal, albedo)
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:32, 0:32]
    reference = 0.4 + 0.2 * xx[..., None] / 32 + 0.002 * rng.standard_normal((32, 32, 3))  # ramp + MC noise
    checker = 0.02 * (((xx + yy) % 2) * 2 - 1)[..., None]
    assert metrics.checkerboard_ratio(reference, reference, mask) == 1.0
    assert metrics.checkerboard_ratio(reference + checker, reference, mask) > 20.0
    stripes = 0.02 * ((xx % 2) * 2 - 1)[..., None]
    assert metrics.checkerboard_ratio(reference + stripes, reference, mask) > 20.0
    smooth = 0.4 + 0.2 * xx[..., None] / 32 + 0 * reference  # the ramp alone: less power than the noise
    assert metrics.checkerboard_ratio(smooth, reference, mask) < 0.01
    assert metrics.checkerboard_ratio(smooth, smooth, mask) == 1.0
    assert metrics.checkerboard_ratio(reference, np.full_like(reference, 0.5), mask) == math.inf


@pytest.mark.parametrize("k", [1.0, 0.5])
def test_equivalent_spp_on_known_error_curves(k):
    ladder = [1, 4, 16, 64, 256]
    err = [0.3 / s ** k for s in ladder]  # Monte-Carlo: MSE ~ 1/spp (k = 1); RMSE-like (k = 0.5)
    for true in (1.0, 2.5, 37.0, 100.0, 256.0):
        r = metrics.equivalent_spp(ladder, err, 0.3 / true ** k)
        assert r["bound"] == "=" and r["spp"] == pytest.approx(true, rel=1e-9)
    assert metrics.equivalent_spp(ladder, err, 0.3 / 37.0 ** k)["text"] == "37"
    assert metrics.equivalent_spp(ladder, err, 0.3 / 1000 ** k) == {"spp": 256.0, "bound": ">=", "text": ">= 256"}
    assert metrics.equivalent_spp(ladder, err, 0.6) == {"spp": 1.0, "bound": "<", "text": "< 1"}


def test_equivalent_spp_from_psnr_and_non_monotone_ladders():
    ladder = [1, 4, 16, 64, 256]
    psnrs = [20.0, 26.0, 32.0, 38.0, 44.0]  # +6 dB per 4x: PSNR linear in log spp
    r = metrics.equivalent_spp(ladder, [metrics.psnr_error(p) for p in psnrs], metrics.psnr_error(35.0))
    assert r["spp"] == pytest.approx(32.0)  # halfway between 16 and 64 in log spp
    r = metrics.equivalent_spp([1, 4, 16], [1.0, 0.2, 0.3], 0.25)  # noise made 16 spp worse than 4
    assert r["bound"] == "=" and 1 < r["spp"] < 4
    with pytest.raises(ValueError):
        metrics.equivalent_spp([4, 1], [1.0, 0.5], 0.7)


def test_equivalent_spp_is_read_per_metric_and_ssim_as_its_error():
    """`equivalent` reads every metric of EQUIVALENT_BY off the ladder; SSIM through 1 - SSIM, so a model whose SSIM
    lies between two rungs gets a count between them, and a perfect one none."""
    from diviewer.evaluation.scoring import EQUIVALENT_BY, equivalent

    ladder_spp = [1, 4, 16, 64, 256]
    row = lambda p, q, f: {"psnr_tm": {"mean": p}, "psnr": {"mean": p + 20}, "flip_ldr": {"mean": f},  # noqa: E731
                           "ssim_tm": {"mean": q}}
    ladder = [row(20.0 + 6 * i, 1.0 - 0.8 / 4 ** (i / 2), 0.4 / 2 ** i) for i in range(5)]  # 1 - SSIM ~ 1/sqrt(spp)
    eq = equivalent(row(35.0, 1.0 - 0.8 / 32 ** 0.5, 0.4 / 8), ladder_spp, ladder)
    assert set(eq) == set(EQUIVALENT_BY) and "ssim_tm" in eq
    assert eq["psnr_tm"]["spp"] == pytest.approx(32.0) and eq["ssim_tm"]["spp"] == pytest.approx(32.0)
    assert eq["flip_ldr"]["spp"] == pytest.approx(64.0)  # FLIP 0.4 / sqrt(spp): 0.05 is the 64-spp rung
    assert equivalent(row(35.0, 1.0, 0.05), ladder_spp, ladder)["ssim_tm"] is None  # a perfect SSIM: no count


def test_pooled_bias_is_the_signed_relative_error_of_the_summed_radiance():
    from diviewer.evaluation.evaluate import aggregate, pooled_bias, score_frame

    rng = np.random.default_rng(3)
    truths = [rng.uniform(0.01, 0.3, (16, 16, 3)) for _ in range(3)]
    directs = [0.5 * t for t in truths]
    mask = np.ones((16, 16), bool)
    rows = [score_frame(d + 0.8 * (t - d), t, 1.0, mask, d) for t, d in zip(truths, directs)]
    m = aggregate(rows)
    assert m["bias"] == pytest.approx((0.5 + 0.8 * 0.5) - 1.0)  # 0.9 x the truth everywhere
    assert m["bias_indirect"] == pytest.approx(-0.2)
    same = [score_frame(t, t, 1.0, mask) for t in truths]
    assert pooled_bias(same) == 0.0 and pooled_bias(same, "sum_indirect") is None  # no direct light given
    black = np.zeros((16, 16, 3))
    assert pooled_bias([score_frame(truths[0], black, 0.0, mask)]) is None  # nothing to be relative to


def test_masked_psnr_counts_only_the_region():
    a = np.zeros((16, 16, 3))
    b = a.copy()
    b[:, :8] = 0.1  # an error of 0.1 on the left half ...
    b[:, 8:] = 0.5  # ... and of 0.5 on the right half
    left = np.zeros((16, 16), bool)
    left[:, :8] = True
    assert metrics.masked_psnr(a, b, left) == pytest.approx(20.0)  # 10 log10(1 / 0.01)
    assert metrics.masked_psnr(a, b, ~left) == pytest.approx(-20 * math.log10(0.5))
    assert metrics.masked_psnr(a, b, np.ones((16, 16), bool)) == pytest.approx(metrics.psnr(a, b))
    assert metrics.masked_psnr(a, a, left) == math.inf
    assert metrics.masked_psnr(a, b, np.zeros((16, 16), bool)) is None  # an empty region has no score
    assert metrics.masked_psnr(a, b, left.astype(np.float32)[..., None]) == pytest.approx(20.0)  # a mask channel
    with pytest.raises(ValueError):
        metrics.masked_psnr(a, b, left[:8])


def test_masked_ssim_known_answers():
    rng = np.random.default_rng(0)
    a = np.full((32, 32, 3), 0.5)
    b = a.copy()
    b[:, 16:] = rng.uniform(0, 1, (32, 16, 3))  # noise on the right half only
    left = np.zeros((32, 32), bool)
    left[:, :10] = True  # windows centred here (radius 5) never reach column 16
    assert metrics.masked_ssim(a, b, left) == 1.0
    assert metrics.masked_ssim(a, b, ~left) < 0.9
    # A constant offset on a flat region: SSIM's luminance term alone, (2 mu_a mu_b + c1) / (mu_a^2 + mu_b^2 + c1).
    c = a + 0.1
    c1 = 0.01 ** 2
    expected = (2 * 0.5 * 0.6 + c1) / (0.5 ** 2 + 0.6 ** 2 + c1)
    assert metrics.masked_ssim(a, c, left) == pytest.approx(expected, rel=1e-9)
    assert metrics.masked_ssim(a, b, np.ones((32, 32), bool)) == pytest.approx(metrics.ssim(a, b))
    border = np.zeros((32, 32), bool)
    border[:, :5] = True  # no window is centred within 5 pixels of the border
    assert metrics.masked_ssim(a, b, border) is None


def test_regions_and_below_direct_share_on_a_synthetic_frame():
    from diviewer.evaluation.scoring import below_direct, regions, score_frame_regions

    direct = np.zeros((16, 16, 3))
    direct[:8] = 0.5  # the top half is lit
    obj = np.zeros((16, 16, 1), np.float32)
    obj[4:12, 4:12] = 1  # the object straddles the shadow line
    truth = direct + 0.2
    frame = {"direct": direct, "object": obj, "pt": truth}
    masks = regions(frame, exposure=1.0)
    assert masks["object"].sum() == 64 and masks["object_unlit"].sum() == 32
    assert not masks["object_unlit"][:8].any()
    assert masks["lit"][:8].all() and not masks["lit"][8:].any() and (masks["shade"] == ~masks["lit"]).all()
    assert set(regions({"direct": direct, "pt": truth}, 1.0)) == {"lit", "shade"}  # no object mask: the frame's two
    good = truth.copy()
    good[masks["object_unlit"]] += 0.01  # small error only in the object's shade
    row = score_frame_regions(good, frame, 1.0, np.ones((16, 16), bool))
    row_direct = score_frame_regions(direct, frame, 1.0, np.ones((16, 16), bool))
    assert row["pixels_object_unlit"] == 32 and row["psnr_tm_object_unlit"] < row["psnr_tm_object"] < math.inf
    assert row["psnr_tm_object_unlit"] > row_direct["psnr_tm_object_unlit"]
    bad = dict(row, psnr_tm_object_unlit=row_direct["psnr_tm_object_unlit"] - 1)
    share = below_direct([row, bad], [row_direct, row_direct])
    assert share["frame"] == {"share": 0.0, "frames": 2}
    assert share["object_unlit"] == {"share": 0.5, "frames": 2}
    assert row["pixels_shade"] == 128 and row["psnr_tm_lit"] == math.inf  # the error is in the shade only
    assert row_direct["psnr_tm_shade"] < row["psnr_tm_shade"] < math.inf and share["shade"]["share"] == 0.0
    assert "object" not in below_direct([dict(row, psnr_tm_object=None)], [row_direct])  # a frame without the region


def _textured_frame(seed: int = 0, size: int = 128):
    """A smooth irradiance over a random texture, the albedo the G-buffer gives, and geometry everywhere."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0:size]
    irradiance = 0.2 + 0.1 * np.sin(xx / 20.0) + 0.05 * np.cos(yy / 13.0)
    albedo = np.full((size, size, 3), 0.5) * (0.6 + 0.4 * rng.random((size, size)))[..., None]
    return irradiance[..., None] * albedo, albedo, np.ones((size, size)), (yy, xx)


def test_stride_pattern_reads_a_grid_locked_pattern_and_not_texture_or_noise():
    image, albedo, depth, (yy, xx) = _textured_frame()
    rng = np.random.default_rng(1)
    checker = np.where((yy + xx) % 2 == 0, 1.1, 0.9)[..., None]  # +-10 % on every pixel: RMS 0.1
    stripes = (1 + 0.05 * np.cos(2 * np.pi * xx / 4))[..., None]  # period 4, amplitude 5 %: RMS 0.035
    noisy = image * (1 + 0.5 * rng.standard_normal(image.shape[:2]))[..., None]  # a path tracer's noise, 50 %
    assert metrics.stride_pattern(image, albedo, depth) < 0.005  # texture and smooth shading: nothing grid-locked
    assert metrics.stride_pattern(image * checker, albedo, depth) == pytest.approx(0.1, abs=0.005)
    assert metrics.stride_pattern(image * stripes, albedo, depth) == pytest.approx(0.05 / math.sqrt(2), abs=0.004)
    assert metrics.stride_pattern(noisy, albedo, depth) < 0.01  # the noise the phase means keep is taken out
    assert metrics.stride_pattern(noisy * checker, albedo, depth) == pytest.approx(0.1, abs=0.015)
    # The mask (the frame's shade) and the geometry choose the pixels read; too few to read gives None.
    half = np.zeros(depth.shape, bool)
    half[:, 64:] = True
    patterned = image * np.where(half[..., None], checker, 1.0)
    assert metrics.stride_pattern(patterned, albedo, depth, half) == pytest.approx(0.1, abs=0.005)
    assert metrics.stride_pattern(patterned, albedo, depth, ~half) < 0.005
    assert metrics.stride_pattern(image, albedo, np.zeros_like(depth)) is None
    assert metrics.stride_pattern(image[:16, :16], albedo[:16, :16], depth[:16, :16]) is None
    # A black image has no relative pattern, nor one black over half its pixels (direct light in the shade, but for
    # a few shadow edges); a firefly weighs no more than the clip allows.
    assert metrics.stride_pattern(np.zeros_like(image), albedo, depth) is None
    edges = np.zeros_like(image)
    edges[:, 60:68] = image[:, 60:68] * checker[:, 60:68]
    assert metrics.stride_pattern(edges, albedo, depth) is None
    hot = image.copy()
    hot[40, 40] = 1e6
    assert metrics.stride_pattern(hot, albedo, depth) < 0.02


def test_stride_pattern_is_scored_in_the_shade_and_pooled_per_split():
    from diviewer.evaluation.scoring import PER_FRAME_KEYS, aggregate, score_frame_regions

    image, albedo, depth, (yy, xx) = _textured_frame()
    direct = np.zeros_like(image)
    direct[:, :48] = 1.0  # lit on the left: the shade is the rest, 80 columns
    checker = np.where((yy + xx) % 2 == 0, 1.2, 0.8)[..., None]
    frame = {"pt": image + direct, "direct": direct, "albedo": albedo, "depth": depth}
    flat = np.ones(depth.shape, bool)
    rows = [score_frame_regions(im, frame, 1.0, flat) for im in (image * checker + direct, 1.01 * image + direct)]
    assert rows[0]["stride_shade"] == pytest.approx(0.2, abs=0.01) and rows[1]["stride_shade"] < 0.005
    pooled = aggregate(rows)["stride_shade"]
    assert pooled["frames"] == 2 and pooled["max"] == rows[0]["stride_shade"]
    assert pooled["mean"] == pytest.approx((rows[0]["stride_shade"] + rows[1]["stride_shade"]) / 2)
    assert "stride_shade" in PER_FRAME_KEYS
    # Without the G-buffer (a caller's frame of truth and direct light alone) nothing is read or pooled.
    bare = score_frame_regions(1.01 * image + direct, {"pt": image + direct, "direct": direct}, 1.0, flat)
    assert "stride_shade" not in bare and aggregate([bare])["stride_shade"] is None


def test_per_frame_keeps_each_frame_with_its_index_or_nothing_when_rows_are_missing():
    from diviewer.evaluation.scoring import PER_FRAME_KEYS, per_frame

    rows = [{k: float(i) for k in (*PER_FRAME_KEYS, "mse")} for i in range(3)]
    kept = per_frame([4, 7, 9], rows)
    assert [r["index"] for r in kept] == [4, 7, 9] and kept[1]["psnr_tm"] == 1.0
    assert "mse" not in kept[0] and set(kept[0]) == {"index", *PER_FRAME_KEYS}
    assert per_frame([4, 7, 9], rows[:2]) is None  # a model refused part-way: no pairing to guess
