"""The display pass: linear images to display pixels (exposure, tone map, sRGB), for files and the window.

One pass owns both display programs: ``composite.glsl`` shows one radiance image (the final frame,
`diviewer render`'s and the dataset's PNGs), ``view.glsl`` shows the viewer's other view modes (raw
values, depth, normals, albedo, split screen, difference). Both include ``tonemap.glsl``; the
tone curves they know are named here and nowhere else.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from diviewer.errors import DiviewerError
from diviewer.gl.context import unbind_framebuffer
from diviewer.gl.resources import set_uniform
from diviewer.gl.shaders import ShaderCache
from diviewer.scene.model import FrameConfig, Scene

TONEMAPS: dict[str, int] = {"aces": 2, "reinhard": 1, "clamp": 0}
"""Tone curves by name (menu order, the default first) -> ``u_tonemap`` of shaders/tonemap.glsl."""
DEFAULT_TONEMAP = "aces"

KINDS: dict[str, int] = {"radiance": 0, "raw": 1, "depth": 2, "normal": 3, "albedo": 4}
"""What an image holds, which decides how it is shown (``u_kind_*`` of view.glsl)."""
LAYOUTS: dict[str, int] = {"single": 0, "split": 1, "difference": 2}
"""One image, two side by side, or their difference (``u_layout`` of view.glsl)."""


@dataclass(frozen=True)
class Image:
    """A GL texture to show and what it holds."""

    texture: moderngl.Texture
    flip: bool = False
    """Rows top first (the neural output, the path-traced reference): sampled upside down."""
    kind: str = "radiance"


@dataclass(frozen=True)
class Look:
    """How images are shown: exposure and tone curve, and the view modes' parameters."""

    exposure: float = 0.0
    """Stops."""
    tonemap: str = DEFAULT_TONEMAP
    depth_range: tuple[float, float] = (0.0, 1.0)
    """View-space depth shown brightest / darkest (``depth_range``)."""
    split: float = 0.5
    """Split-screen divider, fraction of the width."""
    diff_gain: float = 4.0
    """Multiplier of the difference image."""


def tonemap_code(name: str) -> int:
    """The shader's code of a tone curve; an unknown name is the user's error."""
    if name not in TONEMAPS:
        raise DiviewerError(f"unknown tone map '{name}'; use one of {', '.join(TONEMAPS)}", field="tonemap")
    return TONEMAPS[name]


def depth_range(scene: Scene, config: FrameConfig) -> tuple[float, float]:
    """The view-space depth range of the scene's bounding box: what the depth view spreads from bright to dark."""
    b = scene.bounds(config)
    corners = np.array([[b[i, 0], b[j, 1], b[k, 2], 1.0] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    z = -(config.camera.view_matrix() @ corners.T)[2]
    return max(float(z.min()), config.camera.near), max(float(z.max()), config.camera.near + 1e-3)


class DisplayPass:
    """Draws images into any framebuffer rectangle, and turns arrays into sRGB uint8 through the same shader."""

    def __init__(self, ctx: moderngl.Context, shaders: ShaderCache):
        self.ctx = ctx
        self.composite = shaders.program("composite.glsl")
        self.view = shaders.program("view.glsl")
        self._vaos = {p.glo: ctx.vertex_array(p, []) for p in (self.composite, self.view)}
        self._ldr: dict[tuple[int, int], tuple] = {}

    def _draw(self, prog: moderngl.Program) -> None:
        self._vaos[prog.glo].render(moderngl.TRIANGLES, vertices=3)

    def run(self, hdr: moderngl.Texture, target: moderngl.Framebuffer, exposure: float = 0.0,
            tonemap: str = DEFAULT_TONEMAP, flip_y: bool = False) -> None:
        """One radiance texture, exposed and tone-mapped, over ``target``'s viewport (composite.glsl)."""
        target.use()
        self.ctx.enable_only(moderngl.NOTHING)
        hdr.use(location=0)
        set_uniform(self.composite, "u_hdr", 0)
        set_uniform(self.composite, "u_exposure", float(exposure))
        set_uniform(self.composite, "u_tonemap", tonemap_code(tonemap))
        set_uniform(self.composite, "u_flip_y", bool(flip_y))
        self._draw(self.composite)

    def show(self, target: moderngl.Framebuffer, rect: tuple[int, int, int, int], a: Image, b: Image | None = None,
             layout: str = "single", look: Look = Look()) -> None:
        """Draw a view into ``rect`` (x, y, w, h from the bottom) of ``target``: ``a`` alone, or ``a`` and ``b``
        split or differenced. A single radiance image goes through composite.glsl, as in the PNGs."""
        target.viewport = rect
        if layout == "single" and a.kind == "radiance":
            self.run(a.texture, target, look.exposure, look.tonemap, flip_y=a.flip)
            return
        b = b or a
        prog = self.view
        target.use()
        self.ctx.enable_only(moderngl.NOTHING)
        a.texture.use(location=0)
        b.texture.use(location=1)
        for name, value in (("u_a", 0), ("u_b", 1), ("u_kind_a", KINDS[a.kind]), ("u_kind_b", KINDS[b.kind]),
                            ("u_flip_a", bool(a.flip)), ("u_flip_b", bool(b.flip)), ("u_layout", LAYOUTS[layout]),
                            ("u_split", float(look.split)), ("u_line", 1.0 / max(rect[2], 1)),
                            ("u_exposure", float(look.exposure)), ("u_tonemap", tonemap_code(look.tonemap)),
                            ("u_depth_range", tuple(map(float, look.depth_range))),
                            ("u_diff_gain", float(look.diff_gain))):
            set_uniform(prog, name, value)
        self._draw(prog)

    def to_ldr(self, image: np.ndarray, exposure: float = 0.0, tonemap: str = DEFAULT_TONEMAP) -> np.ndarray:
        """Tone-map a linear (H, W, 3) image to uint8 sRGB through the same shader as the display."""
        h, w = image.shape[:2]
        if (w, h) not in self._ldr:
            # Kept per size: no allocation per call.
            src = self.ctx.texture((w, h), 3, dtype="f4")
            src.filter = (moderngl.NEAREST, moderngl.NEAREST)
            dst = self.ctx.texture((w, h), 4)
            self._ldr[(w, h)] = (src, dst, self.ctx.framebuffer([dst]))
        src, _, fbo = self._ldr[(w, h)]
        src.write(np.ascontiguousarray(np.flipud(image), dtype="f4").tobytes())
        self.run(src, fbo, exposure, tonemap)
        return read_rgb8(fbo)

    def release(self) -> None:
        unbind_framebuffer(self.ctx)
        for targets in self._ldr.values():
            for t in reversed(targets):
                t.release()
        for vao in self._vaos.values():
            vao.release()


def read_rgb8(fbo: moderngl.Framebuffer) -> np.ndarray:
    """An 8-bit framebuffer's viewport-independent contents as (H, W, 3) uint8, top row first."""
    w, h = fbo.size
    rgb = np.frombuffer(fbo.read(viewport=(0, 0, w, h), components=3), np.uint8).reshape(h, w, 3)
    return np.ascontiguousarray(np.flipud(rgb))
