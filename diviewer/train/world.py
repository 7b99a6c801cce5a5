"""World-space position and normal of each pixel, the inputs of encoding version 3, on torch tensors.

The ablation of the world-space inputs (docs/generalisation.md at commit c48f1bc) gave a network these two planes beside the view-space buffers and
it scored higher on held-out cameras and meshes, most of all on an object lit only by bounced light: a per-scene
network can key its indirect light on where a surface is, as a radiance cache does. They are computed from what
every frame already has, the depth and view-space normal buffers and the frame's camera
(`diviewer.scene.camera.camera_params`), by this one function, which training calls on its batches and export
puts in the graph (so the runtime feeds the camera, not two more buffers).

    ray(c, r) = (ax (clip(c, x_lo, x_hi) + 0.5) + bx, ay (clip(r, y_lo, y_hi) + 0.5) + by, -1)
    world position  p = R (depth ray) + t        encoded clip((p - world_center) / world_half, -1, 1)
    world normal    n = R clip(normal, -1, 1)     encoded clip(n, -1, 1)

Both are 0 where there is no surface (depth <= 0), with the mask ``clip(depth HUGE, 0, 1)`` (1 for any depth
>= 1e-38, a Where without onnxruntime's slow Where). Inputs must be finite (the graph's NaN guard runs first).

Encoding version 4 adds `light_planes`: where each light is (three numbers a light, the graph's ``light`` input)
spread over the frame's surfaces, so a network can tell which side of the scene a sun lights in a frame of shade.
"""

from __future__ import annotations

from typing import Any

import torch

_HUGE = 1e38


def world_planes(depth: torch.Tensor, normal: torch.Tensor, cams: torch.Tensor, center: Any, half: Any) -> torch.Tensor:
    """(N, 1, H, W) depth and (N, 3, H, W) view normal, (N, CAMERA_PARAMS) cameras -> (N, 6, H, W) encoded planes.

    center, half: the encoding's ``world_center`` and ``world_half`` (three numbers each, or tensors)."""
    n, _, h, w = depth.shape
    c = cams.to(depth.dtype).reshape(n, -1, 1, 1)
    cols = torch.arange(w, dtype=depth.dtype, device=depth.device).reshape(1, 1, 1, w)
    rows = torch.arange(h, dtype=depth.dtype, device=depth.device).reshape(1, 1, h, 1)
    cols = torch.minimum(torch.maximum(cols, c[:, 16:17]), c[:, 17:18]) + 0.5
    rows = torch.minimum(torch.maximum(rows, c[:, 18:19]), c[:, 19:20]) + 0.5
    view = (depth * (c[:, 12:13] * cols + c[:, 13:14]), depth * (c[:, 14:15] * rows + c[:, 15:16]), -depth)
    nrm = torch.split(torch.clamp(normal, -1.0, 1.0), 1, 1)  # unit normals as they are; an infinite one stays finite
    center = torch.as_tensor(center, dtype=depth.dtype, device=depth.device).reshape(1, 3, 1, 1)
    inv_half = 1.0 / torch.as_tensor(half, dtype=depth.dtype, device=depth.device).reshape(1, 3, 1, 1)
    pos = torch.cat([c[:, 3 * k:3 * k + 1] * view[0] + c[:, 3 * k + 1:3 * k + 2] * view[1]
                     + c[:, 3 * k + 2:3 * k + 3] * view[2] + c[:, 9 + k:10 + k] for k in range(3)], 1)
    wn = torch.cat([c[:, 3 * k:3 * k + 1] * nrm[0] + c[:, 3 * k + 1:3 * k + 2] * nrm[1]
                    + c[:, 3 * k + 2:3 * k + 3] * nrm[2] for k in range(3)], 1)
    geo = torch.clamp(depth * _HUGE, 0.0, 1.0)
    return torch.cat([torch.clamp((pos - center) * inv_half, -1.0, 1.0) * geo, torch.clamp(wn, -1.0, 1.0) * geo], 1)


def light_planes(lights: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
    """(N, 3 L) light parameters (`diviewer.scene.lights.light_params`) and (N, 1, H, W) depth -> (N, 3 L, H, W)
    planes: each parameter constant over the frame's surfaces, 0 where there is none (encoding version 4)."""
    n = depth.shape[0]
    geo = torch.clamp(depth * _HUGE, 0.0, 1.0)
    return lights.to(depth.dtype).reshape(n, -1, 1, 1) * geo
