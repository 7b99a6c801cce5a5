"""What `diviewer export` refuses before it writes a model: broken weights and outputs that verify nothing; and the
frame of broken values (`extreme_frame`) it checks the graph on.

A checkpoint with NaN/Inf weights or a negative BatchNorm running variance is broken however it was
made (a diverged run, a hand edit, a truncated copy); a generator whose output is constant or
non-finite on the verification frames is dead, and comparing two such outputs ("PSNR inf") verifies
nothing. For ``--fp16`` every weight must fit float16 (largest 65504), and the fp16 graph must stay
within `FP16_TOLERANCE` of the float32 PyTorch output.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError

FP16_MAX = 65504.0
"""Largest finite float16: a weight beyond it becomes infinite in an fp16 export."""

FP16_TOLERANCE = 1e-2
"""fp16 export fails if max |onnx fp16 - torch fp32| exceeds this fraction of the reference's peak radiance.
Measured 3.9e-4 (the shipped cornell K=16 fp16 model) and 5.6e-4 (tests' tiny model): float16's 11-bit
mantissa through a dozen layers; 1e-2 leaves room for deeper models and refuses a graph that overflowed
or lost a layer's range."""
HALF_WEIGHTS_TOLERANCE = FP16_TOLERANCE
"""The same for fp32 with ``half_weights``: float16's rounding of every weight (2**-11 of it at most) through
the network. Measured on cornell v3 K=16 (4 capture frames): 2.0e-3 of peak at the worst pixel, a mean
|difference| of 6e-6 (PSNR 108 dB against PyTorch); its scores on the compact evaluation set are the float32
file's to 0.01 dB. No tighter than a float16 graph's, whose every product is rounded so."""
INT8_WEIGHTS_TOLERANCE = 5e-2
"""The same for fp32 with ``int8_weights``: the inner convolutions' weights rounded to 1/254 of their output
channel's range. Measured against the shipped half-weights files on their compact evaluation sets (the stored
direct light): Sponza K=8 2.6e-2 of peak at the worst pixel of 15 frames (median frame 1.0e-2), cornell K=16
3.7e-3; their scores there move by 0.02 dB and 0.0005 of SSIM at most (docs/training.md)."""

CONSTANT_SPREAD = 1e-6
"""The generator's output is constant when its spread (max - min over every pixel of every verification
frame) is at most this fraction of its magnitude (or this absolute value for an all-zero output)."""


def refuse_broken(netG, ref_module, frames: np.ndarray, fp16: bool, ckpt_path: Path, scales=None,
                  cams=None, lights=None) -> np.ndarray:
    """Check the generator's weights, run the float32 reference on ``frames`` and check its outputs.

    Returns:
        The reference output of ``ref_module`` (N, H, W, 3), which export compares the ONNX graph against.

    Raises:
        DiviewerError: non-finite weights, a negative BatchNorm variance, weights beyond float16 with
            ``fp16``, or an output that is non-finite or constant, naming the checkpoint and the tensor.
    """
    import torch

    check_weights(netG, fp16, ckpt_path)
    captured = []
    hook = netG.register_forward_hook(lambda _m, _i, out: captured.append(out.detach().float().numpy()))
    try:
        with torch.no_grad():
            extra = [torch.from_numpy(a.astype(np.float32)) for a in (scales, cams, lights) if a is not None]
            reference = ref_module(torch.from_numpy(frames), *extra).numpy()  # encodings 2, 3, 4's inputs
    finally:
        hook.remove()
    check_outputs(np.concatenate(captured), reference, len(frames), ckpt_path)
    return reference


def check_weights(netG, fp16: bool, ckpt_path: Path) -> None:
    """Refuse non-finite weights or buffers, negative BatchNorm running variances, and (``fp16``) values
    beyond float16's range, naming the first offending tensor."""
    for name, t in netG.state_dict().items():
        if not t.is_floating_point():
            continue  # BatchNorm's num_batches_tracked
        a = t.detach().double().cpu().numpy()
        if not np.all(np.isfinite(a)):
            raise DiviewerError(f"the generator's weights are broken: {name} has {int((~np.isfinite(a)).sum())} NaN/Inf "
                                f"values (a diverged run?); export an earlier checkpoint", path=ckpt_path, field=name)
        if name.endswith("running_var") and a.size and a.min() < 0:
            raise DiviewerError(f"the generator's weights are broken: BatchNorm {name} has a negative variance "
                                f"({a.min():.3g}); export an earlier checkpoint", path=ckpt_path, field=name)
        if fp16 and a.size and np.abs(a).max() > FP16_MAX:
            raise DiviewerError(f"{name} holds {np.abs(a).max():.3g}, beyond float16's range ({FP16_MAX:g}): a "
                                f"float16 export (--fp16, --half-weights, --int8-weights' end layers) would make "
                                f"it infinite; export without them",
                                path=ckpt_path, field=name)


def check_outputs(net_out: np.ndarray, reference: np.ndarray, frames: int, ckpt_path: Path) -> None:
    """Refuse a generator whose raw output (``net_out``, before decoding) or final radiance (``reference``) is
    non-finite, or whose raw output is constant, on the verification frames."""
    for what, a in (("generator output", net_out), ("radiance", reference)):
        if not np.all(np.isfinite(a)):
            raise DiviewerError(f"the model's {what} has {int((~np.isfinite(a)).sum())} NaN/Inf values on the "
                                f"{frames} verification frames: the model is broken; not exported", path=ckpt_path)
    spread = float(net_out.max() - net_out.min()) if net_out.size else 0.0
    if spread <= CONSTANT_SPREAD * max(float(np.abs(net_out).max()) if net_out.size else 0.0, 1.0):
        raise DiviewerError(f"the generator's output is constant ({float(net_out.flat[0]) if net_out.size else 0:.4g}) "
                            f"on the {frames} verification frames: a dead or diverged network, which no comparison "
                            f"with PyTorch can verify; not exported", path=ckpt_path)


def extreme_frame(frame: np.ndarray) -> np.ndarray:
    """A copy of one (H, W, 10) frame with NaN, +-Inf, +-1e30, 0 and 1e-30 written into every channel at a
    few pixels each: the export's check that the graph treats broken buffers as training's functions do."""
    x = frame.copy()
    values = (np.nan, np.inf, -np.inf, 1e30, -1e30, 0.0, 1e-30)
    h, w = x.shape[:2]
    for c in range(x.shape[-1]):
        for k, v in enumerate(values):
            x[(3 * c + k) % h, (5 * k + c) % w, c] = v
    return x


def refuse_departures(check: dict, reference: np.ndarray, fp16: bool, stored: str, precision: str,
                      out: Path) -> None:
    """Refuse, naming ``out``, a graph whose verification record ``check`` departs from PyTorch's ``reference``:
    non-finite where PyTorch is finite, non-finite elsewhere on extreme buffers, or beyond its tolerance."""
    tolerance, same_nonfinite = check["tolerance_rel_to_peak"], check["extremes_same_nonfinite"]
    if np.isfinite(reference).all() and not check["onnx_finite"]:
        raise DiviewerError(f"the {precision} ONNX model produced NaN/Inf where PyTorch did not "
                            f"(overflow?); not written", path=out)
    if not same_nonfinite:
        raise DiviewerError(f"on NaN/Inf/extreme buffers the {precision} ONNX model is non-finite at other pixels "
                            "than PyTorch; not written", path=out)
    if fp16 and not check["max_rel_to_peak"] <= FP16_TOLERANCE:
        raise DiviewerError(f"the fp16 ONNX model differs from PyTorch by {check['max_rel_to_peak']:.2g} of peak "
                            f"(tolerance {FP16_TOLERANCE}); export without --fp16; not written", path=out)
    if not fp16 and max(check["max_rel_to_peak"], check["extremes_max_rel_to_peak"]) > tolerance:
        raise DiviewerError(f"the ONNX model{'' if stored == 'fp32' else f' with {stored}-stored weights'} "
                            f"differs from PyTorch by {check['max_rel_to_peak']:.2g} of peak "
                            f"({check['extremes_max_rel_to_peak']:.2g} on extreme buffers; tolerance "
                            f"{tolerance}); not written", path=out)


def verification_line(check: dict, precision: str) -> str:
    """The export's verification (``check``, as the card records it) in plain words, on one line."""
    words = [f"verified the {precision} model against PyTorch on {check['frames']}: it differs by at most "
             f"{check['max_rel_to_peak']:.2g} of the image's peak (PSNR {check['psnr_db']:.1f} dB)",
             "extreme and broken inputs give the same finite and non-finite pixels"
             if check["extremes_same_nonfinite"] else "extreme inputs differ in which pixels are finite"]
    if "zero_light_max" in check:
        words.append(f"no light gives black, twice the light twice the image (to "
                     f"{check['twice_light_max_rel_to_peak']:.1g} of the peak)")
    return "; ".join(words)
