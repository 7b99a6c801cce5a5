"""Deep Illumination's networks: the U-Net generator and the PatchGAN discriminator.

Architectures follow pix2pix (Isola et al.; pytorch-CycleGAN-and-pix2pix), which the paper uses
with base width K = ngf and a number of levels that follows the resolution. Two ablation options
change them: the decoder's upsampling (`UPSAMPLES`) and the normalisation layer (`NORMS`); the
defaults are the paper's, and a checkpoint that does not name them rebuilds exactly as before.
The losses live in `diviewer.train.losses` (`GANLoss` is re-exported here for older imports); the
training step lives in another module; this one only builds modules.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import torch
from torch import nn

from diviewer.contract.encoding import INPUT_CHANNEL_COUNT, OUTPUT_CHANNELS
from diviewer.errors import DiviewerError
from diviewer.provenance import check_known_keys
from diviewer.train.config import MAX_FREQUENCIES

if TYPE_CHECKING:
    from diviewer.data.dataset import Dataset
    from diviewer.train.config import TrainConfig
from diviewer.train.losses import GANLoss

__all__ = [
    "LAMBDA_L1", "NORMS", "TARGETS", "UPSAMPLES", "GANLoss", "NLayerDiscriminator", "NetConfig",
    "PixelShuffleUpsample", "UnetGenerator", "icnr_", "init_weights", "levels_for_resolution",
]

LAMBDA_L1: float = 100.0
"""Weight of the L1 term against the adversarial term (pix2pix's default, used by the paper)."""

TARGETS: tuple[str, ...] = ("full", "indirect", "residual")
"""What netG may predict (`diviewer.train.config.TrainConfig.target`)."""

UPSAMPLES: tuple[str, ...] = ("transpose", "resize", "shuffle")
"""Decoder upsampling: "transpose" = ConvTranspose 4x4/2 (pix2pix, the paper); "resize" = nearest
upsample x2 then Conv 3x3 (Odena et al. 2016, "Deconvolution and checkerboard artifacts": every
output pixel sees the same number of kernel taps, so no checkerboard by construction); "shuffle" =
Conv 3x3 to 4x the channels then PixelShuffle(2) (Shi et al. 2016), ICNR-initialised (Aitken et al.
2017) so it starts as "resize" and has no checkerboard at initialisation."""

NORMS: tuple[str, ...] = ("batch", "instance", "none")
"""Normalisation after each inner convolution: BatchNorm (pix2pix, the paper), InstanceNorm (affine,
no running statistics: train and eval behave alike), or none (the convolution gets a bias instead)."""


def _norm_layer(norm: str, channels: int) -> nn.Module | None:
    """The normalisation module for `norm` (None for "none")."""
    if norm == "batch":
        return nn.BatchNorm2d(channels)
    if norm == "instance":
        # affine=True (pix2pix uses affine=False) so the layer has the same learnable scale and
        # shift as BatchNorm and the ablation changes only the statistics it normalises with.
        return nn.InstanceNorm2d(channels, affine=True, track_running_stats=False)
    return None


def _check_choice(name: str, value: str, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")


def icnr_(weight: torch.Tensor, scale: int = 2, init=nn.init.kaiming_normal_) -> torch.Tensor:
    """ICNR init of a conv that feeds PixelShuffle(scale): the scale**2 sub-pixel kernels of each
    output channel start equal, so conv + shuffle equals nearest upsampling of one conv (Aitken et al.).

    Args:
        weight: (C_out * scale**2, C_in, kh, kw) conv weight, overwritten in place.
        scale: the PixelShuffle factor.
        init: initialiser applied to the (C_out, C_in, kh, kw) sub-kernel.
    """
    out_channels = weight.shape[0] // scale**2
    sub = torch.empty(out_channels, *weight.shape[1:], dtype=weight.dtype, device=weight.device)
    init(sub)
    # PixelShuffle puts input channel c * scale**2 + k at sub-pixel k of output channel c, so the
    # copies of one kernel must be consecutive: repeat_interleave, not repeat.
    with torch.no_grad():
        weight.copy_(sub.repeat_interleave(scale**2, dim=0))
    return weight


class PixelShuffleUpsample(nn.Sequential):
    """Sub-pixel convolution: Conv 3x3 to 4 x out_channels, then PixelShuffle(2); ICNR-initialised."""

    def __init__(self, in_channels: int, out_channels: int, bias: bool = True) -> None:
        super().__init__(nn.Conv2d(in_channels, 4 * out_channels, 3, 1, 1, bias=bias), nn.PixelShuffle(2))
        self.reset_icnr()

    def reset_icnr(self, init=nn.init.kaiming_normal_) -> None:
        """Re-initialise the conv ICNR-style with `init` for the sub-kernel; the bias, too, per group."""
        conv = self[0]
        icnr_(conv.weight, 2, init)
        if conv.bias is not None:
            with torch.no_grad():
                conv.bias.copy_(conv.bias[::4].repeat_interleave(4))


def _upsample(kind: str, in_channels: int, out_channels: int, bias: bool) -> list[nn.Module]:
    """The decoder's x2 upsampling convolution as a list of modules (one module for "transpose", so
    a default decoder keeps pix2pix's layer indices and today's checkpoints load)."""
    if kind == "transpose":
        return [nn.ConvTranspose2d(in_channels, out_channels, 4, 2, 1, bias=bias)]
    if kind == "resize":
        # Nearest, as Odena et al. recommend; the 3x3 conv then smooths the 2x2 blocks. Upsampling
        # before the conv costs 9 MACs per output pixel and channel pair (transpose: 4).
        return [nn.Upsample(scale_factor=2, mode="nearest"), nn.Conv2d(in_channels, out_channels, 3, 1, 1, bias=bias)]
    return [PixelShuffleUpsample(in_channels, out_channels, bias=bias)]


def levels_for_resolution(resolution: int) -> int:
    """Number of U-Net levels for a square input: log2(resolution), so the bottleneck is 1x1.

    8 at 256 (the paper's unet_256), one fewer per halving. For a side that is not a power of two
    it is the number of times the side halves exactly (384 -> 7, a 3x3 bottleneck).
    """
    if isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 2 or resolution % 2:
        raise ValueError(f"resolution must be an even integer >= 2, got {resolution!r}")
    levels = 0
    while resolution % 2 == 0:
        resolution //= 2
        levels += 1
    return levels


class UnetGenerator(nn.Module):
    """pix2pix U-Net: `levels` stride-2 encoders down to the bottleneck, as many decoders back up.

    Encoder block: Conv 4x4/2 -> norm -> LeakyReLU(0.2); no norm on the first encoder, and the
    innermost (bottleneck) conv has neither norm nor LeakyReLU (pix2pix: a 1x1 map cannot be
    batch-normalised at batch size 1). Decoder block: ReLU -> x2 upsampling conv -> norm
    [-> Dropout]; the last decoder ends in tanh without norm. With the defaults (BatchNorm,
    ConvTranspose 4x4/2) this is pix2pix's U-Net. Each decoder after the first sees its
    input concatenated with the mirrored encoder's output (skip first, as pix2pix's cat([x, f(x)])).

    This is pix2pix's dataflow written as a flat list rather than recursive blocks: pix2pix's
    in-place LeakyReLU at the start of each block also rewrites the tensor it later concatenates,
    so its skips carry the activated features, as here.

    Args:
        in_channels: network input channels (the encoded G-buffers + direct light).
        out_channels: output channels (encoded radiance).
        K: base width (pix2pix's ngf); widths are K, 2K, 4K, 8K, 8K, ... capped at 8K.
        levels: number of encoder (and decoder) levels; inputs must be multiples of 2**levels.
        dropout: dropout probability in the innermost decoders (0 disables it).
        resolution: used only when levels is None, through `levels_for_resolution`.
        upsample: the decoders' upsampling, one of `UPSAMPLES`.
        norm: the normalisation layer, one of `NORMS`.
        frequencies, frequency_start: L > 0 appends 6 L planes before the first encoder (`fourier_features`, NeRF's
            positional encoding), sin and cos of pi 2^l p, l < L, of the three planes p from ``frequency_start``.
    """

    def __init__(
        self,
        in_channels: int = INPUT_CHANNEL_COUNT,
        out_channels: int = OUTPUT_CHANNELS,
        K: int = 32,
        levels: int | None = None,
        dropout: float = 0.5,
        resolution: int = 256,
        upsample: str = "transpose",
        norm: str = "batch",
        frequencies: int = 0,
        frequency_start: int = INPUT_CHANNEL_COUNT,
    ) -> None:
        super().__init__()
        _check_choice("upsample", upsample, UPSAMPLES)
        _check_choice("norm", norm, NORMS)
        if levels is None:
            levels = levels_for_resolution(resolution)
        if levels < 1:
            raise ValueError(f"levels must be >= 1, got {levels}")
        if not 0.0 <= dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {dropout}")
        self.in_channels = in_channels
        self.out_channels = out_channels
        self.K = K
        self.levels = levels
        self.dropout = dropout
        self.upsample = upsample
        self.norm = norm
        if frequencies < 0 or (frequencies and not 0 <= frequency_start <= in_channels - 3):
            raise ValueError(f"frequencies must be >= 0, of 3 of {in_channels} planes: {frequencies} at {frequency_start}")
        self.frequencies, self.frequency_start = frequencies, frequency_start

        widths = [K * min(2**i, 8) for i in range(levels)]
        self.down = nn.ModuleList()
        for i in range(levels):
            c_in = in_channels + 6 * frequencies if i == 0 else widths[i - 1]
            innermost = i == levels - 1
            norm_layer = _norm_layer(norm, widths[i]) if 0 < i < levels - 1 else None
            layers: list[nn.Module] = [nn.Conv2d(c_in, widths[i], 4, 2, 1, bias=norm_layer is None)]
            if norm_layer is not None:
                layers.append(norm_layer)
            if not innermost:
                layers.append(nn.LeakyReLU(0.2))
            self.down.append(nn.Sequential(*layers))

        # Dropout in the decoders whose output has the capped width 8K, at most 3: the paper's
        # "CD512-CD512-CD512" (the first 3 decoders at 256x256), fewer at lower resolutions.
        # (pix2pix's code puts them one decoder later, skipping the innermost; the paper is followed.)
        n_dropout = max(0, min(3, levels - 4)) if dropout > 0 else 0
        self.up = nn.ModuleList()
        for k in range(levels):
            c_in = widths[levels - 1] if k == 0 else 2 * widths[levels - 1 - k]
            outermost = k == levels - 1
            layers = [nn.ReLU()]
            if outermost:
                layers += [*_upsample(upsample, c_in, out_channels, bias=True), nn.Tanh()]
            else:
                norm_layer = _norm_layer(norm, widths[levels - 2 - k])
                layers += _upsample(upsample, c_in, widths[levels - 2 - k], bias=norm_layer is None)
                if norm_layer is not None:
                    layers.append(norm_layer)
                if k < n_dropout:
                    layers.append(nn.Dropout(dropout))
            self.up.append(nn.Sequential(*layers))

    @property
    def multiple(self) -> int:
        """Input height and width must be multiples of this (2**levels)."""
        return 2**self.levels

    def model_args(self) -> dict[str, Any]:
        """Constructor arguments that rebuild this module: `UnetGenerator(**netG.model_args())`."""
        return {
            "in_channels": self.in_channels,
            "out_channels": self.out_channels,
            "K": self.K,
            "levels": self.levels,
            "dropout": self.dropout,
            "upsample": self.upsample,
            "norm": self.norm,
            **({"frequencies": self.frequencies, "frequency_start": self.frequency_start} if self.frequencies else {}),
        }

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Encoded input (N, in_channels, H, W) -> encoded output (N, out_channels, H, W) in [-1, 1]."""
        # Skipped while exporting, so a dynamic-shape ONNX graph needs no divisibility guard; the
        # runtime checks the size against the model's metadata instead.
        if not (torch.compiler.is_compiling() or torch.jit.is_tracing()):
            h, w = x.shape[-2], x.shape[-1]
            m = self.multiple
            if h % m or w % m:
                raise ValueError(
                    f"UnetGenerator with {self.levels} levels needs H and W to be multiples of {m}; "
                    f"got {h}x{w} (pad or resize the input, or build the generator with fewer levels)"
                )
        if self.frequencies:
            x = torch.cat([x, self.fourier_features(x)], 1)
        skips: list[torch.Tensor] = []
        for block in self.down:
            x = block(x)
            skips.append(x)
        x = skips.pop()  # the bottleneck
        for k, block in enumerate(self.up):
            if k > 0:
                x = torch.cat([skips.pop(), x], dim=1)
            x = block(x)
        return x


    def fourier_features(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 6 L, H, W): sin, then cos, of pi 2^l p for l < L (octave by octave, three planes each) of the three
        planes p from ``frequency_start``: a Mul, a Concat, a Sin and a Cos in the exported graph."""
        p = x[:, self.frequency_start:self.frequency_start + 3]
        arg = torch.cat([p * (math.pi * 2.0 ** level) for level in range(self.frequencies)], 1)
        return torch.cat([torch.sin(arg), torch.cos(arg)], 1)


class NLayerDiscriminator(nn.Module):
    """pix2pix PatchGAN: one real/fake logit per overlapping patch (70x70 at n_layers=3).

    Conditioned: the caller concatenates the input buffers and the image (real_B or fake_B), so
    in_channels = input channels + 3. Layers: Conv/2 + LeakyReLU; n_layers - 1 times
    Conv/2 + norm + LeakyReLU; Conv/1 + norm + LeakyReLU; Conv/1 to one channel
    (n_layers + 2 convolutions, 5 for the paper's n_layers = 3). norm is one of `NORMS` (BatchNorm
    in pix2pix and the paper).
    """

    def __init__(self, in_channels: int = INPUT_CHANNEL_COUNT + OUTPUT_CHANNELS, ndf: int = 64, n_layers: int = 3,
                 norm: str = "batch") -> None:
        super().__init__()
        if n_layers < 1:
            raise ValueError(f"n_layers must be >= 1, got {n_layers}")
        _check_choice("norm", norm, NORMS)
        self.in_channels = in_channels
        self.ndf = ndf
        self.n_layers = n_layers
        self.norm = norm
        layers: list[nn.Module] = [nn.Conv2d(in_channels, ndf, 4, 2, 1), nn.LeakyReLU(0.2)]
        mult = 1
        for n in range(1, n_layers + 1):
            prev, mult = mult, min(2**n, 8)
            stride = 2 if n < n_layers else 1
            norm_layer = _norm_layer(norm, ndf * mult)
            layers.append(nn.Conv2d(ndf * prev, ndf * mult, 4, stride, 1, bias=norm_layer is None))
            if norm_layer is not None:
                layers.append(norm_layer)
            layers.append(nn.LeakyReLU(0.2))
        layers.append(nn.Conv2d(ndf * mult, 1, 4, 1, 1))
        self.model = nn.Sequential(*layers)

    def model_args(self) -> dict[str, Any]:
        """Constructor arguments that rebuild this module."""
        return {"in_channels": self.in_channels, "ndf": self.ndf, "n_layers": self.n_layers, "norm": self.norm}

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, in_channels, H, W) -> patch logits (N, 1, H', W')."""
        return self.model(x)


def init_weights(net: nn.Module, gain: float = 0.02) -> nn.Module:
    """pix2pix 'normal' init: conv weights ~ N(0, gain), norm scales ~ N(1, gain), biases 0.

    Pixel-shuffle convolutions get the same N(0, gain) sub-kernel, ICNR-repeated (see `icnr_`).
    Seed torch first for a reproducible net. Returns net, for chaining.
    """
    for m in net.modules():
        if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d, nn.Linear)):
            nn.init.normal_(m.weight, 0.0, gain)
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, (nn.BatchNorm2d, nn.InstanceNorm2d)) and m.weight is not None:
            nn.init.normal_(m.weight, 1.0, gain)
            nn.init.zeros_(m.bias)
    # After the loop: modules() visits a PixelShuffleUpsample before its conv, which the loop redraws.
    for m in net.modules():
        if isinstance(m, PixelShuffleUpsample):
            m.reset_icnr(lambda w: nn.init.normal_(w, 0.0, gain))
    return net


@dataclass(frozen=True)
class NetConfig:
    """Network settings: everything needed to rebuild netG and netD, recorded with checkpoints."""

    K: int = 32
    """Generator base width (pix2pix's ngf); the paper trains K = 32, 64, 128."""

    levels: int | None = None
    """Generator levels; None derives them from `resolution` (log2: 8 at 256)."""

    resolution: int = 256
    """Training image side in pixels; inputs must be multiples of 2**levels."""

    dropout: float = 0.5
    """Dropout probability in the innermost generator decoders (pix2pix: 0.5)."""

    ndf: int = 64
    """Discriminator base width."""

    n_layers_D: int = 3
    """Discriminator stride layers: 3 gives the 5-conv 70x70 PatchGAN."""

    lambda_L1: float = LAMBDA_L1
    """Weight of the L1 term against the adversarial term."""

    target: str = "full"
    """What the generator predicts: "full" GI radiance, or "indirect" / "residual" (added to the GL direct light)."""

    upsample: str = "transpose"
    """Generator decoder upsampling, one of `UPSAMPLES`: "transpose" (the paper), "resize", "shuffle"."""

    norm: str = "batch"
    """Generator normalisation, one of `NORMS`: "batch" (the paper), "instance", "none"."""

    norm_D: str = "batch"
    """Discriminator normalisation, one of `NORMS`: "batch" (the paper), "instance", "none"."""

    world_frequencies: int = 0
    """Octaves of Fourier features of the world position before netG's first encoder (0: none)."""

    def __post_init__(self) -> None:
        def fail(field: str, message: str) -> None:
            raise DiviewerError(message, field=f"net.{field}")

        for name in ("K", "resolution", "ndf", "n_layers_D"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                fail(name, f"must be a positive integer, got {value!r}")
        if self.levels is not None and (isinstance(self.levels, bool) or not isinstance(self.levels, int) or self.levels < 1):
            fail("levels", f"must be a positive integer or None, got {self.levels!r}")
        if self.levels is None and (self.resolution % 2):
            fail("resolution", f"must be even to derive levels, got {self.resolution}; or set levels")
        if self.resolution % (2 ** self.resolved_levels()):
            fail("resolution", f"{self.resolution} is not a multiple of 2**levels = {2 ** self.resolved_levels()}")
        if not (isinstance(self.dropout, (int, float)) and 0.0 <= self.dropout < 1.0):
            fail("dropout", f"must be in [0, 1), got {self.dropout!r}")
        if not (isinstance(self.lambda_L1, (int, float)) and self.lambda_L1 >= 0):
            fail("lambda_L1", f"must be a number >= 0, got {self.lambda_L1!r}")
        if self.target not in TARGETS:
            fail("target", f"must be one of {list(TARGETS)}, got {self.target!r}")
        if self.upsample not in UPSAMPLES:
            fail("upsample", f"must be one of {list(UPSAMPLES)}, got {self.upsample!r}")
        f = self.world_frequencies
        if isinstance(f, bool) or not isinstance(f, int) or not 0 <= f <= MAX_FREQUENCIES:
            fail("world_frequencies", f"must be an integer in [0, {MAX_FREQUENCIES}], got {f!r}")
        for name in ("norm", "norm_D"):
            if getattr(self, name) not in NORMS:
                fail(name, f"must be one of {list(NORMS)}, got {getattr(self, name)!r}")

    def resolved_levels(self) -> int:
        """The generator's levels: explicit, or derived from the resolution."""
        return self.levels if self.levels is not None else levels_for_resolution(self.resolution)

    def build_generator(self, in_channels: int = INPUT_CHANNEL_COUNT) -> UnetGenerator:
        """netG for this config (weights not yet initialised: see `init_weights`); ``in_channels``: the encoded
        inputs (10, and 16 with encoding version 3's world planes)."""
        return UnetGenerator(in_channels, OUTPUT_CHANNELS, K=self.K, levels=self.resolved_levels(),
                             dropout=self.dropout, upsample=self.upsample, norm=self.norm,
                             frequencies=self.world_frequencies)

    def build_discriminator(self, in_channels: int = INPUT_CHANNEL_COUNT) -> NLayerDiscriminator:
        """netD for this config, conditioned on the input buffers (input channels + 3)."""
        return NLayerDiscriminator(in_channels + OUTPUT_CHANNELS, ndf=self.ndf, n_layers=self.n_layers_D,
                                   norm=self.norm_D)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for checkpoints and model cards."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> NetConfig:
        """Rebuild from `to_dict()` output; unknown keys are an error, missing ones take defaults (a
        checkpoint from before upsample/norm existed rebuilds as transpose/batch, which it was)."""
        check_known_keys(cls, data, "net")
        return cls(**dict(data))


def net_config(cfg: TrainConfig, ds: Dataset) -> NetConfig:
    """The networks for a run's settings and its dataset's resolution (`diviewer.train.trainer`)."""
    try:
        # Cropped (or any wider) frames are padded to the stride: the network's depth follows the height.
        levels = (levels_for_resolution(min(ds.width, ds.height)) if cfg.aspect_crops else
                  min(levels_for_resolution(ds.width), levels_for_resolution(ds.height)))
    except ValueError:
        raise DiviewerError(f"resolution {ds.width}x{ds.height} must be even on both sides to train a U-Net",
                            path=ds.root) from None
    return NetConfig(K=cfg.K, levels=levels, resolution=min(ds.width, ds.height), dropout=cfg.dropout,
                     ndf=cfg.ndf, n_layers_D=cfg.n_layers_D, lambda_L1=cfg.lambda_L1, target=cfg.target,
                     upsample=cfg.upsample, norm=cfg.norm, norm_D=cfg.norm_D, world_frequencies=cfg.world_frequencies)
