"""The training-range check (scene/ranges_check.py): what the capture draws is inside, what it cannot is not."""

from __future__ import annotations

import dataclasses

import pytest

from diviewer.scene import load_scene, sample_config
from diviewer.scene.lights import rotate_light, scale_light
from diviewer.scene.model import Camera, CameraRange, ObjectRange
from diviewer.scene.ranges_check import (camera_path_reasons, camera_region_reasons, light_reasons, object_reasons,
                                         out_of_range)


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


def _camera(scene, **changes):
    return dataclasses.replace(scene.default, camera=dataclasses.replace(scene.default.camera, **changes))


def test_the_scene_and_every_training_draw_are_inside(cornell):
    assert out_of_range(cornell, cornell.default) == []
    for seed in range(40):
        assert out_of_range(cornell, sample_config(cornell, seed, "train")) == [], seed


def test_test_draws_are_flagged_as_held_out(cornell):
    for seed in range(10):
        reasons = out_of_range(cornell, sample_config(cornell, seed, "test"))
        assert any("held-out test region" in r for r in reasons), reasons
        assert any("held-out test mesh" in r for r in reasons), reasons


def test_camera_region(cornell):
    region = cornell.ranges.camera_region
    assert "outside the trained region" in " ".join(out_of_range(cornell, _camera(cornell, position=(0.0, 1.0, 6.0))))
    assert "field of view 80" in " ".join(out_of_range(cornell, _camera(cornell, fov=80.0)))
    # From the scene camera the jitter box spans ~13 degrees: looking at the ceiling's corner is beyond it.
    away = out_of_range(cornell, _camera(cornell, target=(1.0, 2.0, 0.0)))
    assert len(away) == 1 and "deg away from the scene's target" in away[0]
    # Inside the region, aimed within the jitter, a field of view in range: nothing to say.
    inside = Camera(position=(0.3, 1.2, 2.0), target=(0.2, 1.1, 0.1), fov=50.0)
    assert camera_region_reasons(region, inside) == []


def test_camera_path():
    path = CameraRange(positions=((0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (20.0, 0.0, 0.0)),
                       targets=((0.0, 0.0, -5.0), (10.0, 0.0, -5.0), (20.0, 0.0, -5.0)), test_stretches=((0.8, 1.0),))
    default = Camera(position=(0.0, 0.0, 0.0), target=(0.0, 0.0, -5.0), fov=60.0)
    on = Camera(position=(5.0, 0.3, 0.0), target=(5.0, 0.3, -5.0), fov=60.0)
    assert camera_path_reasons(path, on, default, reach=1.0) == []
    far = dataclasses.replace(on, position=(5.0, 4.0, 0.0), target=(5.0, 4.0, -5.0))
    assert "from the trained camera path" in camera_path_reasons(path, far, default, reach=1.0)[0]
    turned = dataclasses.replace(on, target=(5.0, 0.3, 5.0))
    assert "looks 180 deg away" in camera_path_reasons(path, turned, default, reach=1.0)[0]
    held_out = Camera(position=(18.0, 0.0, 0.0), target=(18.0, 0.0, -5.0), fov=60.0)
    assert "held-out stretch" in camera_path_reasons(path, held_out, default, reach=1.0)[0]
    assert "field of view" in camera_path_reasons(path, dataclasses.replace(on, fov=90.0), default, reach=1.0)[0]


def test_sponza_path_camera():
    sponza = load_scene("sponza")
    assert out_of_range(sponza, sponza.default) == []
    for seed in range(8):
        assert out_of_range(sponza, sample_config(sponza, seed, "train")) == []
    lost = _camera(sponza, position=(0.0, 20.0, 12.0), target=(0.0, 20.0, 20.0))
    assert "from the trained camera path" in out_of_range(sponza, lost)[0]


def test_lights(cornell):
    sun = cornell.default.lights[0]
    r = cornell.ranges.lights["sun"]
    centre = cornell.bounds().mean(axis=0)
    assert light_reasons(scale_light(rotate_light(sun, r.axis, 35.0, centre), 1.9), sun, r, centre) == []
    assert "turned 60 deg" in light_reasons(rotate_light(sun, r.axis, 60.0, centre), sun, r, centre)[0]
    assert "tilted" in light_reasons(rotate_light(sun, (1.0, 0.0, 0.0), 20.0, centre), sun, r, centre)[0]
    assert "x0.00" in light_reasons(scale_light(sun, 0.0), sun, r, centre)[0]
    assert "x4.00" in light_reasons(scale_light(sun, 4.0), sun, r, centre)[0]
    assert "colour" in light_reasons(dataclasses.replace(sun, color=(1.0, 0.0, 0.0)), sun, r, centre)[0]
    # A light without a range stays as the scene file sets it.
    assert "turned" in light_reasons(rotate_light(sun, (0, 1, 0), 10.0, centre), sun, None, centre)[0]
    # The panel's light controls and the viewer's animation stay inside when the range allows it.
    from diviewer.viewer.state import ViewerState

    st = ViewerState(cornell)
    st.animate_light = True
    for _ in range(20):
        st.step(0.37)
        assert st.out_of_range() == [], st.config.lights


def test_objects(cornell):
    centre = next(o for o in cornell.default.objects if o.name == "center")
    r = cornell.ranges.objects["center"]
    assert object_reasons(dataclasses.replace(centre, mesh="sphere", rotation=(10.0, 200.0, -45.0)), centre, r) == []
    assert "held-out test mesh" in object_reasons(dataclasses.replace(centre, mesh="torus"), centre, r)[0]
    assert "never saw" in object_reasons(dataclasses.replace(centre, mesh="file:bunny"), centre, r)[0]
    assert "moved by" in object_reasons(dataclasses.replace(centre, position=(0.2, 0.75, 0.0)), centre, r)[0]
    assert "scaled" in object_reasons(dataclasses.replace(centre, scale=(2.0, 2.0, 2.0)), centre, r)[0]
    assert "material" in object_reasons(dataclasses.replace(centre, material="red"), centre, r)[0]
    # An offset box allows moves within it; a single axis allows turns about it within its angle.
    boxed = ObjectRange(offset=((-0.5, 0.0, -0.5), (0.5, 0.0, 0.5)))
    assert object_reasons(dataclasses.replace(centre, position=(0.4, 0.75, -0.3)), centre, boxed) == []
    assert object_reasons(dataclasses.replace(centre, position=(0.4, 0.95, -0.3)), centre, boxed) != []
    wall = next(o for o in cornell.default.objects if o.name == "back")
    spin = ObjectRange(axes=((0.0, 1.0, 0.0),), angle=(0.0, 90.0))
    assert object_reasons(dataclasses.replace(wall, rotation=(0.0, 45.0, 0.0)), wall, spin) == []
    assert "beyond the trained rotations" in object_reasons(dataclasses.replace(wall, rotation=(0.0, 120.0, 0.0)),
                                                             wall, spin)[0]
    assert "beyond" in object_reasons(dataclasses.replace(wall, rotation=(30.0, 0.0, 0.0)), wall, spin)[0]
    # A static object (no range) must stay where the scene file puts it.
    assert "moved by" in object_reasons(dataclasses.replace(wall, position=(0.0, 1.0, -0.5)), wall, None)[0]
    assert "turned" in object_reasons(dataclasses.replace(wall, rotation=(0.0, 5.0, 0.0)), wall, None)[0]
    whole = out_of_range(cornell, cornell.default.replace_object("back", position=(0.0, 1.0, -0.5)))
    assert whole == ["object 'back' moved by (0.00, 0.00, 0.55); trained offsets (0.00, 0.00, 0.00)-(0.00, 0.00, 0.00)"]
