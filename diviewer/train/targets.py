"""What the network learns: the target radiance, how the displayed image is composed from netG's
output, the dataset's encoding (fixed from the train split) and a stored batch split into netG's
input and target. Export imports the composition from here, so the ONNX graph composes as training did.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import torch

    from diviewer.data.dataset import Dataset
    from diviewer.encoding import Encoding
    from diviewer.train.config import TrainConfig

ALBEDO_FLOOR: float = 0.05
"""With divide_albedo, indirect light is divided by max(albedo, ALBEDO_FLOOR) and multiplied back by
the same: exactly invertible, and dark or background pixels (albedo 0) do not amplify noise."""


def target_radiance(pt: Any, pt_direct: Any, albedo: Any, target: str, divide_albedo: bool) -> Any:
    """Linear radiance netG learns to predict (before encoding), from path-traced ground truth."""
    if target == "full":
        return pt
    indirect = pt - pt_direct
    if divide_albedo:
        indirect = indirect / _albedo_floor(albedo)
    return indirect


def compose_radiance(pred: Any, direct: Any, albedo: Any, target: str, divide_albedo: bool) -> Any:
    """The displayed image from netG's decoded output: as is ("full"), or GL direct + indirect; clamped at 0.

    Works on numpy arrays and torch tensors (ONNX: Max/Mul/Add), so the exporter can use it too.
    """
    if target == "full":
        return _non_negative(pred)
    if divide_albedo:
        pred = pred * _albedo_floor(albedo)
    return _non_negative(direct + pred)


def _non_negative(x: Any) -> Any:
    """Radiance is never negative: an undershooting prediction is clamped (validation, export and runtime agree)."""
    if type(x).__module__.startswith("torch"):
        return x.clamp(min=0.0)
    return np.maximum(x, 0.0)


def _albedo_floor(albedo: Any) -> Any:
    """Albedo within [ALBEDO_FLOOR, 1], a NaN taken as black: the exported graph multiplies its prediction
    by the raw albedo input, and a broken G-buffer texel must not turn into a broken pixel (albedo above 1
    is refused by the scene loader, so clamping there changes no valid frame)."""
    if type(albedo).__module__.startswith("torch"):
        import torch

        return torch.where(torch.isnan(albedo), torch.zeros_like(albedo), albedo).clamp(ALBEDO_FLOOR, 1.0)
    return np.clip(np.where(np.isnan(albedo), 0.0, albedo), ALBEDO_FLOOR, 1.0)


def fit_encoding(ds: Dataset, train_idx: list[int], train: np.ndarray) -> Encoding:
    """The dataset's encoding, fixed from the train split.

    exposure: `fit_exposure` over the train frames' GL direct light; depth_scale: the camera's far
    plane from the frame configurations (all visible geometry then maps into [0, 1]), else the
    largest train depth; radiance_max: the default.
    """
    from diviewer.encoding import Encoding, fit_exposure

    direct = ds.slices["direct"]
    exposure = fit_exposure([frame[..., direct] for frame in train])
    wanted = set(train_idx)
    fars = []
    for f in ds.frames:
        cam = (f.get("config") or {}).get("camera") or {}
        if f["index"] in wanted and isinstance(cam.get("far"), (int, float)) and cam["far"] > 0:
            fars.append(float(cam["far"]))
    if fars:
        depth_scale = max(fars)
    else:
        depth = train[..., ds.slices["depth"]].astype(np.float32)
        finite = depth[np.isfinite(depth) & (depth > 0)]
        depth_scale = float(finite.max()) if finite.size else 1.0
    return Encoding(exposure=float(exposure), depth_scale=float(depth_scale))


def split_batch(x16: torch.Tensor, slices: Mapping[str, slice], enc: Encoding,
                cfg: TrainConfig) -> dict[str, torch.Tensor]:
    """A stored (N, H, W, C) batch on the device -> real_A (encoded inputs), real_B (encoded target),
    and the raw NCHW planes the composition, the losses and the metrics need (direct, albedo, pt,
    target: the linear target radiance)."""
    from diviewer.train.encoding_torch import encode_inputs, encode_radiance

    x = x16.permute(0, 3, 1, 2).float().contiguous()
    p = {name: x[:, s] for name, s in slices.items()}
    real_A = encode_inputs(p["depth"], p["normal"], p["albedo"], p["direct"], enc, channel_axis=1)
    target = target_radiance(p["pt"], p["pt_direct"], p["albedo"], cfg.target, cfg.divide_albedo)
    real_B = encode_radiance(target, enc)
    return {"real_A": real_A, "real_B": real_B, "direct": p["direct"], "albedo": p["albedo"], "pt": p["pt"],
            "target": target}
