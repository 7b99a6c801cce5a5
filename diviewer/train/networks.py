"""Deep Illumination's networks: the U-Net generator, the PatchGAN discriminator and the GAN loss.

Architectures follow pix2pix (Isola et al.; pytorch-CycleGAN-and-pix2pix), which the paper uses
with base width K = ngf and a number of levels that follows the resolution. The training step
lives in another module; this one only builds modules.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from diviewer.encoding import INPUT_CHANNEL_COUNT, OUTPUT_CHANNELS
from diviewer.errors import DiviewerError
from diviewer.provenance import check_known_keys

LAMBDA_L1: float = 100.0
"""Weight of the L1 term against the adversarial term (pix2pix's default, used by the paper)."""

TARGETS: tuple[str, ...] = ("full", "indirect")
"""What the generator predicts: the full GI image, or indirect light only (added to exact direct)."""


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

    Encoder block: Conv 4x4/2 -> BatchNorm -> LeakyReLU(0.2); no norm on the first encoder, and the
    innermost (bottleneck) conv has neither norm nor LeakyReLU (pix2pix: a 1x1 map cannot be
    batch-normalised at batch size 1). Decoder block: ReLU -> ConvTranspose 4x4/2 -> BatchNorm
    [-> Dropout]; the last decoder ends in tanh without norm. Each decoder after the first sees its
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
    """

    def __init__(
        self,
        in_channels: int = INPUT_CHANNEL_COUNT,
        out_channels: int = OUTPUT_CHANNELS,
        K: int = 32,
        levels: int | None = None,
        dropout: float = 0.5,
        resolution: int = 256,
    ) -> None:
        super().__init__()
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

        widths = [K * min(2**i, 8) for i in range(levels)]
        self.down = nn.ModuleList()
        for i in range(levels):
            c_in = in_channels if i == 0 else widths[i - 1]
            innermost = i == levels - 1
            norm = 0 < i < levels - 1
            layers: list[nn.Module] = [nn.Conv2d(c_in, widths[i], 4, 2, 1, bias=not norm)]
            if norm:
                layers.append(nn.BatchNorm2d(widths[i]))
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
                layers += [nn.ConvTranspose2d(c_in, out_channels, 4, 2, 1), nn.Tanh()]
            else:
                layers += [
                    nn.ConvTranspose2d(c_in, widths[levels - 2 - k], 4, 2, 1, bias=False),
                    nn.BatchNorm2d(widths[levels - 2 - k]),
                ]
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


class NLayerDiscriminator(nn.Module):
    """pix2pix PatchGAN: one real/fake logit per overlapping patch (70x70 at n_layers=3).

    Conditioned: the caller concatenates the input buffers and the image (real_B or fake_B), so
    in_channels = input channels + 3. Layers: Conv/2 + LeakyReLU; n_layers - 1 times
    Conv/2 + BatchNorm + LeakyReLU; Conv/1 + BatchNorm + LeakyReLU; Conv/1 to one channel
    (n_layers + 2 convolutions, 5 for the paper's n_layers = 3).
    """

    def __init__(self, in_channels: int = INPUT_CHANNEL_COUNT + OUTPUT_CHANNELS, ndf: int = 64, n_layers: int = 3) -> None:
        super().__init__()
        if n_layers < 1:
            raise ValueError(f"n_layers must be >= 1, got {n_layers}")
        self.in_channels = in_channels
        self.ndf = ndf
        self.n_layers = n_layers
        layers: list[nn.Module] = [nn.Conv2d(in_channels, ndf, 4, 2, 1), nn.LeakyReLU(0.2)]
        mult = 1
        for n in range(1, n_layers + 1):
            prev, mult = mult, min(2**n, 8)
            stride = 2 if n < n_layers else 1
            layers += [
                nn.Conv2d(ndf * prev, ndf * mult, 4, stride, 1, bias=False),
                nn.BatchNorm2d(ndf * mult),
                nn.LeakyReLU(0.2),
            ]
        layers.append(nn.Conv2d(ndf * mult, 1, 4, 1, 1))
        self.model = nn.Sequential(*layers)

    def model_args(self) -> dict[str, Any]:
        """Constructor arguments that rebuild this module."""
        return {"in_channels": self.in_channels, "ndf": self.ndf, "n_layers": self.n_layers}

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, in_channels, H, W) -> patch logits (N, 1, H', W')."""
        return self.model(x)


class GANLoss(nn.Module):
    """Vanilla GAN loss on logits: BCEWithLogits, stable for any logit size (no sigmoid first)."""

    def __init__(self, real_label: float = 1.0, fake_label: float = 0.0) -> None:
        super().__init__()
        self.register_buffer("real_label", torch.tensor(real_label))
        self.register_buffer("fake_label", torch.tensor(fake_label))
        self.loss = nn.BCEWithLogitsLoss()

    def forward(self, pred: torch.Tensor, target_is_real: bool) -> torch.Tensor:
        """Mean loss of the discriminator logits `pred` against all-real or all-fake labels."""
        label = self.real_label if target_is_real else self.fake_label
        return self.loss(pred, label.to(pred.dtype).expand_as(pred))


def init_weights(net: nn.Module, gain: float = 0.02) -> nn.Module:
    """pix2pix 'normal' init: conv weights ~ N(0, gain), norm scales ~ N(1, gain), biases 0.

    Seed torch first for a reproducible net. Returns net, for chaining.
    """
    for m in net.modules():
        if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d, nn.Linear)):
            nn.init.normal_(m.weight, 0.0, gain)
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.BatchNorm2d):
            nn.init.normal_(m.weight, 1.0, gain)
            nn.init.zeros_(m.bias)
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
    """What the generator predicts: "full" GI radiance, or "indirect" (added to the exact direct light)."""

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

    def resolved_levels(self) -> int:
        """The generator's levels: explicit, or derived from the resolution."""
        return self.levels if self.levels is not None else levels_for_resolution(self.resolution)

    def build_generator(self) -> UnetGenerator:
        """netG for this config (weights not yet initialised: see `init_weights`)."""
        return UnetGenerator(INPUT_CHANNEL_COUNT, OUTPUT_CHANNELS, K=self.K, levels=self.resolved_levels(), dropout=self.dropout)

    def build_discriminator(self) -> NLayerDiscriminator:
        """netD for this config, conditioned on the input buffers (input channels + 3)."""
        return NLayerDiscriminator(INPUT_CHANNEL_COUNT + OUTPUT_CHANNELS, ndf=self.ndf, n_layers=self.n_layers_D)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict for checkpoints and model cards."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> NetConfig:
        """Rebuild from `to_dict()` output; unknown keys are an error, missing ones take defaults."""
        check_known_keys(cls, data, "net")
        return cls(**dict(data))
