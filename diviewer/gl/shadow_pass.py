"""The renderer's shadow pass: each light's map, owned here, kept from frame to frame and drawn again only when
what it depends on changed (the light, an object's pose or mesh, the shadow settings; not the camera).

While a sun moves its map is drawn at the renderer's ``moving_shadow_size``, holding only what can shade the view
(`shadow_fit.sun_footprint`); at rest, at the full size, whole at once, or (``Renderer.rest_in_bands``, the
viewer's) in bands over the next frames, each band as many texels as the moving map, the moving map shown until the
last band is drawn: the frame after the sun stops then costs no more than one while it moved (Sponza's 8192 map
drawn whole took ~325 ms on a 2-core software rasterizer). The full map drawn in bands is the one drawn whole, bit
for bit (tests/gl/test_shadow_pass.py).
"""

from __future__ import annotations

import math

import moderngl
import numpy as np

from diviewer.gl.context import unbind_framebuffer
from diviewer.gl.draw import draw_objects
from diviewer.gl.shadow_fit import fit_directional, point_faces, sun_footprint
from diviewer.gl.shadows import DirectionalShadow, PointShadow
from diviewer.scene.model import DirectionalLight, FrameConfig


def band_rows(size: int, bands: int, i: int) -> tuple[int, int]:
    """Band ``i`` of ``bands`` over a map ``size`` texels a side: its first row and its row count."""
    y0, y1 = i * size // bands, (i + 1) * size // bands
    return y0, y1 - y0


def band_clip(m_light: np.ndarray, size: int, y0: int, rows: int) -> np.ndarray:
    """The light's world-to-clip matrix narrowed to the rows [y0, y0 + rows) of its map: the band's frustum, which
    culls the casters that write none of its texels."""
    lo, hi = 2.0 * y0 / size - 1.0, 2.0 * (y0 + rows) / size - 1.0
    crop = np.identity(4)
    crop[1, 1], crop[1, 3] = 2.0 / (hi - lo), -(hi + lo) / (hi - lo)
    return crop @ np.asarray(m_light, np.float64)


class ShadowPass:
    """Each light's shadow map for a Renderer's frames (its pass named "shadows"): ``run(frame)`` leaves this
    frame's map per light in ``maps`` (`diviewer.gl.shadows`, each binding its lookup to a program; None: shadows
    off). It reads the renderer's state and draws through `diviewer.gl.draw`, never calling the renderer back; the
    frame (the renderer's FrameView) brings the settings."""

    def __init__(self, renderer, settings):
        self.renderer = renderer
        self.face_size = max(settings.shadow_size // 2, 16)
        """A point light's cube face, texels a side (half the map size the renderer started with)."""
        self.maps: dict[str, DirectionalShadow | PointShadow | None] = {}
        """This frame's map per light (`diviewer.gl.shadows`; None entries: shadows off)."""
        self._targets: dict[tuple[str, int], tuple] = {}
        """Per (light name, map size; 0 for a point light's atlas): (kind, texture, framebuffer, depth or None)."""
        self._keys: dict[str, tuple] = {}
        """Per light name: what its map in ``maps`` was drawn from (``_key``)."""
        self._bands: dict[str, int] = {}
        """Per sun at rest whose full map is being drawn in bands: the bands drawn so far."""

    # --- targets --------------------------------------------------------------------------------
    def _target(self, light, size: int, full: int) -> tuple:
        """The light's map of ``size`` and its framebuffer, made at its first use: a depth texture compared in
        hardware (sun, ``size`` texels a side), or a 3x2 atlas of cube faces holding distances (point). A sun keeps
        two, the full size (``full``) and the moving one; one of another size is released when a new one is made."""
        sun = isinstance(light, DirectionalLight)
        key = (light.name, size if sun else 0)
        target = self._targets.get(key)
        if target is not None:
            return target
        r = self.renderer
        keep = {key[1], full, r.moving_shadow_size}
        for old in [k for k in self._targets if k[0] == light.name and ((k[1] == 0) == sun or k[1] not in keep)]:
            self._release(old)
        ctx = r.ctx
        if sun:
            tex = ctx.depth_texture((size, size))
            tex.compare_func = "<="
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            tex.repeat_x = tex.repeat_y = False
            target = ("dir", tex, ctx.framebuffer(depth_attachment=tex), None)
        else:
            s = self.face_size
            tex = ctx.texture((3 * s, 2 * s), 1, dtype="f4")
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            depth = ctx.depth_renderbuffer((3 * s, 2 * s))
            target = ("point", tex, ctx.framebuffer([tex], depth), depth)
        self._targets[key] = target
        return target

    def _release(self, key: tuple[str, int]) -> None:
        """Release one map; the light's cached lookup and its bands too where they are drawn into it."""
        unbind_framebuffer(self.renderer.ctx)
        _, tex, fbo, depth = self._targets.pop(key)
        shown = self.maps.get(key[0])
        if shown is not None and shown.map is tex:
            self._keys.pop(key[0], None)
            self.maps.pop(key[0], None)
        self._bands.pop(key[0], None)
        for res in (fbo, tex, depth):
            if res is not None:
                res.release()

    def release(self) -> None:
        for key in list(self._targets):
            self._release(key)

    # --- the pass -------------------------------------------------------------------------------
    def _key(self, frame, light) -> tuple:
        """Everything a light's shadow map depends on: the light, each object's pose and the GPU mesh it draws
        (a mesh loaded again under the same name is a new one), the settings. Not the camera."""
        objects = tuple((o, id(self.renderer.gpu.meshes.get(o.mesh))) for o in frame.config.objects)
        return (light, objects, tuple(np.asarray(frame.bounds, float).ravel()), frame.settings)

    def run(self, frame) -> None:
        """Each light's shadow map (none with shadows off), reused from an earlier frame when nothing it depends on
        moved; ``frame`` is the renderer's FrameView."""
        r = self.renderer
        maps = {}
        for light in frame.config.lights:
            if not frame.settings.shadows:
                maps[light.name] = None
                continue
            key, full = self._key(frame, light), frame.settings.shadow_size
            cached = self.maps.get(light.name)
            rests = cached is not None and self._keys.get(light.name) == key
            if rests and not cached.pending(full):
                maps[light.name] = cached
                continue
            if not rests:
                self._bands.pop(light.name, None)
            elif r.rest_in_bands and r.moving_shadow_size is not None and (cached.size or full) < full:
                maps[light.name] = self._next_band(frame, light, cached)
                continue
            # the light or an object moved since the last frame: the moving size (if smaller); at rest: the full map
            moving = r.moving_shadow_size if cached is not None and not rests else None
            maps[light.name] = self._draw(frame, light, min(moving or math.inf, full),
                                          moving is not None and r.shadow_footprint)
            self._keys[light.name] = key
            r.shadow_renders += 1
        self.maps = maps

    def _next_band(self, frame, light, moving: DirectionalShadow) -> DirectionalShadow:
        """One band more of a resting sun's full map; the full map once its last band is drawn, until then the
        moving one (drawn again for this view if it holds only what shaded another, whole once the renderer's
        ``shadow_footprint`` is off)."""
        r, full = self.renderer, frame.settings.shadow_size
        bands = math.ceil(full / moving.size) ** 2  # the moving map is smaller: 4 at least
        done = self._bands.get(light.name, 0)
        drawn = self._draw(frame, light, full, False, band=band_rows(full, bands, done))
        if done + 1 == bands:
            self._bands.pop(light.name)
            r.shadow_renders += 1
            return drawn
        self._bands[light.name] = done + 1
        # a map of what shaded another view, or one the renderer no longer wants cut to the view (VXGI reads it over
        # its whole grid): the moving map again, as the renderer wants it now
        if moving.footprint and not (r.shadow_footprint and np.array_equal(moving.clip, frame.proj @ frame.view)):
            moving = self._draw(frame, light, moving.size, r.shadow_footprint)
            r.shadow_renders += 1
        return moving

    def _draw(self, frame, light, size: int, footprint: bool, band: tuple[int, int] | None = None
              ) -> DirectionalShadow | PointShadow:
        """Draw the light's map of ``size`` (a sun's: only what shades the view with ``footprint``, only the rows
        (first, count) of ``band``, the rest of the map left as it is) and return it (`diviewer.gl.shadows`)."""
        r, config, bounds = self.renderer, frame.config, frame.bounds
        ctx = r.ctx
        ctx.enable_only(moderngl.DEPTH_TEST)
        kind, tex, fbo, _ = self._target(light, size, frame.settings.shadow_size)
        if kind == "dir":
            m_light, extent, depth_range = fit_directional(bounds, light.direction)
            clip = frame.proj @ frame.view
            fbo.use()
            rows = (0, band[0], size, band[1]) if band is not None else None
            fbo.clear(depth=1.0, viewport=rows)
            cull, sweep, fbo.scissor = m_light, None, rows
            if footprint:
                sweep, fbo.scissor = sun_footprint(clip, light, bounds, m_light, extent, size, frame.settings)
            elif band is not None:
                cull = band_clip(m_light, size, *band)
            draw_objects(r, config, "shadow.glsl", {}, {"m_light": m_light}, None, cull, "shadows", sweep=sweep)
            fbo.scissor = None
            return DirectionalShadow(tex, m_light, extent / size, depth_range, size, footprint, clip)
        faces = point_faces(light.position, bounds)
        fbo.use()
        fbo.clear(1e30, 1e30, 1e30, 1e30, depth=1.0)
        s = self.face_size
        for i, m in enumerate(faces):
            fbo.viewport = ((i % 3) * s, (i // 3) * s, s, s)
            draw_objects(r, config, "shadow.glsl", {"POINT_LIGHT": 1}, {"u_light_pos": tuple(light.position),
                                                                         "m_light": m}, None, m, "shadows")
        fbo.viewport = (0, 0, 3 * s, 2 * s)
        return PointShadow(tex, faces, s)
