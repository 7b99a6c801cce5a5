"""The exported computation as torch modules: the lean graph that `diviewer export` writes, and the
reference it is verified against (training's own encode, netG, decode and composition).

The lean graph computes what training computes (`diviewer.contract.encoding`, `diviewer.train.targets`) with few
cheap operators, because onnxruntime's CPU kernels for Where, Sign and Cast of a whole frame cost as much as
several convolution layers of a small U-Net (measured per operator on 10 x 128 x 128 float32):

- NaN is handled once, in an If: the common frame (finite everywhere) pays one sum; a frame with NaN or an
  infinite value takes the branch that makes NaN 0 and infinite depth 0, as the encoding treats them.
- inputs: split into depth, normal + albedo, and direct light. Depth: ``clip(d, 0, 1) - clip(1 - d HUGE, 0,
  1)`` (-1 for background without a Where); normal/albedo: one scale, offset and clip; direct: exposed,
  clipped to radiance_max, ``log(1 + |c|) * c / max(|c|, TINY)`` (a sign without Sign).
- output: netG's tanh is in [-1, 1] already, so decoding is ``(exp(|y| L) - 1) * y / max(|y|, TINY) * k``
  with k = 1 / exposure (times the frame's light scale for encoding version 2), then the composition (the
  albedo floor from the encoded albedo, the raw direct light added, so a NaN there stays visible).
- log1p and expm1 are ``log(1 + a)`` and ``exp(z) - 1`` here: against training's exact-cancellation forms
  they differ by under 1e-8 in encoded units and 1e-7 of the exposure's radiance, far below the fp32
  export tolerance.
- batch norm is folded into the convolution before it (``fold_batchnorm``): the generator's graph is then
  convolutions, activations and concatenations only, the bare generator's.
- layout "NCHW" takes the buffers channel-first; "NHWC" (the GL pack's order, the contract of models
  exported before) transposes once on the way in. The output is NHWC radiance either way.
"""

from __future__ import annotations

import math
import warnings

import torch

from diviewer.contract.encoding import INPUT_CHANNELS, Encoding, channel_slices
from diviewer.train.targets import ALBEDO_FLOOR, compose_radiance
from diviewer.train.world import light_planes, world_planes

LAYOUTS = ("NHWC", "NCHW")
"""Input layouts an export can take: the GL pack's interleaved NHWC, or channel-first NCHW."""


TINY = 1e-30
"""x / max(|x|, TINY) is sign(x) for |x| >= TINY (exactly +-1) and ~0 below: a sign without onnxruntime's
slow Sign (and where |x| < TINY the factor it multiplies, log(1 + |x|) or exp(|x| L) - 1, is ~0 anyway)."""

HUGE = 1e38
"""Depth d / depth_scale >= 1 / HUGE counts as geometry: ``clip(1 - d * HUGE, 0, 1)`` is 1 for background
(d <= 0) and 0 for geometry, a Where without onnxruntime's slow Where (only subnormal depths differ)."""


def _finite_inputs(x: torch.Tensor) -> torch.Tensor:
    """NCHW buffers with NaN made 0 (no geometry, no normal, black albedo, no light) and infinite depth made
    0 (no geometry), as the encoding treats them; an ONNX If: the common frame, finite everywhere, pays only
    for one sum (x.sum() * 0 is NaN exactly when some value is NaN or infinite, or the sum overflows)."""
    if bool(torch.isnan(x.sum() * 0.0)):
        x = torch.where(torch.isnan(x), torch.zeros_like(x), x)
        depth = x[:, 0:1]
        x = torch.cat([torch.where(torch.isinf(depth), torch.zeros_like(depth), depth), x[:, 1:]], 1)
    return x


with warnings.catch_warnings():  # TorchScript is how the legacy exporter writes an If; it warns it is old
    warnings.simplefilter("ignore", DeprecationWarning)
    finite_inputs = torch.jit.script(_finite_inputs)


def fold_batchnorm(netG: torch.nn.Module) -> torch.nn.Module:
    """A copy of ``netG`` (in eval mode) with each BatchNorm2d that follows a convolution in a Sequential folded
    into that convolution's weights and bias, and replaced by Identity: the graph then has the bare
    generator's operators (bench's untrained U-Net has no normalisation). onnxruntime folds a BatchNorm into a
    Conv itself, but not into a ConvTranspose. Per output channel o, with g = gamma / sqrt(var + eps):
    W'[o] = W[o] g, b' = (b - mean) g + beta (a ConvTranspose2d's output channels are its weight's axis 1; a
    convolution followed by PixelShuffle(r) has r^2 output channels per normalised one)."""
    import copy

    net = copy.deepcopy(netG).eval()
    convs = (torch.nn.Conv2d, torch.nn.ConvTranspose2d)
    with torch.no_grad():
        for seq in [m for m in net.modules() if isinstance(m, torch.nn.Sequential)]:
            for i in range(len(seq) - 1):
                conv, bn, repeat = seq[i], seq[i + 1], 1
                if (isinstance(conv, torch.nn.Sequential) and len(conv) >= 2
                        and isinstance(conv[-1], torch.nn.PixelShuffle)):
                    # conv -> PixelShuffle(r) -> BN: BN's channel c is the conv's channels c r^2 ... c r^2 + r^2 - 1
                    repeat, conv = conv[-1].upscale_factor ** 2, conv[-2]
                if not (isinstance(conv, convs) and isinstance(bn, torch.nn.BatchNorm2d)
                        and bn.track_running_stats and bn.running_mean is not None and conv.groups == 1):
                    continue
                g = (bn.weight if bn.affine else torch.ones_like(bn.running_var)) / torch.sqrt(bn.running_var + bn.eps)
                beta = bn.bias if bn.affine else torch.zeros_like(bn.running_mean)
                g, shift = g.repeat_interleave(repeat), (beta - bn.running_mean * g).repeat_interleave(repeat)
                shape = (1, -1, 1, 1) if isinstance(conv, torch.nn.ConvTranspose2d) else (-1, 1, 1, 1)
                conv.weight.mul_(g.reshape(shape))
                bias = conv.bias if conv.bias is not None else torch.zeros_like(g)
                conv.bias = torch.nn.Parameter(bias * g + shift)
                seq[i + 1] = torch.nn.Identity()
    return net


class LeanGI(torch.nn.Module):
    """Raw buffers (and, for encoding version 2, the light scale (N,); for version 3 also the camera (N,
    CAMERA_PARAMS); for version 4 also the lights (N, 3 L)) -> linear radiance (N, H, W, 3)."""

    def __init__(self, netG, encoding: Encoding, meta: dict, fp16: bool = False, layout: str = "NHWC"):
        super().__init__()
        if layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
        folded = fold_batchnorm(netG)  # folded in float32, then rounded once
        self.netG = folded.half() if fp16 else folded
        self.fp16, self.layout, self.enc = fp16, layout, encoding
        self.target, self.divide_albedo = meta["target"], bool(meta["divide_albedo"])
        self.log_r = math.log1p(encoding.radiance_max)
        s = channel_slices()
        # The split below takes depth, then normal + albedo, then direct light, in that order.
        assert [k for k, _ in INPUT_CHANNELS] == ["depth", "normal", "albedo", "direct"]
        self.split = [1, s["albedo"].stop - 1, s["direct"].stop - s["direct"].start]
        n = self.split[1]
        # normal: as is; albedo: 2a - 1; both then clipped to [-1, 1]
        self.register_buffer("geo_scale", torch.tensor([1.0] * 3 + [2.0] * 3).reshape(1, n, 1, 1), persistent=False)
        self.register_buffer("geo_offset", torch.tensor([0.0] * 3 + [-1.0] * 3).reshape(1, n, 1, 1), persistent=False)
        self.floor_lo = 2.0 * ALBEDO_FLOOR - 1.0  # the albedo floor, in encoded albedo (2a - 1)

    def forward(self, buffers: torch.Tensor, light_scale: torch.Tensor | None = None,
                camera: torch.Tensor | None = None, light: torch.Tensor | None = None) -> torch.Tensor:
        raw = buffers if self.layout == "NCHW" else buffers.permute(0, 3, 1, 2)
        # The raw direct light, sliced before the If (the tracer would alias raw with its unchanged output): a
        # NaN there stays visible where it arose (the runtime counts it) instead of being hidden.
        raw_direct = raw[:, self.split[0] + self.split[1]:]
        x = finite_inputs(raw)
        enc = self.enc
        # half: the albedo floor below is (e + 1) / 2 of the encoded albedo e
        out_k = (0.5 if self.target != "full" and self.divide_albedo else 1.0) / enc.output().exposure
        if enc.light_scaled:
            # 1/s where s > 0 (1/inf = 0), else 0: no light gives exactly 0 in and out (0 * finite)
            inv = torch.where(light_scale > 0, 1.0 / light_scale, 0.0)
            in_k = (inv * enc.exposure).reshape(-1, 1, 1, 1)
            out_k = (light_scale * out_k).reshape(-1, 1, 1, 1)
        else:
            in_k = enc.exposure
        depth, geo, direct = torch.split(x, self.split, 1)
        d = depth * (1.0 / enc.depth_scale)
        e_depth = torch.clamp(d, 0.0, 1.0) - torch.clamp(1.0 - d * HUGE, 0.0, 1.0)  # -1 where d <= 0
        e_geo = torch.clamp(geo * self.geo_scale + self.geo_offset, -1.0, 1.0)
        c = torch.clamp(direct * in_k, -enc.radiance_max, enc.radiance_max)
        a = torch.abs(c)
        e_direct = torch.log(a + 1.0) * (c / torch.clamp(a * self.log_r, min=TINY * self.log_r))
        parts = [e_depth, e_geo, e_direct]
        if enc.world_inputs:  # encoding 3: world position and normal from the (finite) depth, normal and camera
            parts.append(world_planes(depth, geo[:, :3], camera, enc.world_center, enc.world_half))
        if enc.light_inputs:  # encoding 4: where each light is, over the frame's surfaces
            parts.append(light_planes(light, depth))
        encoded = torch.cat(parts, 1)
        y = self.netG(encoded.half() if self.fp16 else encoded)
        y = y.float() if self.fp16 else y
        ay = torch.abs(y)
        pred = (torch.exp(ay * self.log_r) - 1.0) * (y / torch.clamp(ay, min=TINY)) * out_k
        if self.target == "full":
            out = torch.relu(pred)
        else:
            if self.divide_albedo:  # max(albedo, floor) from the encoded albedo (NaN there is already black)
                pred = pred * (torch.clamp(e_geo[:, 3:], min=self.floor_lo) + 1.0)
            out = torch.relu(raw_direct + pred)
        return out.permute(0, 2, 3, 1)


class ReferenceGI(torch.nn.Module):
    """What training computes, as one module: NHWC buffers (+ light scale) -> NHWC radiance."""

    def __init__(self, netG, encoding: Encoding, meta: dict, fp16: bool = False):
        super().__init__()
        self.netG = netG.half() if fp16 else netG
        self.fp16, self.enc, self.meta = fp16, encoding, meta

    def forward(self, buffers: torch.Tensor, light_scale: torch.Tensor | None = None,
                camera: torch.Tensor | None = None, light: torch.Tensor | None = None) -> torch.Tensor:
        from diviewer.train.encoding_torch import TORCH_OPS, decode_radiance, encode_inputs
        from diviewer.contract.encoding import inverse_light_scale

        x = buffers.permute(0, 3, 1, 2)
        depth, normal, albedo, direct = (x[:, channel_slices()[k]] for k, _ in INPUT_CHANNELS)
        s = inv = None
        if self.enc.light_scaled:
            s = light_scale.reshape(-1, 1, 1, 1)
            inv = inverse_light_scale(light_scale, TORCH_OPS).reshape(-1, 1, 1, 1)
        inp = encode_inputs(depth, normal, albedo, direct if inv is None else direct * inv, self.enc, channel_axis=1)
        if self.enc.world_inputs:  # the buffers made finite as the lean graph's guard makes them (training's are)
            geometry = torch.where(torch.isfinite(depth), depth, torch.zeros_like(depth))
            normal = torch.where(torch.isnan(normal), torch.zeros_like(normal), normal)
            inp = torch.cat([inp, world_planes(geometry, normal, camera, self.enc.world_center, self.enc.world_half)], 1)
            if self.enc.light_inputs:
                inp = torch.cat([inp, light_planes(light, geometry)], 1)
        y = self.netG(inp.half() if self.fp16 else inp)
        radiance = decode_radiance(y.float() if self.fp16 else y, self.enc.output())
        if s is not None:
            radiance = radiance * s
        out = compose_radiance(radiance, direct, albedo, self.meta["target"], self.meta["divide_albedo"])
        return out.permute(0, 2, 3, 1)
