"""One frame's images for the view modes, as GL textures: G-buffers, the network's output, VXGI, the reference.

``FrameImages`` implements ``view_modes.FrameSources``: the neural pass runs at most once a frame, and
only when a shown mode needs it; the path-traced reference is uploaded when a newer image is ready.
"""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.gl.display import Image
from diviewer.viewer.view_modes import Unavailable, ViewMode


class ReferenceTexture:
    """The progressive reference's latest image on the GPU, re-uploaded when a newer one is published."""

    def __init__(self, ctx: moderngl.Context, reference, max_size: int):
        self.ctx, self.reference, self.max_size = ctx, reference, max_size
        self.texture: moderngl.Texture | None = None
        self._serial = -1

    def image(self, scene, config, view_size: tuple[int, int]) -> Image:
        """The reference of this view (requested at most ``max_size`` on its longest side); Unavailable until
        one is ready."""
        ref = self.reference
        if not ref.available:
            raise Unavailable(str(ref.error))
        gw, gh = view_size
        s = min(1.0, self.max_size / max(gw, gh))
        ref.request(scene, config, max(1, round(gw * s)), max(1, round(gh * s)))
        img = ref.latest()
        if img is None:
            raise Unavailable(ref.status())
        if img.serial != self._serial:
            h, w = img.image.shape[:2]
            if self.texture is None or self.texture.size != (w, h):
                self.release()
                self.texture = self.ctx.texture((w, h), 3, dtype="f4")
                self.texture.filter = (moderngl.LINEAR, moderngl.LINEAR)
                self.texture.repeat_x = self.texture.repeat_y = False
            self.texture.write(img.image.tobytes())
            self._serial = img.serial
        return Image(self.texture, flip=True)

    def release(self) -> None:
        if self.texture is not None:
            self.texture.release()
            self.texture = None


class FrameImages:
    """What the view modes draw from in one frame (``FrameSources``); each image knows its orientation."""

    def __init__(self, viewer):
        self.v = viewer
        self.has_model = viewer.neural is not None
        self._neural: Image | None = None
        self._final: Image | None = None
        self._vxgi: Image | None = None

    def buffer(self, name: str) -> Image:
        """One of the frame's buffers (`Renderer.buffer`): the deferred direct pass runs only for ``direct``."""
        return Image(self.v.renderer.buffer(name))

    def network_output(self) -> Image:
        v = self.v
        if v.neural is None:
            raise Unavailable(v.state.model_message or "no model loaded")
        if self._neural is None:
            # the frame's conditioning (contract.conditioning), as its encoding takes it
            inputs = v.neural.inputs_for(v.state.scene, v.state.config)
            self._neural = Image(v.neural.run(**inputs), flip=True)  # stages go to the viewer's timer
        return self._neural

    def final(self) -> Image:
        """The full-resolution frame: direct light + the network's indirect light, upsampled."""
        if self._final is None:
            self.network_output()
            self._final = Image(self.v.neural.composite())
        return self._final

    def reference(self) -> Image:
        st = self.v.state
        return self.v.reference_texture.image(st.scene, st.config, self.v.render_size)

    def vxgi(self) -> Image:
        """The VXGI image, traced at most once a frame; its grid is rebuilt only where the frame changed."""
        v = self.v
        if self._vxgi is None:
            if v.vxgi is None:
                from diviewer.gl.vxgi import VXGIPass

                v.vxgi = VXGIPass(v.ctx, v.renderer, timer=v.timer)  # stages go to the viewer's timer
            v.vxgi.run(v.state.config)
            self._vxgi = Image(v.vxgi.textures["vxgi"])
        return self._vxgi

    def produce(self, mode: ViewMode) -> Image:
        """The mode's image, shown as its display kind; Unavailable propagates with the reason."""
        img = mode.produce(self)
        return Image(img.texture, img.flip, mode.display)


def black_texture(ctx: moderngl.Context) -> moderngl.Texture:
    """A 1x1 black texture: what an unavailable mode shows."""
    return ctx.texture((1, 1), 3, np.zeros(3, np.float32).tobytes(), dtype="f4")
