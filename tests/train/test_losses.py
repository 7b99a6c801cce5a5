"""Tests for diviewer.train.losses: values on hand-made tensors, and which statistic of a noisy
target each reconstruction loss is minimised at (mean, median, or a log-domain mean)."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diviewer.contract.encoding import Encoding  # noqa: E402
from diviewer.train.encoding_torch import decode_radiance, encode_radiance  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.train import networks  # noqa: E402
from diviewer.train.losses import (  # noqa: E402
    GANLoss,
    LossConfig,
    SSIM_EXPOSURES,
    exposed_radiance,
    metered_exposure_torch,
    reconstruction_loss,
    ssim_torch,
    structure_loss,
    tonemap_torch,
)

ENC = Encoding(exposure=2.0, depth_scale=10.0)

# One pixel's Monte-Carlo samples: ten dark ones and one firefly (right-skewed, like path tracing).
SAMPLES = np.array([0.1] * 10 + [10.0])
MEAN, MEDIAN = float(SAMPLES.mean()), float(np.median(SAMPLES))  # 1.0 and 0.1


def _encoded(x) -> torch.Tensor:
    return encode_radiance(torch.as_tensor(np.asarray(x, np.float64), dtype=torch.float32), ENC)


def test_gan_loss_moved_and_re_exported() -> None:
    assert networks.GANLoss is GANLoss
    lsgan = GANLoss(gan_mode="lsgan")
    pred = torch.tensor([[0.0, 2.0]])
    assert lsgan(pred, True).item() == pytest.approx((1.0 + 1.0) / 2)  # (0-1)^2, (2-1)^2
    assert lsgan(pred, False).item() == pytest.approx((0.0 + 4.0) / 2)
    assert GANLoss()(torch.zeros(1, 1, 2, 2), True).item() == pytest.approx(np.log(2), rel=1e-6)
    with pytest.raises(ValueError, match="gan_mode"):
        GANLoss(gan_mode="wgan")


def test_exposed_radiance_is_decode_times_exposure_with_a_gradient_at_zero() -> None:
    y = torch.linspace(-1.2, 1.2, 241)
    expected = decode_radiance(y, ENC) * ENC.exposure
    np.testing.assert_allclose(exposed_radiance(y, ENC).numpy(), expected.numpy(), rtol=1e-5, atol=1e-7)
    zero = torch.zeros(3, requires_grad=True)
    exposed_radiance(zero, ENC).sum().backward()
    # slope of the curve at 0 is log1p(R): the loss still pulls an output sitting exactly at 0
    np.testing.assert_allclose(zero.grad.numpy(), np.log1p(ENC.radiance_max), rtol=1e-6)


def test_loss_values_on_hand_made_tensors() -> None:
    fake_lin = torch.tensor([[0.0, 1.0], [2.0, 0.5]])
    real_lin = torch.tensor([[1.0, 1.0], [0.0, 0.25]])
    fake, real = encode_radiance(fake_lin, ENC), encode_radiance(real_lin, ENC)
    e = ENC.exposure
    d_lin = (fake_lin - real_lin) * e
    l1, l2 = (reconstruction_loss(fake, real, mode, "linear", ENC).item() for mode in ("l1", "l2"))
    assert l1 == pytest.approx(d_lin.abs().mean().item(), rel=1e-5)
    assert l2 == pytest.approx((d_lin**2).mean().item(), rel=1e-5)
    d_enc = fake - real
    assert reconstruction_loss(fake, real).item() == pytest.approx(d_enc.abs().mean().item(), rel=1e-6)
    assert reconstruction_loss(fake, real, "l2").item() == pytest.approx((d_enc**2).mean().item(), rel=1e-6)
    # the paper's default is L1 on the encoded values; float16 inputs are promoted (AMP)
    assert reconstruction_loss(fake.half(), real).dtype == torch.float32
    assert reconstruction_loss(real, real, "l2", "linear", ENC).item() == 0.0


def test_refusals() -> None:
    x = torch.zeros(2)
    with pytest.raises(ValueError, match="mode"):
        reconstruction_loss(x, x, "huber")
    with pytest.raises(ValueError, match="space"):
        reconstruction_loss(x, x, "l1", "cubic")
    with pytest.raises(ValueError, match="encoding"):
        reconstruction_loss(x, x, "l2", "linear")
    with pytest.raises(DiviewerError, match="loss.space"):
        LossConfig(space="cubic")
    with pytest.raises(DiviewerError, match="loss.reconstruction"):
        LossConfig(reconstruction="l3")
    with pytest.raises(DiviewerError, match="loss.gan_mode"):
        LossConfig(gan_mode="hinge")
    with pytest.raises(DiviewerError, match="unknown key"):
        LossConfig.from_dict({"reconstruction": "l1", "weight": 1.0})


def test_loss_config_round_trip_and_dispatch() -> None:
    config = LossConfig(reconstruction="l2", space="linear", gan_mode="lsgan")
    assert LossConfig.from_dict(config.to_dict()) == config
    assert LossConfig.from_dict({}) == LossConfig()  # older checkpoints: the paper's L1 + vanilla GAN
    fake, real = _encoded([0.3, 2.0]), _encoded([0.1, 1.0])
    expected = reconstruction_loss(fake, real, "l2", "linear", ENC).item()
    assert config.reconstruction_loss(fake, real, ENC).item() == expected
    assert config.gan_loss().gan_mode == "lsgan"


def _minimiser(mode: str, space: str) -> float:
    """The linear radiance a constant prediction must take to minimise the loss over SAMPLES."""
    real = _encoded(SAMPLES)
    # a grid over the encoded range that holds the samples, then a finer one around its best point
    lo, hi = float(_encoded(0.05)), float(_encoded(12.0))
    for _ in range(2):
        grid = torch.linspace(lo, hi, 401)
        losses = torch.stack([reconstruction_loss(g.expand_as(real), real, mode, space, ENC) for g in grid])
        best = int(torch.argmin(losses))
        lo, hi = float(grid[max(best - 1, 0)]), float(grid[min(best + 1, len(grid) - 1)])
    return float(decode_radiance(grid[best], ENC))


def _gradient_at(value: float, mode: str, space: str) -> float:
    real = _encoded(SAMPLES)
    p = _encoded(value).clone().requires_grad_(True)
    reconstruction_loss(p.expand_as(real), real, mode, space, ENC).backward()
    return float(p.grad)


def test_l2_on_linear_radiance_is_minimised_at_the_mean() -> None:
    assert _minimiser("l2", "linear") == pytest.approx(MEAN, rel=2e-3)
    assert abs(_gradient_at(MEAN, "l2", "linear")) < 1e-4  # stationary there
    assert _gradient_at(0.9 * MEAN, "l2", "linear") < 0 < _gradient_at(1.1 * MEAN, "l2", "linear")


@pytest.mark.parametrize("space", ["encoded", "linear"])
def test_l1_is_minimised_at_the_median_darker_than_the_mean(space: str) -> None:
    assert _minimiser("l1", space) == pytest.approx(MEDIAN, rel=2e-3)
    assert MEDIAN < 0.2 * MEAN  # the firefly's energy is lost: biased dark


def test_l2_on_encoded_values_is_minimised_at_a_log_domain_mean() -> None:
    log_mean = float(decode_radiance(_encoded(SAMPLES).mean(), ENC))  # the mean taken in the encoded domain
    got = _minimiser("l2", "encoded")
    assert got == pytest.approx(log_mean, rel=2e-3)
    assert MEDIAN < got < 0.5 * MEAN  # biased dark (Jensen), between the median and the mean here


def test_log_space_counts_errors_relative_to_the_pixel() -> None:
    """A 10 % error costs the same in a dark pixel as in a bright one (well above LOG_EPSILON), and the
    value is L1 between log(epsilon + exposed radiance)."""
    from diviewer.train.losses import LOG_EPSILON

    e = ENC.exposure
    dark, bright = 0.5 / e, 50.0 / e  # exposed radiance 0.5 and 50
    costs = [reconstruction_loss(_encoded([x * 1.1]), _encoded([x]), "l1", "log", ENC).item() for x in (dark, bright)]
    expected = [abs(np.log(1.1 * x * e + LOG_EPSILON) - np.log(x * e + LOG_EPSILON)) for x in (dark, bright)]
    np.testing.assert_allclose(costs, expected, rtol=1e-4)
    assert costs[0] == pytest.approx(costs[1], rel=0.03)
    # on the encoded values (linear below ~1) the dark pixel's 10 % costs ~3x less than the bright one's
    enc = [reconstruction_loss(_encoded([x * 1.1]), _encoded([x]), "l1", "encoded", ENC).item() for x in (dark, bright)]
    assert enc[0] < enc[1] / 2
    # negative (noise) targets clamp to zero rather than producing NaN
    assert np.isfinite(reconstruction_loss(_encoded([-0.3]), _encoded([0.2]), "l1", "log", ENC).item())
    with pytest.raises(ValueError, match="needs the encoding"):
        reconstruction_loss(_encoded([1.0]), _encoded([1.0]), "l1", "log")


def _lognormal_frames(n: int = 3000, side: int = 4, seed: int = 0) -> torch.Tensor:
    """Encoded frames (n, 1, side, side) of a flat true value under right-skewed noise: each pixel lognormal with
    sigma 1, its median 61 % of its mean of 1 (at 64 spp Sponza's deep shade is 27-53 % dark at the median)."""
    rng = np.random.default_rng(seed)
    x = rng.lognormal(-0.5, 1.0, (n, 1, side, side))  # mean exp(-0.5 + 0.5) = 1
    return _encoded(x / ENC.exposure)


def _constant_fixed_point(real: torch.Tensor, space: str) -> float:
    """The exposed radiance at which gradient descent on a flat prediction stops (the loss's gradient changes sign;
    the "levels" detail weight is not differentiated, so the loss's value is not what descent minimises)."""
    def slope(v: float) -> float:
        p = _encoded(v / ENC.exposure).clone().requires_grad_(True)
        reconstruction_loss(p.expand_as(real), real, "l1", space, ENC).backward()
        return float(p.grad)

    lo, hi = 0.2, 2.0
    assert slope(lo) < 0 < slope(hi)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slope(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def test_levels_l1_sets_a_blocks_level_near_its_noisy_targets_mean() -> None:
    """L1 on each pixel goes to a pixel's median (61 % of the mean here); L1 on the 4x4 blocks' means goes to the
    median of a block's mean of 16 pixels, 94 % of it; the detail term cannot move a flat prediction's level."""
    real = _lognormal_frames()
    assert _constant_fixed_point(real, "encoded") == pytest.approx(0.61, abs=0.03)
    assert _constant_fixed_point(real, "levels") == pytest.approx(0.94, abs=0.03)


def test_gradient_descent_on_an_image_under_levels_l1_keeps_its_level_in_the_shade_and_in_the_sun() -> None:
    """A free 16x16 image fitted by Adam (its rate annealed) to fresh noisy copies of a truth with a dark and a bright
    half (each pixel times lognormal noise of mean 1, median 0.61): L1 on the encoded values ends 35-40 % dark in both
    halves, as its pixels' medians; the levels space ends within 12 % of the truth in both."""
    torch.manual_seed(0)
    yy, xx = torch.meshgrid(torch.linspace(0, 1, 16), torch.linspace(0, 1, 16), indexing="ij")
    truth = (0.05 + 2.0 * (xx > 0.5).float() + 0.3 * torch.sin(6 * yy)).clamp_min(0.02)  # exposed radiance
    halves = (xx <= 0.5, xx > 0.5)
    ratios = {}
    for space in ("encoded", "levels"):
        p = encode_radiance(torch.full((1, 1, 16, 16), 0.5 / ENC.exposure), ENC).requires_grad_(True)
        opt = torch.optim.Adam([p], lr=5e-3)
        anneal = torch.optim.lr_scheduler.CosineAnnealingLR(opt, 1500)  # settles rather than jitters at the end
        for _ in range(1500):
            noisy = encode_radiance(truth * torch.exp(torch.randn(8, 1, 16, 16) - 0.5) / ENC.exposure, ENC)
            loss = reconstruction_loss(p.expand_as(noisy), noisy, "l1", space, ENC)
            opt.zero_grad()
            loss.backward()
            opt.step()
            anneal.step()
        x = decode_radiance(p.detach(), ENC)[0, 0] * ENC.exposure
        ratios[space] = [float(x[h].mean() / truth[h].mean()) for h in halves]
    assert all(0.55 < r < 0.7 for r in ratios["encoded"])
    assert all(0.88 < r < 1.12 for r in ratios["levels"])


def test_levels_keep_the_detail_and_leave_out_what_the_mask_leaves_out() -> None:
    """The target itself costs nothing; its block means without their detail cost something (the detail term); a
    frame whose last four columns are masked out (stride padding) costs what its first four alone cost, whatever
    the padding holds; sides that are not multiples of the block are refused."""
    from diviewer.train.losses import levels_loss

    real = _lognormal_frames(8, side=8, seed=1)
    fake = _lognormal_frames(8, side=8, seed=2)
    assert levels_loss(real, real, "l1", ENC).item() == pytest.approx(0.0, abs=1e-7)
    blocks = decode_radiance(real, ENC).reshape(8, 1, 2, 4, 2, 4).mean(dim=(3, 5), keepdim=True)
    flat = encode_radiance(blocks.expand(8, 1, 2, 4, 2, 4).reshape(8, 1, 8, 8), ENC)
    assert levels_loss(flat, real, "l1", ENC).item() > 0.01
    mask = torch.ones(1, 1, 8, 8)
    mask[..., 4:] = 0.0
    padded = fake.clone()
    padded[..., 4:] = 5.0
    left = levels_loss(fake[..., :4], real[..., :4], "l1", ENC).item()
    assert levels_loss(padded, real, "l1", ENC, mask).item() == pytest.approx(left, rel=1e-5)
    assert reconstruction_loss(padded, real, "l1", "levels", ENC, mask).item() == pytest.approx(left, rel=1e-5)
    with pytest.raises(ValueError, match="multiples of 4"):
        levels_loss(real[..., :6], real[..., :6], "l1", ENC)
    with pytest.raises(ValueError, match="needs the encoding"):
        reconstruction_loss(real, real, "l1", "levels")


def test_relative_l2_converges_to_the_mean_while_weighing_dark_pixels_like_bright_ones() -> None:
    """Noise2Noise's relative MSE: the weight comes from the prediction alone (not differentiated), so gradient
    descent stops at the noisy target's mean, unlike L1 (the median) or the log space; a 10 % error costs the same
    in a dark pixel as in a bright one."""
    from diviewer.train.losses import REL_EPSILON

    assert abs(_gradient_at(MEAN, "l2", "relative")) < 1e-4  # stationary at the mean: unbiased
    assert _gradient_at(0.9 * MEAN, "l2", "relative") < 0 < _gradient_at(1.1 * MEAN, "l2", "relative")
    assert _gradient_at(MEDIAN, "l2", "relative") < 0  # the median is not a fixed point: it is pushed up
    e = ENC.exposure
    dark, bright = 0.5 / e, 50.0 / e
    costs = [reconstruction_loss(_encoded([x * 1.1]), _encoded([x]), "l2", "relative", ENC).item() for x in (dark, bright)]
    expected = [(0.1 * x * e / (1.1 * x * e + REL_EPSILON)) ** 2 for x in (dark, bright)]
    np.testing.assert_allclose(costs, expected, rtol=1e-3)
    assert costs[0] == pytest.approx(costs[1], rel=0.05)
    assert np.isfinite(reconstruction_loss(_encoded([0.0]), _encoded([0.2]), "l2", "relative", ENC).item())
    with pytest.raises(ValueError, match="needs the encoding"):
        reconstruction_loss(_encoded([1.0]), _encoded([1.0]), "l2", "relative")


def test_ssim_and_tone_map_on_tensors_are_the_metrics_ones() -> None:
    """The structure term's SSIM and tone map are `diviewer.metrics`' (what eval and validation score), on tensors."""
    from diviewer import metrics

    rng = np.random.default_rng(0)
    a, b = rng.random((2, 3, 20, 24)), rng.random((2, 3, 20, 24))
    b[1] = 0.7 * a[1] + 0.3 * b[1]  # one pair alike, one not
    expected = np.mean([metrics.ssim(a[i].transpose(1, 2, 0), b[i].transpose(1, 2, 0)) for i in range(2)])
    got = ssim_torch(torch.as_tensor(a, dtype=torch.float32), torch.as_tensor(b, dtype=torch.float32))
    assert got.item() == pytest.approx(expected, abs=1e-5)
    assert ssim_torch(torch.as_tensor(a), torch.as_tensor(a)).item() == pytest.approx(1.0, abs=1e-6)
    x = rng.random((1, 3, 4, 4)) * 5.0
    assert tonemap_torch(torch.as_tensor(x), 1.7).numpy() == pytest.approx(metrics.tonemap(x, 1.7), rel=1e-6)
    black = torch.zeros(1, 1, 2, 2, requires_grad=True)
    tonemap_torch(black, 1.0).sum().backward()
    assert torch.isfinite(black.grad).all(), "the gamma's slope at black is bounded"


def _batch(target: torch.Tensor, enc: Encoding, pad: int = 0) -> dict:
    """A batch as split_batch gives it for target "indirect" divided by the albedo: planes padded by ``pad`` columns
    of garbage on the right (the stride padding), the frame's crop, the tone map's exposure."""
    n, _, h, w = target.shape
    direct, albedo = torch.full((n, 3, h, w), 0.05), torch.full((n, 3, h, w), 0.6)
    planes = [direct, albedo, target]
    if pad:
        planes = [torch.cat([p, torch.full((n, 3, h, pad), 9.0)], 3) for p in planes]
    return {"direct": planes[0], "albedo": planes[1], "target": planes[2], "crop": (slice(0, h), slice(0, w)),
            "tonemap_exposure": 1.3}


def test_structure_loss_compares_the_displayed_frames_on_the_frames_pixels() -> None:
    """0 for the target itself, above 0 for a blurred one, with a finite gradient; the stride padding is not scored;
    the light scale multiplies both frames."""
    torch.manual_seed(0)
    enc = Encoding(exposure=2.0, depth_scale=10.0, output_gain=3.0)
    target = torch.rand(2, 3, 24, 28) * 0.8
    b = _batch(target, enc)
    exact = encode_radiance(target, enc.output())
    assert structure_loss(exact, b, enc, "indirect", True).item() == pytest.approx(0.0, abs=1e-4)
    blurred = encode_radiance(torch.nn.functional.avg_pool2d(target, 5, 1, 2, count_include_pad=False), enc.output())
    blurred.requires_grad_(True)
    loss = structure_loss(blurred, b, enc, "indirect", True)
    loss.backward()
    assert loss.item() > 0.05 and torch.isfinite(blurred.grad).all() and blurred.grad.abs().sum() > 0
    padded = _batch(target, enc, pad=4)
    garbage = torch.cat([exact, torch.zeros(2, 3, 24, 4)], 3)  # a prediction far off on the padding only
    assert structure_loss(garbage, padded, enc, "indirect", True).item() == pytest.approx(0.0, abs=1e-4)
    scaled = {**b, "scale": torch.full((2, 1, 1, 1), 4.0)}
    assert structure_loss(exact, scaled, enc, "indirect", True).item() == pytest.approx(0.0, abs=1e-4)
    assert structure_loss(blurred.detach(), scaled, enc, "indirect", True).item() != pytest.approx(loss.item())


def test_the_meter_on_tensors_is_the_viewers() -> None:
    """`metered_exposure_torch` reads each frame as `diviewer.exposure.metered_ev` does: a sunlit frame, a frame in
    deep shade, one darker than the meter's limit (held at +16 stops), one with unlit samples left out, and a black
    one (1: nothing to meter)."""
    from diviewer.exposure import ExposureSettings, metered_ev

    rng = np.random.default_rng(1)
    frames = rng.lognormal(0.0, 1.5, (5, 3, 12, 16)) * np.array([4.0, 2e-3, 1e-6, 0.3, 0.0]).reshape(5, 1, 1, 1)
    frames[2] = 2e-6  # lit, above the meter's floor, 16.5 stops under middle grey
    frames[3, :, :4] = 0.0  # a void beside the lit pixels
    got = metered_exposure_torch(torch.as_tensor(frames, dtype=torch.float32)).flatten().tolist()
    for frame, factor in zip(frames[:4], got):
        assert np.log2(factor) == pytest.approx(metered_ev(frame.transpose(1, 2, 0)), abs=1e-4)
    assert np.log2(got[2]) == ExposureSettings().limits[1] and got[4] == 1.0


def _frame_at(target: torch.Tensor, light: float, enc: Encoding, blur: bool) -> tuple[torch.Tensor, dict]:
    """The prediction (the target, blurred or not) and the batch of a frame whose light is ``light`` times
    `_batch`'s."""
    b = _batch(target * light, enc)
    b["direct"] = b["direct"] * light
    shown = torch.nn.functional.avg_pool2d(target, 5, 1, 2, count_include_pad=False) if blur else target
    return encode_radiance(shown * light, enc.output()), b


def test_the_structure_term_at_the_metered_exposure_sees_the_shade_as_the_sun() -> None:
    """At each frame's metered exposure the term does not depend on how bright the frame is (the meter brings it to
    middle grey, as the viewer does); at the scene's it all but vanishes in a frame 9 stops darker. "both" is the
    mean of the two; each is 0 for the target itself."""
    torch.manual_seed(2)
    enc = Encoding(exposure=2.0, depth_scale=10.0, output_gain=3.0)
    target = torch.rand(2, 3, 24, 28) * 0.8
    loss = {}
    for light in (1.0, 2.0 ** -9):
        fake, b = _frame_at(target, light, enc, blur=True)
        exact, _ = _frame_at(target, light, enc, blur=False)
        for mode in SSIM_EXPOSURES:
            loss[mode, light] = structure_loss(fake, b, enc, "indirect", True, mode).item()
            assert structure_loss(exact, b, enc, "indirect", True, mode).item() == pytest.approx(0.0, abs=1e-4)
        assert loss["both", light] == pytest.approx((loss["scene", light] + loss["metered", light]) / 2, rel=1e-5)
    assert loss["metered", 2.0 ** -9] == pytest.approx(loss["metered", 1.0], rel=1e-3)
    assert loss["metered", 2.0 ** -9] > 0.05 and loss["scene", 2.0 ** -9] < loss["scene", 1.0] / 10
    fake, b = _frame_at(target, 2.0 ** -9, enc, blur=True)
    fake.requires_grad_(True)
    structure_loss(fake, b, enc, "indirect", True, "metered").backward()
    assert torch.isfinite(fake.grad).all() and fake.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="exposure must be one of"):
        structure_loss(fake, b, enc, "indirect", True, "viewer")


def test_the_structure_terms_weight_is_checked_and_older_configs_have_none() -> None:
    assert LossConfig.from_dict({"reconstruction": "l1"}).ssim_weight == 0.0
    assert LossConfig.from_dict(LossConfig(ssim_weight=0.25).to_dict()).ssim_weight == 0.25
    for bad in (-0.1, float("inf"), "0.5"):
        with pytest.raises(DiviewerError, match="loss.ssim_weight"):
            LossConfig(ssim_weight=bad)
    assert LossConfig.from_dict({"reconstruction": "l1"}).ssim_exposure == "scene"
    assert LossConfig.from_dict(LossConfig(ssim_weight=0.1, ssim_exposure="both").to_dict()).ssim_exposure == "both"
    with pytest.raises(DiviewerError, match="loss.ssim_exposure"):
        LossConfig(ssim_exposure="viewer")
