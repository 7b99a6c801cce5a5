"""A light's shadow map is typed by the light's kind (diviewer.gl.shadows): a sun's map and a point light's cube atlas,
each binding its own lookup to a program; the direct light shades alike through either."""

from __future__ import annotations

import numpy as np

from diviewer.gl.renderer import Renderer, RenderSettings
from diviewer.gl.shadows import SHADOW_UNIT, DirectionalShadow, PointShadow
from scenes import facing_plane

LIGHTS = [{"name": "sun", "type": "directional", "direction": [0.3, -0.2, -1.0], "irradiance": 2.0},
          {"name": "bulb", "type": "point", "position": [0.3, -0.2, -0.5], "intensity": 1.0}]


def test_each_light_kind_has_its_map_and_binds_it(ctx):
    scene = facing_plane(distance=2.0, lights=LIGHTS)
    r = Renderer(ctx, scene, 16, 16, RenderSettings(shadow_size=64))
    try:
        r.render(scene.default)
        sun, bulb = r.shadow_pass.maps["sun"], r.shadow_pass.maps["bulb"]
        assert isinstance(sun, DirectionalShadow) and isinstance(bulb, PointShadow)
        assert (sun.size, sun.footprint, sun.pending(64), sun.pending(128)) == (64, False, False, True)
        assert (bulb.size, bulb.face_size, bulb.pending(64)) == (None, r.shadow_pass.face_size, False)
        assert bulb.faces.shape == (6, 4, 4) and not r.shadows_pending
        for shadow, lookup, defines in ((sun, "u_shadow_map", {"DIRECTIONAL": 1}), (bulb, "u_shadow_atlas",
                                                                                    {"POINT_LIGHT": 1})):
            prog = r.shaders.program("direct.glsl", defines)
            shadow.bind(prog)
            assert prog[lookup].value == SHADOW_UNIT
        assert np.all(np.isfinite(r.read("direct"))) and r.read("direct").max() > 0
        off = Renderer(ctx, scene, 16, 16, RenderSettings(shadows=False))
        try:
            off.render(scene.default)
            assert off.shadow_pass.maps == {"sun": None, "bulb": None}
        finally:
            off.release()
    finally:
        r.release()
