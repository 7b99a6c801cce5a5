"""How a frame of any size is padded to the network's stride and cropped back, defined once (no torch).

A U-Net of L levels needs H and W multiples of 2**L. A frame of another size (a window of any shape, a
random-width training crop) is padded by replicating its edge pixels, the padding split evenly between
the two sides (one more pixel at the bottom / right when it is odd), then the network's output is cropped
back to the frame. Replicated edges are what a render of a slightly larger view would show first
(the same surface continues), where zeros would read as "background" to the network.

Training (`diviewer.train.targets`) and the runtime (`diviewer.contract.runtime.NeuralGI.run`) both pad with
`pad_index`: gathering rows and columns through these index arrays works on numpy arrays and on torch
tensors alike, so the two pad exactly alike.

A ``guard`` asks for at least that many pixels of padding a side: a frame the stride would pad by less (a 128-wide
frame at a stride of 128: none) is padded to the next multiple instead. The runtime guards the columns of models
trained on random-width crops (`EDGE_GUARD`, `edge_guard`): such a network has nearly always seen its frame's left
and right edges with a wide band of replicated columns beside them, and run on a frame that fills the stride it
loses 1-2 dB in the columns next to the edges (docs/sponza.md at commit c48f1bc, "The frame's edge").
"""

from __future__ import annotations

import numpy as np


EDGE_GUARD = 8
"""Columns of padding a side at least, for a network trained on random-width crops (`edge_guard`). Measured on
Sponza's and cornell's shipped models (docs/sponza.md at commit c48f1bc, "The frame's edge"): 128-wide frames lose 0.9-2.2 dB
unguarded, 126-wide (1 a side) 0.7-1.6, 120-wide (4) 0.4-0.8; 130-wide (63 a side) 0.1-0.2, the context alone."""


def edge_guard(aspect_crops) -> int:
    """The column guard the runtime gives a model trained with these ``aspect_crops`` (None: whole frames, whose
    edges always filled the stride in training, are not guarded)."""
    return EDGE_GUARD if aspect_crops else 0


def padded_size(n: int, multiple: int, guard: int = 0) -> int:
    """The smallest multiple of ``multiple`` that holds ``n`` pixels and ``guard`` more a side (n itself when it is
    a multiple and there is no guard)."""
    if n < 1 or multiple < 1 or guard < 0:
        raise ValueError(f"size {n} and multiple {multiple} must be positive, guard {guard} not negative")
    return -(-(n + 2 * guard) // multiple) * multiple


def pad_before(n: int, multiple: int, guard: int = 0) -> int:
    """Pixels of padding before the frame (top or left) along an axis of ``n`` pixels."""
    return (padded_size(n, multiple, guard) - n) // 2


def pad_index(n: int, multiple: int, guard: int = 0) -> np.ndarray:
    """For each pixel of the padded axis, the frame's pixel it copies (edge replication), int64."""
    before = pad_before(n, multiple, guard)
    return np.clip(np.arange(padded_size(n, multiple, guard)) - before, 0, n - 1).astype(np.int64)


def crop_slice(n: int, multiple: int, guard: int = 0) -> slice:
    """Where the frame's ``n`` pixels lie along the padded axis."""
    before = pad_before(n, multiple, guard)
    return slice(before, before + n)


def valid_mask(n: int, multiple: int, guard: int = 0) -> np.ndarray:
    """1 where the padded axis holds a frame pixel, 0 on the padding (float32)."""
    m = np.zeros(padded_size(n, multiple, guard), np.float32)
    m[crop_slice(n, multiple, guard)] = 1.0
    return m


def pad_nhwc(x: np.ndarray, multiple: int, guard: int = 0) -> np.ndarray:
    """(N, H, W, C) numpy frames edge-padded to multiples of ``multiple``, at least ``guard`` columns a side (x
    itself if they are multiples already and there is no guard). Rows are never guarded."""
    h, w = x.shape[1], x.shape[2]
    if h % multiple == 0 and w % multiple == 0 and not guard:
        return x
    return np.ascontiguousarray(x[:, pad_index(h, multiple)][:, :, pad_index(w, multiple, guard)])


def crop_nhwc(y: np.ndarray, height: int, width: int, multiple: int, guard: int = 0) -> np.ndarray:
    """The (N, height, width, C) frame out of a padded (N, H', W', C) output (padded with this column ``guard``)."""
    if y.shape[1] == height and y.shape[2] == width:
        return y
    return np.ascontiguousarray(y[:, crop_slice(height, multiple), crop_slice(width, multiple, guard)])


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


def pad_camera_params(cams, width: int, height: int, multiple: int, guard: int = 0) -> np.ndarray:
    """Cameras of ``width`` x ``height`` frames -> those of the frames padded to ``multiple`` with this column
    ``guard`` (`shift_camera_params`)."""
    return shift_camera_params(cams, 0, (pad_before(width, multiple, guard), pad_before(height, multiple)),
                               (width, height))
