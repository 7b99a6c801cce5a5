"""The shadow pass (diviewer/gl/shadow_pass.py): a resting sun's full map drawn in bands over several frames is the
map drawn whole, bit for bit, and the frames before its last band show the moving map."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diviewer.gl.culling import boxes_visible, frustum_planes
from diviewer.gl.renderer import Renderer, RenderSettings
from diviewer.gl.shadow_pass import band_clip, band_rows
from scenes import facing_plane

RES = 32


@pytest.mark.parametrize("size,bands", [(512, 16), (100, 3), (7, 7)])
def test_bands_cover_every_row_once_in_order(size, bands):
    rows = [band_rows(size, bands, i) for i in range(bands)]
    assert rows[0][0] == 0 and all(a[0] + a[1] == b[0] for a, b in zip(rows, rows[1:]))
    assert sum(n for _, n in rows) == size and min(n for _, n in rows) >= size // bands


def test_a_bands_frustum_keeps_the_boxes_over_its_rows_and_no_other():
    """band_clip narrows the light's clip space to the band's rows: a box over them is kept, one wholly above or
    below them is culled (the light here maps y in [-1, 1] to the map's rows, x and z kept inside)."""
    m_light = np.identity(4)
    planes = frustum_planes(band_clip(m_light, 64, 16, 16))  # rows 16-31: y in [-0.5, 0)
    boxes = np.array([[[-0.1, -0.4, -0.1], [0.1, -0.3, 0.1]],  # inside the band
                      [[-0.1, -0.7, -0.1], [0.1, -0.45, 0.1]],  # reaching into it from below
                      [[-0.1, 0.05, -0.1], [0.1, 0.5, 0.1]],  # above it
                      [[-0.1, -0.9, -0.1], [0.1, -0.6, 0.1]]])  # below it
    assert boxes_visible(planes, boxes).tolist() == [True, True, False, False]


def _sun_scene():
    return facing_plane(lights=[{"name": "sun", "type": "directional", "direction": [0.3, -0.4, -1.0]}],
                        extra_objects=[{"name": "box", "mesh": "wall", "material": "occ", "position": [0, 0, -1.5],
                                        "scale": [0.1, 0.1, 0.1]}])


def test_a_resting_sun_shows_the_moving_map_until_its_last_band_then_the_map_drawn_whole(ctx):
    """``rest_in_bands``: at rest after a move, (full / moving)^2 frames each draw one band of the full map; the
    frames before the last show the moving map (the frame a renderer without bands shows while the sun moves), the
    last the full map, whose texels and frame are those of a renderer that draws it whole. A sun that moves again
    mid-way starts its bands over at its next rest."""
    scene = _sun_scene()
    turned = [scene.default.replace_light("sun", direction=(0.3 + 0.05 * k, -0.4, -1.0)) for k in range(3)]
    r = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=256))
    moving = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=128))
    plain = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=256))
    r.moving_shadow_size, r.rest_in_bands = 128, True
    try:
        r.frame(turned[0])
        r.frame(turned[1])  # the sun moved: the moving map
        assert r.shadow_pass.maps["sun"].size == 128 and r.shadow_renders == 2
        shown = []
        for _ in range(4):  # (256 / 128)^2 bands
            frame = r.frame(turned[1])["direct"]
            shown.append((r.shadow_pass.maps["sun"].size, r.shadow_renders))
            if len(shown) < 4:
                np.testing.assert_array_equal(frame, moving.frame(turned[1])["direct"])
        assert shown == [(128, 2), (128, 2), (128, 2), (256, 3)]
        np.testing.assert_array_equal(frame, plain.frame(turned[1])["direct"])
        assert r.shadow_pass.maps["sun"].map.read() == plain.shadow_pass.maps["sun"].map.read()
        r.frame(turned[1])
        assert r.shadow_renders == 3  # kept
        r.frame(turned[2])
        r.frame(turned[2])
        r.frame(turned[2])  # two bands of four
        r.frame(turned[1])  # the sun moves again
        sizes = []
        for _ in range(4):
            r.frame(turned[1])
            sizes.append(r.shadow_pass.maps["sun"].size)
        assert sizes == [128, 128, 128, 256]
        np.testing.assert_array_equal(r.frame(turned[1])["direct"], plain.frame(turned[1])["direct"])
    finally:
        for x in (r, moving, plain):
            x.release()


def test_a_moving_map_cut_to_the_view_is_drawn_whole_mid_bands_once_the_footprint_is_turned_off(ctx):
    """VXGI turns the renderer's ``shadow_footprint`` off when it starts (it reads the map over its whole grid): a
    resting sun whose bands show a moving map cut to the view gets its moving map drawn whole at the next frame
    (a map drawn more, which tells VXGI to inject again), and its bands go on to the full map."""
    scene = _sun_scene()
    r = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=256))
    r.moving_shadow_size, r.rest_in_bands = 128, True
    try:
        turned = scene.default.replace_light("sun", direction=(0.4, -0.4, -1.0))
        r.frame(scene.default)
        r.frame(turned)
        r.frame(turned)  # band 1 of 4
        assert r.shadow_pass.maps["sun"].footprint and r.shadow_renders == 2
        r.shadow_footprint = False
        r.frame(turned)  # band 2
        assert not r.shadow_pass.maps["sun"].footprint and r.shadow_pass.maps["sun"].size == 128
        assert r.shadow_renders == 3
        r.frame(turned)  # band 3: the whole moving map is kept
        assert r.shadow_renders == 3
        r.frame(turned)  # band 4: the full map
        assert r.shadow_pass.maps["sun"].size == 256 and r.shadow_renders == 4
    finally:
        r.release()


def test_without_a_smaller_moving_map_a_resting_sun_is_drawn_whole_at_once(ctx):
    """Bands need a moving map smaller than the full one to show meanwhile; with none the full map is drawn at the
    first frame the sun rests, as without bands."""
    scene = _sun_scene()
    r = Renderer(ctx, scene, RES, RES, RenderSettings(shadow_size=128))
    r.moving_shadow_size, r.rest_in_bands = 256, True
    try:
        r.frame(scene.default)
        turned = scene.default.replace_light("sun", direction=(0.4, -0.4, -1.0))
        r.frame(turned)
        assert r.shadow_pass.maps["sun"].footprint  # the full size, only what shades the view
        r.frame(turned)
        assert r.shadow_renders == 3 and not r.shadow_pass.maps["sun"].footprint
    finally:
        r.release()


def test_sponza_bands_cull_their_casters_and_a_walking_camera_sees_the_same_frames(ctx, sponza):
    """Sponza from the gallery, the sun come to rest, the camera walking on: each band draws only the casters over its
    rows (each fewer triangles than the map drawn whole, the outer ones under a fifth, every caster in some band); the
    moving map, which holds only what shades the view, is drawn again for each new view while the bands go on, so
    every frame is the one a renderer whose moving map holds everything shows; the last band's frame is the full
    map's, bit for bit."""
    gallery = dataclasses.replace(sponza.default.camera, position=(5.9, 11.8, 4.4), target=(4.8, 11.4, -3.05))
    sun = next(light for light in sponza.default.lights if light.kind == "directional")
    start = dataclasses.replace(sponza.default, camera=gallery)
    rest = start.replace_light(sun.name, direction=(-0.33, -0.903, -0.24))
    walk = [dataclasses.replace(rest, camera=dataclasses.replace(gallery, position=(5.9 - 0.4 * k, 11.8, 4.4)))
            for k in range(4)]
    renderers = {fp: Renderer(ctx, sponza, 48, 48, RenderSettings(shadow_size=512)) for fp in (True, False)}
    plain = Renderer(ctx, sponza, 48, 48, RenderSettings(shadow_size=512))
    try:
        frames, renders, bands = {}, {}, []
        for fp, r in renderers.items():
            r.moving_shadow_size, r.rest_in_bands, r.shadow_footprint = 256, True, fp
            r.frame(start)
            r.frame(rest)  # the sun moved
            before, frames[fp] = r.shadow_renders, []
            for config in walk:
                frames[fp].append(r.frame(config)["direct"])
                if not fp:  # no moving map drawn again: the shadow pass drew the band alone
                    bands.append(r.drawn["shadows"][1])
            renders[fp] = r.shadow_renders - before
        # the first walk frame's view is the one the moving map was drawn for: two moving maps for new views, then
        # the full one (the last band's frame); without the footprint, the full one alone
        assert renders == {True: 3, False: 1}
        for a, b in zip(frames[True], frames[False]):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(frames[True][-1], plain.frame(walk[-1])["direct"])
        whole = plain.drawn["shadows"][1]
        assert max(bands) < whole and min(bands) < 0.2 * whole and sum(bands) >= whole
    finally:
        for x in (*renderers.values(), plain):
            x.release()
