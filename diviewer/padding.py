"""How a frame of any size is padded to the network's stride and cropped back, defined once (no torch).

A U-Net of L levels needs H and W multiples of 2**L. A frame of another size (a window of any shape, a
random-width training crop) is padded by replicating its edge pixels, the padding split evenly between
the two sides (one more pixel at the bottom / right when it is odd), then the network's output is cropped
back to the frame. Replicated edges are what a render of a slightly larger view would show first
(the same surface continues), where zeros would read as "background" to the network.

Training (`diviewer.train.targets`) and the runtime (`diviewer.runtime.NeuralGI.run`) both pad with
`pad_index`: gathering rows and columns through these index arrays works on numpy arrays and on torch
tensors alike, so the two pad exactly alike.
"""

from __future__ import annotations

import numpy as np


def padded_size(n: int, multiple: int) -> int:
    """The smallest multiple of ``multiple`` that holds ``n`` pixels (n itself when it is one)."""
    if n < 1 or multiple < 1:
        raise ValueError(f"size {n} and multiple {multiple} must be positive")
    return -(-n // multiple) * multiple


def pad_before(n: int, multiple: int) -> int:
    """Pixels of padding before the frame (top or left) along an axis of ``n`` pixels."""
    return (padded_size(n, multiple) - n) // 2


def pad_index(n: int, multiple: int) -> np.ndarray:
    """For each pixel of the padded axis, the frame's pixel it copies (edge replication), int64."""
    before = pad_before(n, multiple)
    return np.clip(np.arange(padded_size(n, multiple)) - before, 0, n - 1).astype(np.int64)


def crop_slice(n: int, multiple: int) -> slice:
    """Where the frame's ``n`` pixels lie along the padded axis."""
    before = pad_before(n, multiple)
    return slice(before, before + n)


def valid_mask(n: int, multiple: int) -> np.ndarray:
    """1 where the padded axis holds a frame pixel, 0 on the padding (float32)."""
    m = np.zeros(padded_size(n, multiple), np.float32)
    m[crop_slice(n, multiple)] = 1.0
    return m


def pad_nhwc(x: np.ndarray, multiple: int) -> np.ndarray:
    """(N, H, W, C) numpy frames edge-padded to multiples of ``multiple`` (x itself if they already are)."""
    h, w = x.shape[1], x.shape[2]
    if h % multiple == 0 and w % multiple == 0:
        return x
    return np.ascontiguousarray(x[:, pad_index(h, multiple)][:, :, pad_index(w, multiple)])


def crop_nhwc(y: np.ndarray, height: int, width: int, multiple: int) -> np.ndarray:
    """The (N, height, width, C) frame out of a padded (N, H', W', C) output."""
    if y.shape[1] == height and y.shape[2] == width:
        return y
    return np.ascontiguousarray(y[:, crop_slice(height, multiple), crop_slice(width, multiple)])


def shift_camera_params(cams, left, pad: tuple[int, int], size: tuple[int, int]):
    """Cameras (`diviewer.scene.camera.camera_params`, (..., 20), numpy or torch) of whole frames -> those of their
    ``size`` (width, height) crops at columns ``left`` (a number or one per frame), padded by ``pad`` (left, top):
    rays shifted by the crop and the padding, clamped to the crop's pixels (so the padding replicates the edge
    rays, as it replicates the edge pixels)."""
    out = cams.clone() if hasattr(cams, "clone") else np.array(cams, np.float32, copy=True)
    (px, py), (w, h) = pad, size
    out[..., 13] = out[..., 13] + out[..., 12] * (left - px)
    out[..., 15] = out[..., 15] - out[..., 14] * py
    out[..., 16], out[..., 17], out[..., 18], out[..., 19] = px, px + w - 1, py, py + h - 1
    return out


def pad_camera_params(cams, width: int, height: int, multiple: int) -> np.ndarray:
    """Cameras of ``width`` x ``height`` frames -> those of the frames padded to ``multiple`` (`shift_camera_params`)."""
    return shift_camera_params(cams, 0, (pad_before(width, multiple), pad_before(height, multiple)), (width, height))
