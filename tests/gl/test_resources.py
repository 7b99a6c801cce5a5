"""diviewer.gl.resources: material textures in half floats, mipmapped, top row first, alpha kept."""

from __future__ import annotations

import numpy as np

from diviewer.gl.resources import upload_texture


def test_a_material_texture_is_half_floats_within_a_quarter_thousandth_of_its_linear_values(ctx):
    """Every 8-bit sRGB level decoded to linear, in a 16x16 image: the texture holds it within 2.5e-4 (half
    floats, half float32's memory), GL's bottom row is the image's last, the alpha is the one given, and the
    mipmap chain's last level is the image's mean."""
    levels = np.arange(256) / 255.0
    linear = np.where(levels <= 0.04045, levels / 12.92, ((levels + 0.055) / 1.055) ** 2.4).reshape(16, 16)
    image = np.stack([linear, linear[::-1], np.full_like(linear, 0.5)], -1).astype(np.float32)
    alpha = (np.arange(256).reshape(16, 16) % 2).astype(np.float32)
    tex = upload_texture(ctx, image, alpha)
    assert tex.dtype == "f2" and tex.components == 4
    back = np.frombuffer(tex.read(), dtype=np.float16).reshape(16, 16, 4).astype(np.float64)
    np.testing.assert_allclose(back[::-1, :, :3], image, atol=2.5e-4, rtol=0)  # GL's t = 0: the last row
    np.testing.assert_array_equal(back[::-1, :, 3], alpha)
    top = np.frombuffer(tex.read(level=4), dtype=np.float16).reshape(4).astype(np.float64)  # 1x1
    np.testing.assert_allclose(top[:3], image.reshape(-1, 3).mean(0), atol=2e-3)
    tex.release()
