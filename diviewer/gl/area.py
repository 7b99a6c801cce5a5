"""The GL direct light over each pixel's area: rendered at ``samples`` x ``samples`` times the frame's size and
box-filtered back to it, as the path tracer's box pixel filter sees a pixel.

A G-buffer pixel holds the surface at its centre, so its direct light (shadow test and shading) is that point's;
the truth of the same pixel is the mean over its area. At every silhouette, shadow edge and terminator the two
differ by up to the whole pixel's light, and a network that adds indirect light to the point's direct light
cannot know the share of the pixel that was lit (docs/generalisation.md at commit c48f1bc: a perfect indirect-light network is
capped at 37.5 dB with cornell's camera moved and 24-26 dB on the object's unlit pixels; over 4 x 4 samples, 50.8
and 42 dB). Models trained on such a direct light (`diviewer data area-direct`) record ``direct_samples`` on
their card, and every path that feeds them computes it the same way (this module at the model's resolution; the
viewer from its window-resolution buffer, `pack.glsl`'s ``AREA_DIRECT``).
"""

from __future__ import annotations

import numpy as np

from diviewer.errors import DiviewerError

MAX_SAMPLES = 8
"""Samples per axis at most (64 per pixel): beyond it the supersampled frame's cost buys nothing measurable."""


def check_samples(samples, field: str = "samples") -> int:
    """``samples`` as a positive int of at most MAX_SAMPLES, or a one-line error naming ``field``."""
    if isinstance(samples, bool) or not isinstance(samples, int) or not 1 <= samples <= MAX_SAMPLES:
        raise DiviewerError(f"must be a whole number of samples per axis in 1..{MAX_SAMPLES}, got {samples!r}",
                            field=field)
    return samples


def box_filter(image: np.ndarray, samples: int) -> np.ndarray:
    """(H*s, W*s, C) -> (H, W, C): the mean of each pixel's s x s block."""
    hs, ws, c = image.shape
    h, w = hs // samples, ws // samples
    if (h * samples, w * samples) != (hs, ws):
        raise ValueError(f"{ws}x{hs} is not a multiple of {samples}")
    return image.reshape(h, samples, w, samples, c).mean(axis=(1, 3), dtype=np.float64).astype(np.float32)


class AreaDirect:
    """The direct light of configurations at (width, height), each pixel the mean of ``samples`` x ``samples``
    sub-pixel samples; its own renderer at the supersampled size, so the caller's renderer keeps its buffers."""

    def __init__(self, ctx, scene, width: int, height: int, samples: int, settings=None):
        from diviewer.gl.renderer import Renderer

        self.width, self.height, self.samples = int(width), int(height), check_samples(samples)
        self.renderer = Renderer(ctx, scene, self.width * self.samples, self.height * self.samples, settings)

    def __call__(self, config) -> np.ndarray:
        """(H, W, 3) float32 linear direct light (and visible emission) of ``config``, top row first."""
        self.renderer.render(config)
        return box_filter(self.renderer.read("direct"), self.samples)

    def release(self) -> None:
        self.renderer.release()
