"""One frame's images for the view modes, as GL textures: G-buffers, the network's output, VXGI, the reference.

``FrameImages`` implements ``view_modes.FrameSources`` from what it is given (the renderer, the neural pass, the
state, the reference's texture, the viewer's ``VXGISlot``), never from the viewer: the neural pass runs at most once
a frame, and only when a shown mode needs it; the path-traced reference is uploaded when a newer image is ready.
The app asks ``view_modes.produce`` for a mode's image, which calls these.
"""

from __future__ import annotations

import moderngl
import numpy as np

from diviewer.gl.display import Image
from diviewer.viewer.view_modes import Unavailable


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


class VXGISlot:
    """The viewer's VXGI pass, made the first time a frame asks for it and kept between frames."""

    def __init__(self, ctx: moderngl.Context, renderer, timer=None):
        self.ctx, self.renderer, self.timer = ctx, renderer, timer
        self.pass_ = None
        """The ``gl.vxgi.VXGIPass``, or None until the VXGI view mode is first shown."""

    def get(self):
        """The pass, made now if it is not yet (its stages go to the viewer's timer)."""
        if self.pass_ is None:
            from diviewer.gl.vxgi import VXGIPass

            self.pass_ = VXGIPass(self.ctx, self.renderer, timer=self.timer)
        return self.pass_

    def release(self) -> None:
        if self.pass_ is not None:
            self.pass_.release()
            self.pass_ = None


class FrameImages:
    """What the view modes draw from in one frame (``FrameSources``); each image knows its orientation.

    Args:
        renderer: the frame's ``gl.renderer.Renderer`` (its buffers drawn).
        neural: the model's ``gl.neural.NeuralPass``, or None without a model.
        state: the ``ViewerState`` the frame shows (its scene, configuration and why there is no model).
        reference_texture: the progressive reference on the GPU (``ReferenceTexture``).
        render_size: the shading resolution, the size the reference is asked for.
        vxgi: the viewer's ``VXGISlot``.
    """

    def __init__(self, renderer, neural, state, reference_texture: ReferenceTexture, render_size: tuple[int, int],
                 vxgi: VXGISlot):
        self.renderer, self.neural, self.state = renderer, neural, state
        self.reference_texture, self.render_size, self.vxgi_slot = reference_texture, render_size, vxgi
        self.has_model = neural is not None
        self._neural: Image | None = None
        self._final: Image | None = None
        self._vxgi: Image | None = None

    def buffer(self, name: str) -> Image:
        """One of the frame's buffers (`Renderer.buffer`): the deferred direct pass runs only for ``direct``."""
        return Image(self.renderer.buffer(name))

    def network_output(self) -> Image:
        if self.neural is None:
            raise Unavailable(self.state.model_message or "no model loaded")
        if self._neural is None:
            # the frame's conditioning (contract.conditioning), as its encoding takes it
            inputs = self.neural.inputs_for(self.state.scene, self.state.config)
            self._neural = Image(self.neural.run(**inputs), flip=True)  # stages go to the viewer's timer
        return self._neural

    def final(self) -> Image:
        """The full-resolution frame: direct light + the network's indirect light, upsampled."""
        if self._final is None:
            self.network_output()
            self._final = Image(self.neural.composite())
        return self._final

    def reference(self) -> Image:
        return self.reference_texture.image(self.state.scene, self.state.config, self.render_size)

    def vxgi(self) -> Image:
        """The VXGI image, traced at most once a frame; its grid is rebuilt only where the frame changed."""
        if self._vxgi is None:
            vxgi = self.vxgi_slot.get()
            vxgi.run(self.state.config)
            self._vxgi = Image(vxgi.textures["vxgi"])
        return self._vxgi


def black_texture(ctx: moderngl.Context) -> moderngl.Texture:
    """A 1x1 black texture: what an unavailable mode shows."""
    return ctx.texture((1, 1), 3, np.zeros(3, np.float32).tobytes(), dtype="f4")
