"""What the network learns: the target radiance, how the displayed image is composed from netG's
output, the dataset's encoding (fixed from the train split) and a stored batch split into netG's
input and target. Export imports the composition from here, so the ONNX graph composes as training did.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from diviewer.data.scales import ALBEDO_FLOOR, floored_albedo  # noqa: F401 (ALBEDO_FLOOR re-exported: the trainer's floor)

if TYPE_CHECKING:
    import torch

    from diviewer.data.dataset import Dataset
    from diviewer.contract.encoding import Encoding
    from diviewer.train.config import TrainConfig


def target_radiance(pt: Any, pt_direct: Any, albedo: Any, target: str, divide_albedo: bool, direct: Any = None) -> Any:
    """Linear radiance netG learns to predict (before encoding), from path-traced ground truth: ``pt`` ("full"),
    ``pt - pt_direct`` ("indirect") or ``pt - direct``, the GL direct light the composite adds ("residual")."""
    if target == "full":
        return pt
    if target == "residual" and direct is None:
        raise ValueError("target 'residual' needs the GL direct light")
    indirect = pt - (direct if target == "residual" else pt_direct)
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
    return floored_albedo(albedo)


def run_light_scales(cfg: TrainConfig, ds: Dataset, train_idx: list[int],
                  with_val: bool) -> tuple[np.ndarray | None, np.ndarray | None]:
    """A run's train (and val) frames' light scales (None, None without ``cfg.light_scale``: encoding 1)."""
    from diviewer.errors import DiviewerError

    if not cfg.light_scale:
        return None, None
    from diviewer.data.scales import light_scales

    train_scales = light_scales(ds, train_idx)
    if not np.any(train_scales > 0):
        raise DiviewerError("no train frame has any light (every light scale is 0: no lights, emitters or sky "
                            "in the frame configurations); train with --no-light-scale", path=ds.root)
    return train_scales, light_scales(ds, sorted(ds.indices("val"))) if with_val else None


GAIN_NOTE: float = 4.0
"""A run without ``output_gain`` whose fitted gain would be at least this is told so (`fit_encoding`): its target's
99th percentile lies below 1/4 of the direct light's exposure (Sponza: 1/6.2; cornell: 1/2.5)."""


def fit_encoding(ds: Dataset, train_idx: list[int], train: np.ndarray, scales: np.ndarray | None = None,
                 world: bool = False, lights: bool = False, output_of: TrainConfig | None = None,
                 say: Callable[[str], None] | None = None) -> Encoding:
    """The dataset's encoding, fixed from the train split.

    exposure: `fit_exposure` over the train frames' GL direct light (divided by each frame's light scale
    when ``scales`` is given: encoding version 2); depth_scale: the camera's far plane from the frame
    configurations (all visible geometry then maps into [0, 1]), else the largest train depth;
    radiance_max: the default. ``world`` (encoding version 3, with ``scales``): world_center and world_half
    from the bounds of the scene's objects (`Scene.bounds`), the scene the dataset was captured from. ``lights``
    (encoding version 4, with ``world``): the number of the scene's lights, which every frame configuration has.
    ``output_of``: a run whose ``output_gain`` is set gets `fit_output_gain`'s gain on its targets; one without it
    whose gain would be ``GAIN_NOTE`` or more is told so through ``say``.
    """
    enc = _fit_encoding(ds, train_idx, train, scales, world, lights)
    if output_of is None or not (output_of.output_gain or say is not None):
        return enc
    gain = fit_output_gain(ds, train, scales, enc, output_of)
    if output_of.output_gain:
        import dataclasses

        return dataclasses.replace(enc, output_gain=gain)
    if gain >= GAIN_NOTE:
        from diviewer.contract.encoding import encode_radiance

        say(f"note: the target's 99th percentile is {1 / gain:.2g} at the direct light's exposure, "
            f"{float(encode_radiance(1 / gain / enc.exposure, enc)):.1e} of the network's range; --output-gain "
            f"would encode it at its own exposure (x {gain:.3g}; docs/training.md, 'Radiance encoding')")
    return enc


def fit_output_gain(ds: Dataset, train: np.ndarray, scales: np.ndarray | None, enc: Encoding,
                    cfg: TrainConfig) -> float:
    """The gain that puts the 99th percentile of the train frames' exposed target luminance at 1 (`fit_exposure` on
    the targets as the trainer makes them: divided by the albedo and the light scale, times the exposure). Sponza's
    indirect light is ~1 % of its direct light: its target's 99th percentile is 0.14 at the direct light's
    exposure, its median 0.0057, i.e. 5e-4 of the encoded range (docs/sponza.md at commit c48f1bc; cornell's median: 0.107)."""
    from diviewer.contract.encoding import fit_exposure

    return float(fit_exposure(list(exposed_targets(ds, train, scales, enc, cfg, stride=4))))  # 1/16: bounded memory


def exposed_targets(ds: Dataset, train: np.ndarray, scales: np.ndarray | None, enc: Encoding, cfg: TrainConfig,
                    stride: int = 1):
    """Each frame's target as the trainer makes it (`target_radiance`, divided by the frame's light scale), times
    the encoding's (input) exposure, at every ``stride``-th row and column: float32 (H', W', 3) arrays, one a frame."""
    from diviewer.contract.encoding import inverse_light_scale

    s = ds.slices
    inv = np.ones(len(train)) if scales is None else inverse_light_scale(scales.astype(np.float64))
    for frame, k in zip(train, inv):
        f = {name: frame[::stride, ::stride, s[name]].astype(np.float32)
             for name in ("pt", "pt_direct", "albedo", "direct")}
        t = target_radiance(f["pt"], f["pt_direct"], f["albedo"], cfg.target, cfg.divide_albedo, f["direct"])
        yield t * np.float32(k * enc.exposure)


def _fit_encoding(ds: Dataset, train_idx: list[int], train: np.ndarray, scales: np.ndarray | None, world: bool,
                  lights: bool) -> Encoding:
    from diviewer.contract.encoding import Encoding, fit_exposure, inverse_light_scale

    direct = ds.slices["direct"]
    if scales is None:
        exposure = fit_exposure([frame[..., direct] for frame in train])
    else:
        inv = inverse_light_scale(scales.astype(np.float64))
        exposure = fit_exposure([frame[..., direct].astype(np.float32) * np.float32(k) for frame, k in zip(train, inv)])
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
    if not world:
        return Encoding(exposure=float(exposure), depth_scale=float(depth_scale), version=1 if scales is None else 2)
    scene = _scene_of(ds)
    lo, hi = scene.bounds()
    count = None
    if lights:
        from diviewer.errors import DiviewerError

        count = len(scene.default.lights)
        if count == 0:
            raise DiviewerError("the scene has no lights to feed the network (light_inputs); train without them",
                                path=ds.root)
        wrong = next((f["index"] for f in ds.frames if len((f.get("config") or {}).get("lights") or []) != count),
                     None)
        if wrong is not None:
            raise DiviewerError(f"frame {wrong}'s configuration has not the scene's {count} light(s) (light_inputs)",
                                path=ds.root / "manifest.json")
    return Encoding(exposure=float(exposure), depth_scale=float(depth_scale), version=4 if lights else 3,
                    world_center=tuple(float(v) for v in (lo + hi) / 2),
                    world_half=tuple(float(v) for v in np.maximum((hi - lo) / 2, 1e-3)), lights=count)


def _scene_of(ds: Dataset):
    """The scene a dataset was captured from (refused if its file changed since: other geometry)."""
    from diviewer.scene.loader import load_recorded_scene

    return load_recorded_scene(ds.manifest, ds.root / "manifest.json", "it changed since the capture")


def raw_exposure(ds: Dataset, train_arr: np.ndarray) -> float:
    """`fit_exposure` on the train frames' GL direct light as stored (not divided by the light scale): the
    tone map `diviewer eval --data` fits, so validation and eval score alike."""
    from diviewer.contract.encoding import fit_exposure

    return float(fit_exposure([frame[..., ds.slices["direct"]] for frame in train_arr]))


def run_conditioning(enc: Encoding, ds: Dataset, train_idx: list[int], with_val: bool) -> tuple[tuple, tuple]:
    """Each train (and val) frame's camera and lights: its conditioning (`diviewer.contract.conditioning`) of its stored
    configuration over the whole stored frame, stacked in the order of the frames' arrays as ((cameras, lights) of
    train, (cameras, lights) of val): (N, CAMERA_PARAMS) and (N, 3 L) float32, None where the encoding takes none
    (and val's (None, None) without ``with_val``). The light scales come before the encoding (`run_light_scales`)."""
    if not (enc.world_inputs or enc.light_inputs):  # encodings 1 and 2: no frame's conditioning is kept
        return (None, None), (None, None)
    from diviewer.contract.conditioning import conditioning, needs_scene, stacked
    from diviewer.data.scales import dataset_scene

    scene = dataset_scene(ds) if needs_scene(enc) else None
    config = {f["index"]: f.get("config") for f in ds.frames}
    where = ds.root / "manifest.json"

    def of(idx: list[int]) -> tuple:
        return stacked([conditioning(scene, config.get(i), (ds.width, ds.height), enc, path=where) for i in idx])[1:]

    return of(train_idx), of(sorted(ds.indices("val"))) if with_val else (None, None)


def crop_widths(aspect_crops: tuple[float, float], height: int, width: int) -> tuple[int, int]:
    """The narrowest and widest aspect crop of a ``height`` x ``width`` frame (``aspect_crops`` x height, at most
    the frame's width); `crop_plan` draws between them uniformly, and the build's cost model takes their mean."""
    lo, hi = aspect_crops
    w_lo = max(2, min(width, int(math.ceil(lo * height))))
    return w_lo, max(w_lo, min(width, int(math.floor(hi * height))))


def crop_plan(cfg: TrainConfig, epoch: int, batch: int, n: int, height: int, width: int) -> tuple[int, list[int]] | None:
    """This batch's random aspect crop, or None: one width for the whole batch (`crop_widths`) and each frame's
    left edge. A pure function of (seed, epoch, batch), like the data order, so a resumed run crops exactly as an
    uninterrupted one."""
    if not cfg.aspect_crops:
        return None
    w_lo, w_hi = crop_widths(cfg.aspect_crops, height, width)
    rng = np.random.default_rng([cfg.seed, 0xA5EC7, epoch, batch])
    w = int(rng.integers(w_lo, w_hi + 1))
    return w, [int(x) for x in rng.integers(0, width - w + 1, size=n)]


def split_batch(x16: torch.Tensor, slices: Mapping[str, slice], enc: Encoding, cfg: TrainConfig,
                scale: torch.Tensor | None = None, multiple: int = 1,
                crop: tuple[int, list[int]] | None = None, cams: torch.Tensor | None = None,
                lights: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """A stored (N, H, W, C) batch on the device -> real_A (encoded inputs), real_B (encoded target),
    and the raw NCHW planes the composition, the losses and the metrics need (direct, albedo, pt,
    target: the linear target radiance, divided by the light scale for encoding version 2).

    Args:
        scale: (N,) each frame's light scale (encoding version 2; ignored for version 1).
        multiple: frames are edge-padded to multiples of this (`diviewer.contract.padding`, as the runtime pads);
            ``mask`` (1 on the frame's pixels, 0 on the padding) and ``crop`` (the frame's rows and columns
            in the padded planes) say where the frame lies.
        crop: (width, left edges): each frame cut to that width first (`crop_plan`).
        cams: (N, CAMERA_PARAMS) each frame's camera over its whole stored frame (encoding version 3: the world
            planes are computed on the padded crop, as the graph computes them on the runtime's padded frame).
        lights: (N, 3 L) each frame's lights (encoding version 4, `run_conditioning`).
    """
    import torch

    from diviewer.contract.encoding import inverse_light_scale
    from diviewer.contract.padding import crop_slice, pad_index, valid_mask
    from diviewer.train.encoding_torch import TORCH_OPS, encode_inputs, encode_radiance

    x = x16.permute(0, 3, 1, 2).float()
    left = [0] * x.shape[0]
    if crop is not None:
        w, left = crop
        x = torch.stack([x[i, :, :, o:o + w] for i, o in enumerate(left)])
    h, w = x.shape[2], x.shape[3]
    mask = None
    if h % multiple or w % multiple:
        rows, cols = (torch.from_numpy(pad_index(n, multiple)).to(x.device) for n in (h, w))
        x = x.index_select(2, rows).index_select(3, cols)
        mask = torch.from_numpy(np.outer(valid_mask(h, multiple), valid_mask(w, multiple))).to(x.device)[None, None]
    x = x.contiguous()
    p = {name: x[:, s] for name, s in slices.items()}
    direct_in, inv = p["direct"], None
    if enc.light_scaled:
        if scale is None:
            raise ValueError("encoding version 2 needs each frame's light scale")
        inv = inverse_light_scale(scale.to(x.device, torch.float32), TORCH_OPS).reshape(-1, 1, 1, 1)
        direct_in = direct_in * inv
    real_A = encode_inputs(p["depth"], p["normal"], p["albedo"], direct_in, enc, channel_axis=1)
    if enc.world_inputs:
        from diviewer.contract.padding import pad_before, shift_camera_params
        from diviewer.train.world import world_planes

        if cams is None:
            raise ValueError("encoding version 3 needs each frame's camera")
        cams = cams.to(x.device, torch.float32)
        cams = shift_camera_params(cams, torch.as_tensor(left, dtype=cams.dtype, device=cams.device),
                                   (pad_before(w, multiple), pad_before(h, multiple)), (w, h))
        real_A = torch.cat([real_A, world_planes(p["depth"], p["normal"], cams, enc.world_center, enc.world_half)], 1)
    if enc.light_inputs:
        from diviewer.train.world import light_planes

        if lights is None:
            raise ValueError("encoding version 4 needs each frame's lights")
        real_A = torch.cat([real_A, light_planes(lights.to(x.device, torch.float32), p["depth"])], 1)
    target = target_radiance(p["pt"], p["pt_direct"], p["albedo"], cfg.target, cfg.divide_albedo, p["direct"])
    if inv is not None:
        target = target * inv
    real_B = encode_radiance(target, enc.output())
    out = {"real_A": real_A, "real_B": real_B, "direct": p["direct"], "albedo": p["albedo"], "pt": p["pt"],
           "target": target, "mask": mask, "crop": (crop_slice(h, multiple), crop_slice(w, multiple))}
    if inv is not None:
        out["scale"] = scale.to(x.device, torch.float32).reshape(-1, 1, 1, 1)
    return out
