"""diviewer.scene.lights.light_scale: a frame's light from its sources (encoding 2 divides radiance by it)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diviewer.scene.colour import luminance
from diviewer.scene.lights import light_scale, scale_light
from scenes import facing_plane

SUN = {"name": "sun", "type": "directional", "direction": [0, 0, -1], "color": [1.0, 0.5, 0.25], "irradiance": 3.0}
BULB = {"name": "bulb", "type": "point", "position": [0, 1, -1], "color": [0.2, 0.4, 1.0], "intensity": 5.0}


def test_sum_of_luminance_times_power():
    scene = facing_plane(lights=[SUN, BULB])
    want = 3.0 * luminance((1.0, 0.5, 0.25)) + 5.0 * luminance((0.2, 0.4, 1.0))
    assert light_scale(scene, scene.default) == pytest.approx(want)
    assert luminance((1, 1, 1)) == pytest.approx(1.0)


def test_linear_in_every_light_and_zero_without_light():
    scene = facing_plane(lights=[SUN, BULB])
    s = light_scale(scene, scene.default)
    doubled = dataclasses.replace(scene.default, lights=tuple(scale_light(l, 2.0) for l in scene.default.lights))
    assert light_scale(scene, doubled) == pytest.approx(2 * s)
    off = dataclasses.replace(scene.default, lights=tuple(scale_light(l, 0.0) for l in scene.default.lights))
    assert light_scale(scene, off) == 0.0
    assert light_scale(facing_plane(), facing_plane().default) == 0.0  # no lights at all


def test_emitters_and_the_sky_count():
    from diviewer.scene.loader import parse_scene

    data = {"scene": {"name": "e", "ambient": [0.1, 0.1, 0.1]},
            "camera": {"position": [0, 0, 0], "target": [0, 0, -1], "up": [0, 1, 0], "fov": 40},
            "materials": {"lamp": {"albedo": [0.5, 0.5, 0.5], "emission": [2.0, 2.0, 2.0]},
                          "unused": {"albedo": [0.5, 0.5, 0.5], "emission": [50.0, 0, 0]}},
            "meshes": {"box": {"shape": "box", "size": [1, 1, 1]}},
            "objects": [{"name": "lamp", "mesh": "box", "material": "lamp", "position": [0, 0, -3]}], "lights": []}
    scene = parse_scene(data)
    assert light_scale(scene, scene.default) == pytest.approx(2.0 + 0.1)  # only the emitters in the frame


def test_a_textured_emitter_scales_as_a_uniform_one_of_its_brightest_texel():
    """Encoding 2's light scale counts a textured emitter by factor x its brightest texel (by luminance), so a
    half-dark lamp scales as the uniform lamp its bright half is."""
    from diviewer.scene.loader import parse_scene
    from diviewer.scene.model import Material

    data = {"camera": {"position": [0, 0, 0], "target": [0, 0, -1], "fov": 40},
            "materials": {"lamp": {"albedo": [0.5, 0.5, 0.5], "emission": [2.0, 1.0, 4.0]}},
            "meshes": {"box": {"shape": "box", "size": [1, 1, 1]}},
            "objects": [{"name": "lamp", "mesh": "box", "material": "lamp"}], "lights": []}
    scene = parse_scene(data)
    texture = np.zeros((2, 4, 3), np.float32)
    texture[0, 1] = (0.5, 0.25, 0.5)   # times the factor (1, 0.25, 2): the brightest texel, luminance 0.54
    texture[1, 3] = (0.0, 0.0, 1.0)    # (0, 0, 4): the most blue, luminance 0.29 (blue weighs 0.07)
    lamp = dataclasses.replace(scene.materials["lamp"], emission_texture=texture)
    textured = dataclasses.replace(scene, materials={"lamp": lamp})
    assert lamp.peak_emission == (1.0, 0.25, 2.0)
    assert light_scale(textured, scene.default) == pytest.approx(luminance((1.0, 0.25, 2.0)))
    uniform = dataclasses.replace(scene, materials={"lamp": Material("lamp", emission=(1.0, 0.25, 2.0))})
    assert light_scale(textured, scene.default) == pytest.approx(light_scale(uniform, uniform.default))


def test_light_params_give_suns_directions_and_point_lights_positions_in_the_world_box():
    """Encoding 4's light input: a sun's unit direction, a point light's position normalised (and clipped) to the
    world box, from the scene's light objects or a dataset's dicts alike; strength plays no part."""
    from diviewer.scene.lights import LIGHT_PARAMS, light_params
    from diviewer.scene.model import DirectionalLight, PointLight

    sun = DirectionalLight(name="sun", direction=(0.0, -2.0, 0.0), color=(1.0, 1.0, 1.0), irradiance=5.0)
    lamp = PointLight(name="lamp", position=(1.0, 3.0, -9.0), color=(1.0, 1.0, 1.0), intensity=7.0)
    got = light_params([sun, lamp], center=(0.0, 1.0, 0.0), half=(2.0, 4.0, 2.0))
    assert got.dtype == np.float32 and got.shape == (2 * LIGHT_PARAMS,)
    np.testing.assert_allclose(got, [0.0, -1.0, 0.0, 0.5, 0.5, -1.0])  # z clipped at the box's face
    as_dicts = [{"type": "directional", "direction": [0.0, -2.0, 0.0], "irradiance": 0.1},
                {"type": "point", "position": [1.0, 3.0, -9.0], "intensity": 70.0}]
    np.testing.assert_array_equal(light_params(as_dicts, (0.0, 1.0, 0.0), (2.0, 4.0, 2.0)), got)
    assert light_params([], (0, 0, 0), (1, 1, 1)).shape == (0,)


def test_box_sweep_stays_in_the_box_and_crosses_it():
    import numpy as np

    from diviewer.scene.lights import box_sweep

    box = ((-1.0, 2.0, -0.5), (1.0, 2.0, 0.5))  # flat in y: a lamp sliding along a ceiling
    p = np.array([box_sweep(box, t) for t in np.linspace(0.0, 2 * np.pi, 200)])
    assert np.all(p >= np.array(box[0]) - 1e-12) and np.all(p <= np.array(box[1]) + 1e-12)
    assert np.allclose(p.min(axis=0), box[0], atol=1e-3) and np.allclose(p.max(axis=0), box[1], atol=1e-3)
    assert np.allclose(box_sweep(box, 0.0), box_sweep(box, 2 * np.pi))  # a closed curve: the animation loops
