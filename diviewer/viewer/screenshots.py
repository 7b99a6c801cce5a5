"""Screenshots: the view (without the panel) as PNG with the frame's JSON, or the whole window as PNG.

Asked for at any time, saved at the end of the next frame, so that the image and the recorded
configuration are the same frame. The JSON is the frame.json that ``diviewer render --config`` reads,
plus the view settings.
"""

from __future__ import annotations

import json
from pathlib import Path

import moderngl

from diviewer import imageio
from diviewer.frames import frame_record
from diviewer.gl.context import unbind_framebuffer
from diviewer.gl.display import read_rgb8
from diviewer.viewer.state import ViewerState
from diviewer.viewer.view_modes import view_mode


def view_record(state: ViewerState, size: tuple[int, int], model_path: Path | None, gl_renderer: str,
                **extra) -> dict:
    """The frame.json of the state's current frame, with how it was shown (view mode, model, display, and
    ``extra``: the GI resolution and settings)."""
    st = state
    return frame_record(st.scene, st.config, size, view_mode=st.view_mode,
                        compare=list(st.compare) if view_mode(st.view_mode).layout != "single" else None,
                        model=str(model_path) if model_path is not None else None,
                        model_message=st.model_message or None, provider=st.provider or None,
                        display={"exposure": st.exposure, "tonemap": st.tonemap, "auto_exposure": st.auto_exposure},
                        gl_renderer=gl_renderer, user_meshes=dict(st.user_meshes) or None, **extra)


class Screenshots:
    """Pending and saved screenshots, and the offscreen target the view is redrawn into."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.pending: list[Path] = []
        self.pending_window: list[Path] = []
        self.saved: list[Path] = []
        self._target: tuple | None = None

    def request(self, path: str | Path) -> Path:
        """Save the view (PNG, made so if the suffix differs) and its JSON at the end of the next frame."""
        path = Path(path)
        if path.suffix.lower() != ".png":
            path = path.with_suffix(".png")
        self.pending.append(path)
        return path

    def request_window(self, path: str | Path) -> Path:
        """Save the whole window (with the panel) as PNG at the end of the next frame."""
        path = Path(path)
        self.pending_window.append(path)
        return path

    def target(self, size: tuple[int, int]) -> moderngl.Framebuffer:
        """The offscreen framebuffer of ``size`` the view is redrawn into before `save_view` saves it."""
        if self._target is None or self._target[0].size != size:
            self._release_target()
            tex = self.ctx.texture(size, 4)
            self._target = (tex, self.ctx.framebuffer([tex]))
        return self._target[1]

    def save_view(self, path: Path, record: dict) -> Path:
        """Save the view redrawn into `target` as PNG, with ``record`` as the JSON beside it."""
        fbo = self._target[1]
        path.parent.mkdir(parents=True, exist_ok=True)
        imageio.write_png(path, read_rgb8(fbo))
        imageio.write_text(path.with_suffix(".json"), json.dumps(record, indent=2))
        self.saved.append(path)
        return path

    def save_window(self, path: Path, rgb) -> Path:
        """Save the window's own pixels (``Window.read_pixels``, read before the swap) as PNG."""
        path.parent.mkdir(parents=True, exist_ok=True)
        imageio.write_png(path, rgb)
        return path

    def _release_target(self) -> None:
        if self._target is not None:
            unbind_framebuffer(self.ctx)
            self._target[1].release()
            self._target[0].release()
            self._target = None

    def release(self) -> None:
        self._release_target()
