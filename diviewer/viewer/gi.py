"""The viewer's neural GI: which model runs, and its neural pass at the GI resolution asked for.

The GI resolution policy lives here: ``gi_res`` is ``model`` (the training row count, the window's shape), a
fraction of the shading resolution (it follows the window and the dynamic scale) or ``WxH``; a size the
model cannot run at is refused and changes nothing. The pass is rebuilt when the resolution, the pipelining
or the sizes it follows change. The sizes themselves are computed by ``models.gi_resolution``; where the
runtime cannot pad a shape to its stride, ``note`` says what was run instead, and where the shape is one the model
was not trained on, that its GI is extrapolated.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.gl.neural import GISettings
from diviewer.viewer.models import GI_FRACTIONS, gi_sizes, open_model
from diviewer.viewer.state import ViewerState


class GIControl:
    """The loaded model (``model``, a ``runtime.NeuralGI``) and its ``NeuralPass`` (``neural``), or neither."""

    def __init__(self, ctx, renderer, state: ViewerState, gi_res: str, settings: GISettings,
                 provider: str | None = None):
        self.ctx, self.renderer, self.state, self.provider = ctx, renderer, state, provider
        self.gi_res = str(gi_res)
        """What the user asked for: ``model``, a fraction (``1/4``) or ``WxH``."""
        self.settings = settings
        """How the inputs are reduced and the output upsampled, and whether inference runs a frame behind."""
        self.model = None
        self.neural = None
        self._fits: set[tuple[int, int]] = set()
        self.view_size: tuple[int, int] | None = None
        """The window's framebuffer size (the shape ``model`` follows); None: the render size."""
        self.note = ""
        """Why the GI runs at another shape than the window's (a runtime that pads no shape), and whether that
        shape is one the model never saw (`runtime.NeuralGI.shape_note`), or empty."""
        self._offered: tuple[tuple, tuple] = ((), ())  # (what they were computed for, the GI sizes offered)

    @property
    def render_size(self) -> tuple[int, int]:
        return self.renderer.width, self.renderer.height

    @property
    def size(self) -> tuple[int, int]:
        """The GI resolution the network runs at (the render size without a model)."""
        return self.neural.gi_size if self.neural is not None else self.render_size

    def sizes(self, model, gi_res: str, render_size: tuple[int, int] | None = None) -> tuple[tuple, tuple]:
        """(the GI size the runtime will run, the size asked for) for ``gi_res`` at ``render_size`` (default:
        the renderer's); they differ where the runtime cannot pad the asked shape to the model's stride."""
        render_size = render_size or self.render_size
        return gi_sizes(model, gi_res, render_size, self.view_size or render_size)

    def offered(self) -> tuple[tuple[str, tuple[int, int]], ...]:
        """(GI resolution, the size it runs at) for the training rows at the window's shape and each fraction of
        the shading size that the model can run at (the panel's list; empty without a model)."""
        if self.model is None:
            return ()
        key, (was, offered) = (self.model, self.render_size, self.view_size), self._offered
        if was and was[0] is key[0] and was[1:] == key[1:]:
            return offered
        out = []
        for spec in ("model",) + GI_FRACTIONS:
            try:
                out.append((spec, tuple(self.sizes(self.model, spec)[0])))
            except DiviewerError:
                continue
        self._offered = (key, tuple(out))
        return self._offered[1]

    def _size_for(self, model, gi_res: str, render_size: tuple[int, int]) -> tuple[int, int]:
        size, wanted = self.sizes(model, gi_res, render_size)
        notes = [] if size == wanted else [
            f"the runtime runs this model only at multiples of {model.multiple}: GI {size[0]}x{size[1]} instead "
            f"of {wanted[0]}x{wanted[1]} (the window's shape is squashed)"]
        shape = model.shape_note(*size)
        self.note = "; ".join(notes + ([shape] if shape else []))
        if size not in self._fits:  # a size beyond the GL limits is refused cleanly, before a pass allocates
            from diviewer.gl.context import check_render_size

            check_render_size(self.ctx, size[0], size[1], "--gi-res")
            self._fits.add(size)
        return size

    def _build(self, model) -> None:
        from diviewer.gl.neural import NeuralPass

        size = self._size_for(model, self.gi_res, self.render_size)
        self.neural = NeuralPass(self.ctx, self.renderer, model, size, self.settings)
        self.note = "; ".join(n for n in (self.note, self.neural.path_note) if n)  # a model without a lean path
        self.state.gi_res = self.gi_res

    def _rebuild(self) -> None:
        self.neural.release()
        self._build(self.model)

    def load(self, spec: str | Path | None) -> None:
        """Load a model (path, ``auto`` or ``none``); without one the state's message says why."""
        self.release()
        model, message = open_model(spec, self.state.scene, self.provider)
        st = self.state
        st.model_message, st.model_meta, st.provider = message, None, ""
        st.model_name = None
        if model is not None:
            # A GI resolution the model cannot run at is the user's request, not the model's fault: raised.
            self._size_for(model, self.gi_res, self.render_size)
            try:
                self._build(model)
            except DiviewerError as exc:
                st.model_message = f"model refused: {exc}"
                return
            self.model = model
            st.model_name = model.path.name
            st.model_meta = dict(model.meta)
            st.provider = model.provider
        if message and str(spec).lower() != "none":  # a named model refused, or none found for auto
            print(f"diviewer view: {message}", file=sys.stderr)

    def set_gi_res(self, spec: str) -> tuple[int, int]:
        """Run the network at another GI resolution (``model``, ``1/4``, ``WxH``); refused sizes change nothing."""
        if self.model is not None:
            self._size_for(self.model, str(spec), self.render_size)  # raises before anything changes
        self.gi_res = str(spec)
        if self.model is not None:
            self._rebuild()
        return self.size

    def set_pipelined(self, on: bool) -> None:
        """Run inference one frame behind on a worker thread (GL and onnxruntime overlap) or in the frame."""
        self.settings = dataclasses.replace(self.settings, pipelined=bool(on))
        if self.model is not None:
            self._rebuild()

    def follow_window(self, view_size: tuple[int, int] | None = None) -> None:
        """After the renderer was resized (the window, or the dynamic scale): ``model`` follows the window's
        shape, a fraction the shading resolution; an explicit WxH stays."""
        if view_size is not None:
            self.view_size = tuple(view_size)
        if self.neural is not None:
            if self._size_for(self.model, self.gi_res, self.render_size) != self.neural.gi_size:
                self._rebuild()

    def release(self) -> None:
        """Drop the neural pass and the model (and with it the onnxruntime session)."""
        if self.neural is not None:
            self.neural.release()
        self.neural = None
        self.model = None
