"""Training losses: the adversarial loss (`GANLoss`) and the reconstruction loss (`reconstruction_loss`).

The reconstruction loss compares netG's output with the path-traced target. Both arrive encoded
(`diviewer.contract.encoding.encode_radiance`: linear below ~1, logarithmic above), and the loss is taken
either on those encoded values or on linear radiance scaled by the dataset's exposure. Which
statistic of a noisy target each choice converges to matters, because the ground truth is a
Monte-Carlo estimate whose noise is heavy-tailed (rare, very bright "firefly" samples):

- L2 on linear radiance is minimised by the per-pixel **mean** of the targets the network sees,
  and the Monte-Carlo estimate is unbiased, so this is the one unbiased choice: trained on many
  noisy frames it learns the converged image (at the price of gradients dominated by fireflies).
- L1 (on either space: the encoding is monotonic, so medians commute with it) is minimised by the
  **median**, which for a right-skewed distribution lies below the mean: biased dark exactly where
  fireflies are (caustics, small bright light paths).
- L2 on the encoded (log-like) values is minimised by the mean of the encoded values, i.e. the
  decoded result is a generalised (for bright pixels, geometric-like) mean, below the arithmetic
  mean by Jensen's inequality: biased dark too, less than L1 for mild noise.
- L1 on linear radiance: the median again, with linear-radiance weighting across pixels.
- L2 on "relative" errors, (prediction - target) / (|prediction| + REL_EPSILON) with the denominator taken
  from the prediction and not differentiated (Noise2Noise's relative MSE, Lehtinen et al. 2018): the weight
  depends on the prediction only, never on the noisy target, so the minimiser is still the **mean**, while an
  error counts relative to the pixel's brightness, so shade weighs as much as sunlit walls. Its weakness: an
  overshoot costs at most ~1 a pixel however large, and in shade single bright samples dominate its gradient.
  On Sponza (docs/sponza.md at commit c48f1bc, "Where the dark bias comes from") the median, where L1 goes, is 27-53 % below the
  mean in deep shade at 64 spp, yet a relative-L2 model overshot dim frames 7-44x and L1 stayed the better loss.
- "levels": the frame split into the means of its `LEVEL_POOL` x `LEVEL_POOL` blocks of linear radiance (compared on
  the encoded scale) and each pixel's departure from its block's mean (compared in linear radiance, weighed by the
  encoding's slope at the target's block mean: one weight for a whole block). A block's mean holds LEVEL_POOL^2
  times the samples of a pixel, so its noise is near symmetric and its median near its mean: L1 sets the level
  there, not at a pixel's median. The departures sum to zero over a block and share its weight, so their term
  cannot move the level (a shift of the whole block leaves them as they are): it carries the detail at full
  resolution. On Sponza's 64-spp capture, K = 8 at 8,000 steps, it did not beat L1 (docs/training.md), nor did a
  first version that weighed the departures at the predicted mean (a dark early network then sees the sunlit
  blocks' detail uncompressed).

Beside it, an optional **structure term** (`structure_loss`, weight ``ssim_weight`` times lambda_L1): 1 - SSIM of the
displayed image, GL direct light plus the decoded prediction, tone-mapped as `diviewer eval` scores it, against the
same image with the target in its place. The L1 term weighs a pixel's error by its radiance; this one by what the
tone-mapped SSIM, the issue's measure, sees: local means, contrasts and structure in 11x11 windows, the shade as much
as the sun. Under Monte-Carlo noise it is not neutral: the target's noise adds to its variance in each window but
not to its covariance with the prediction, so the SSIM against a noisy target is highest for a prediction of more
contrast than the converged image (by about sqrt(1 + noise variance / signal variance) within a window: 1.7x for a
sinusoid under noise of its own global variance, simulated). Meant for a clean truth (Sponza's refined ones).
Where it tone-maps (``ssim_exposure``): at the scene's one exposure, as `diviewer eval` scores ("scene"); at each frame's
metered exposure, as the viewer shows it ("metered": `metered_exposure_torch`, the viewer's meter read off the target's
frame); or the mean of both terms ("both"). At the scene's exposure Sponza's shade lies ~9 stops under the sunlit
floor, where the tone map's slope leaves the decoder's grid-locked pattern (docs/accuracy.md at commit c48f1bc, "The stride pattern in
the shade") almost unseen; the meter lifts a shaded frame by up to 13 stops, as the viewer does.

The trainer calls `LossConfig.reconstruction_loss` and `structure_loss`; `LossConfig` is the settings dataclass
recorded with checkpoints.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from diviewer.contract.encoding import Encoding
from diviewer.errors import DiviewerError
from diviewer.provenance import check_known_keys
from diviewer.train.encoding_torch import encode_radiance

RECONSTRUCTION_MODES: tuple[str, ...] = ("l1", "l2")
"""Reconstruction norms: mean absolute error (pix2pix, the paper) or mean squared error."""

RECONSTRUCTION_SPACES: tuple[str, ...] = ("encoded", "linear", "log", "relative", "levels")
"""Where the reconstruction loss is taken: on the network's encoded values (the paper's choice, as
the network sees them), on linear radiance times the dataset's exposure (so ~1 is a typical value), or
on log(LOG_EPSILON + exposed radiance), where an error counts relative to the pixel's own brightness:
dark regions (an object lit only by bounced light) weigh as much as bright ones; or "relative": linear errors
divided by the prediction's own brightness (+ REL_EPSILON), not differentiated, so that with "l2" the loss still
converges to the mean of a noisy target while weighing dark regions as the log space does; or "levels": block means
and the detail around them (`levels_loss`), where L1 sets each block's level near its noisy target's mean."""

LEVEL_POOL: int = 4
"""The "levels" space's block side, pixels: a block's mean holds 16 pixels' samples (1,024 at 64 spp)."""

LOG_EPSILON: float = 0.01
"""Offset of the "log" space, in exposed radiance (~1 typical): below it errors count absolutely, so
the black background and Monte-Carlo noise around zero do not dominate."""

REL_EPSILON: float = 0.01
"""Offset of the "relative" space's denominator, in exposed radiance (Noise2Noise's 0.01): below it errors count
absolutely, so a black pixel does not weigh without bound."""

SSIM_EXPOSURES: tuple[str, ...] = ("scene", "metered", "both")
"""Where the structure term tone-maps: the scene's exposure, each frame's metered one, or the mean of both terms."""

GAN_MODES: tuple[str, ...] = ("vanilla", "lsgan")
"""Adversarial objectives (pix2pix's names): BCE on logits (the paper), or least squares (Mao et al.)."""


class GANLoss(nn.Module):
    """pix2pix's GAN loss on discriminator outputs against all-real or all-fake labels.

    "vanilla": BCEWithLogits, stable for any logit size (no sigmoid first). "lsgan": mean squared
    error to the labels, whose gradient does not vanish for confidently classified fakes.
    """

    def __init__(self, real_label: float = 1.0, fake_label: float = 0.0, gan_mode: str = "vanilla") -> None:
        super().__init__()
        if gan_mode not in GAN_MODES:
            raise ValueError(f"gan_mode must be one of {list(GAN_MODES)}, got {gan_mode!r}")
        self.gan_mode = gan_mode
        self.register_buffer("real_label", torch.tensor(real_label))
        self.register_buffer("fake_label", torch.tensor(fake_label))
        self.loss = nn.BCEWithLogitsLoss() if gan_mode == "vanilla" else nn.MSELoss()

    def forward(self, pred: torch.Tensor, target_is_real: bool) -> torch.Tensor:
        """Mean loss of the discriminator outputs `pred` against all-real or all-fake labels."""
        label = self.real_label if target_is_real else self.fake_label
        return self.loss(pred, label.to(pred.dtype).expand_as(pred))


def exposed_radiance(y: torch.Tensor, encoding: Encoding) -> torch.Tensor:
    """Encoded values -> linear radiance times the exposure, differentiable everywhere.

    Equals `decode_radiance(y, encoding) * encoding.exposure` (clamping y to [-1, 1] likewise), but
    written for gradients rather than for ONNX: torch's exact expm1, and an odd extension by a
    `where` whose branches are both finite, so the slope at y = 0 is log1p(R), not sign's 0.
    """
    c = math.log1p(encoding.radiance_max)
    y = y.clamp(-1.0, 1.0)
    return torch.where(y >= 0, torch.expm1(y * c), -torch.expm1(-y * c))


def reconstruction_loss(fake_B: torch.Tensor, real_B: torch.Tensor, mode: str = "l1", space: str = "encoded",
                        encoding: Encoding | None = None, mask: torch.Tensor | None = None) -> torch.Tensor:
    """The reconstruction term between netG's output and the target, both encoded; see the module
    docstring for which statistic of a noisy target each (mode, space) converges to.

    Args:
        fake_B: netG's output (encoded, any float dtype; the loss is computed in float32).
        real_B: the encoded target, same shape.
        mode: "l1" or "l2" (`RECONSTRUCTION_MODES`).
        space: "encoded", "linear", "log" or "relative" (`RECONSTRUCTION_SPACES`); all but "encoded" need
            `encoding`.
        encoding: the dataset's encoding, to decode to linear radiance (times its exposure).
        mask: (1 or N, 1, H, W), 1 on the frame's pixels and 0 on the stride padding (`diviewer.contract.padding`):
            the mean is then over the frame's pixels only. None: every pixel.

    Returns:
        The mean over all elements (a scalar tensor), unweighted: the caller applies lambda.
    """
    if mode not in RECONSTRUCTION_MODES:
        raise ValueError(f"mode must be one of {list(RECONSTRUCTION_MODES)}, got {mode!r}")
    if space not in RECONSTRUCTION_SPACES:
        raise ValueError(f"space must be one of {list(RECONSTRUCTION_SPACES)}, got {space!r}")
    fake, real = fake_B.float(), real_B.float()
    if space == "levels":
        if encoding is None:
            raise ValueError(f"space '{space}' needs the encoding to decode radiance")
        return levels_loss(fake, real, mode, encoding, mask)
    if space in ("linear", "log", "relative"):
        if encoding is None:
            raise ValueError(f"space '{space}' needs the encoding to decode radiance")
        fake, real = exposed_radiance(fake, encoding), exposed_radiance(real, encoding)
    if space == "log":
        fake, real = torch.log(fake.clamp_min(0.0) + LOG_EPSILON), torch.log(real.clamp_min(0.0) + LOG_EPSILON)
    if space == "relative":  # the weight from the prediction alone: the minimiser stays the target's mean (l2)
        weight = 1.0 / (fake.detach().abs() + REL_EPSILON)
        fake, real = fake * weight, real * weight
    if mask is not None:
        err = (fake - real).abs() if mode == "l1" else (fake - real).square()
        m = mask.to(err.dtype).expand_as(err)
        return (err * m).sum() / m.sum().clamp(min=1.0)
    if mode == "l1":
        return nn.functional.l1_loss(fake, real)
    return nn.functional.mse_loss(fake, real)


def levels_loss(fake_B: torch.Tensor, real_B: torch.Tensor, mode: str, encoding: Encoding,
                mask: torch.Tensor | None = None, pool: int = LEVEL_POOL) -> torch.Tensor:
    """The "levels" reconstruction term (module docstring): the blocks' means on the encoded scale plus each pixel's
    departure from its block's mean, in linear radiance times the encoding's slope at the target's mean. Both
    encoded, (N, C, H, W) with H and W multiples of ``pool``; ``mask`` as in `reconstruction_loss` (a block's mean
    over its frame pixels, a block without any left out)."""
    n, _, h, w = fake_B.shape
    if h % pool or w % pool:
        raise ValueError(f"the levels loss needs frames whose sides are multiples of {pool}, got {w}x{h}")
    c = math.log1p(encoding.radiance_max)
    x, t = exposed_radiance(fake_B.float(), encoding), exposed_radiance(real_B.float(), encoding)
    m = (torch.ones((n, 1, h, w), dtype=x.dtype, device=x.device) if mask is None
         else mask.to(x.dtype).expand(n, 1, h, w))
    share = nn.functional.avg_pool2d(m, pool)
    level_x, level_t = (nn.functional.avg_pool2d(v * m, pool) / share.clamp_min(1e-6) for v in (x, t))
    scaled = [encode_radiance(v / encoding.exposure, encoding) for v in (level_x, level_t)]
    up_x, up_t = (v.repeat_interleave(pool, 2).repeat_interleave(pool, 3) for v in (level_x, level_t))
    slope = 1.0 / ((1.0 + up_t.abs()) * c)
    pairs = ((scaled[0], scaled[1], (share > 0).to(x.dtype)), ((x - up_x) * slope, (t - up_t) * slope, m))
    total = x.new_zeros(())
    for a, b, weight in pairs:
        err = (a - b).abs() if mode == "l1" else (a - b).square()
        weight = weight.expand_as(err)
        total = total + (err * weight).sum() / weight.sum().clamp(min=1.0)
    return total


SSIM_WINDOW, SSIM_SIGMA, SSIM_C1, SSIM_C2 = 11, 1.5, 0.01 ** 2, 0.03 ** 2
"""`diviewer.metrics.ssim`'s window and constants (data range 1: tone-mapped values)."""

TONEMAP_EPSILON: float = 1e-6
"""Floor of the tone map's ``y / (1 + y)`` before its gamma, whose slope is unbounded at 0."""


def ssim_torch(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Mean SSIM of two NCHW batches in [0, 1] over every wholly-inside window and channel: `diviewer.metrics.ssim`
    of each frame (data range 1), averaged; differentiable in ``a``, ``b`` the reference (no gradient flows into it,
    and its two window sums are taken without a graph: about a quarter less time on a CPU, micro-benchmarked)."""
    a, b = a.float(), b.float()
    c = a.shape[1]
    with torch.no_grad():
        mu_b, bb = _window_sums(torch.cat([b, b * b], 1)).split(c, 1)
    mu_a, aa, ab = _window_sums(torch.cat([a, a * a, a * b], 1)).split(c, 1)
    var_a = (aa - mu_a * mu_a).clamp_min(0.0)
    var_b = (bb - mu_b * mu_b).clamp_min(0.0)
    cov = ab - mu_a * mu_b
    num = (2 * mu_a * mu_b + SSIM_C1) * (2 * cov + SSIM_C2)
    den = (mu_a * mu_a + mu_b * mu_b + SSIM_C1) * (var_a + var_b + SSIM_C2)
    return (num / den).mean()


def _window_sums(t: torch.Tensor) -> torch.Tensor:
    """Each channel of an NCHW batch under the SSIM's Gaussian window, 'valid' (two separable passes)."""
    from diviewer.metrics import gaussian_window

    g = torch.as_tensor(gaussian_window(SSIM_WINDOW, SSIM_SIGMA), dtype=torch.float32, device=t.device)
    k = t.shape[1]
    rows, cols = g.reshape(1, 1, -1, 1).repeat(k, 1, 1, 1), g.reshape(1, 1, 1, -1).repeat(k, 1, 1, 1)
    # channels-last: the grouped convolutions and their gradient in 23-24 ms instead of 30-35 for Sponza's batch
    # (4 x 3 x 128 x 228, the whole SSIM; Intel Xeon, 2 threads, the chain paused), the same SSIM to 8 digits
    t = t.contiguous(memory_format=torch.channels_last)
    return nn.functional.conv2d(nn.functional.conv2d(t, rows, groups=k), cols, groups=k)


def tonemap_torch(x: torch.Tensor, exposure: float | torch.Tensor) -> torch.Tensor:
    """`diviewer.metrics.tonemap` on a tensor (Reinhard at ``exposure``, then gamma 2.2), its slope at black bounded
    by `TONEMAP_EPSILON`; ``exposure`` one number or one per frame (N, 1, 1, 1)."""
    from diviewer.metrics import TONEMAP_GAMMA

    y = (x * exposure).clamp_min(0.0)
    return (y / (1.0 + y)).clamp_min(TONEMAP_EPSILON) ** (1.0 / TONEMAP_GAMMA)


def metered_exposure_torch(rgb: torch.Tensor) -> torch.Tensor:
    """Each frame's exposure factor (N, 1, 1, 1) as the viewer's meter reads it off an NCHW batch of linear radiance:
    2 ** `diviewer.exposure.metered_ev` of each frame (1 where nothing is lit); no gradient."""
    from diviewer.exposure import metered_ev

    frames = rgb.detach().float().permute(0, 2, 3, 1).cpu().numpy()
    evs = [metered_ev(f) or 0.0 for f in frames]
    return torch.tensor(evs, dtype=torch.float32, device=rgb.device).exp2().reshape(-1, 1, 1, 1)


def structure_loss(fake_B: torch.Tensor, b: Mapping[str, Any], encoding: Encoding, target: str,
                   divide_albedo: bool, exposure: str = "scene") -> torch.Tensor:
    """1 - SSIM of the displayed frame with netG's output against the same frame with the target, both tone-mapped at
    the batch's ``tonemap_exposure`` as `diviewer eval` and validation compose and score it (GL direct light plus
    the decoded indirect light, times the albedo where the target is divided by it, times the light scale), on the
    frame's own pixels (``b["crop"]``: the stride padding left out). ``b``: `diviewer.train.targets.split_batch`'s
    planes with ``tonemap_exposure``. ``exposure`` (one of `SSIM_EXPOSURES`): "metered" tone-maps each frame at
    the exposure the viewer's meter reads off its target's frame instead, "both" takes the mean of the two terms."""
    from diviewer.train.targets import compose_radiance

    out = encoding.output()
    rows, cols = b["crop"]  # the frame's own pixels first: nothing is composed on the padding
    frame = lambda t: t[:, :, rows, cols].float()  # noqa: E731
    pred, true = exposed_radiance(frame(fake_B), out) / out.exposure, frame(b["target"])
    if "scale" in b:
        pred, true = pred * b["scale"], true * b["scale"]
    direct, albedo = frame(b["direct"]), frame(b["albedo"])
    if exposure not in SSIM_EXPOSURES:
        raise ValueError(f"exposure must be one of {list(SSIM_EXPOSURES)}, got {exposure!r}")
    pred, true = (compose_radiance(x, direct, albedo, target, divide_albedo) for x in (pred, true))
    exposures = ([b["tonemap_exposure"]] if exposure in ("scene", "both") else []) + (
        [metered_exposure_torch(true)] if exposure in ("metered", "both") else [])
    terms = [1.0 - ssim_torch(tonemap_torch(pred, e), tonemap_torch(true, e)) for e in exposures]
    return sum(terms) / len(terms)


@dataclass(frozen=True)
class LossConfig:
    """Loss settings, recorded with checkpoints; the weight of the reconstruction term stays the
    trainer's lambda_L1 (pix2pix's name, kept whatever the mode)."""

    reconstruction: str = "l1"
    """Reconstruction norm, one of `RECONSTRUCTION_MODES` ("l1": the paper)."""

    space: str = "encoded"
    """Where the reconstruction loss is taken, one of `RECONSTRUCTION_SPACES` ("encoded": the paper)."""

    gan_mode: str = "vanilla"
    """Adversarial objective, one of `GAN_MODES` ("vanilla": the paper)."""

    ssim_weight: float = 0.0
    """Weight of the structure term (`structure_loss`) beside the reconstruction term, both times lambda_L1 (0: none,
    every model before it)."""

    ssim_exposure: str = "scene"
    """Where the structure term tone-maps, one of `SSIM_EXPOSURES` ("scene": every model before it)."""

    def __post_init__(self) -> None:
        for name, choices in (("reconstruction", RECONSTRUCTION_MODES), ("space", RECONSTRUCTION_SPACES),
                              ("gan_mode", GAN_MODES), ("ssim_exposure", SSIM_EXPOSURES)):
            value = getattr(self, name)
            if value not in choices:
                raise DiviewerError(f"must be one of {list(choices)}, got {value!r}", field=f"loss.{name}")
        if not (isinstance(self.ssim_weight, (int, float)) and 0.0 <= self.ssim_weight < math.inf):
            raise DiviewerError(f"must be a number >= 0, got {self.ssim_weight!r}", field="loss.ssim_weight")

    def reconstruction_loss(self, fake_B: torch.Tensor, real_B: torch.Tensor, encoding: Encoding,
                            mask: torch.Tensor | None = None) -> torch.Tensor:
        """`reconstruction_loss` with this config's mode and space (over the frame's pixels: ``mask``)."""
        return reconstruction_loss(fake_B, real_B, self.reconstruction, self.space, encoding, mask)

    def gan_loss(self) -> GANLoss:
        """The adversarial criterion for this config."""
        return GANLoss(gan_mode=self.gan_mode)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for checkpoints and model cards."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LossConfig:
        """Rebuild from `to_dict()` output; unknown keys are an error, missing ones take defaults."""
        check_known_keys(cls, data, "loss")
        return cls(**dict(data))
