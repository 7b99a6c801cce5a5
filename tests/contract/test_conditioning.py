"""A frame's conditioning (diviewer.contract.conditioning): what each encoding version takes, derived alike from a scene
configuration and from the dict a dataset stores, and refused where the frame cannot give it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.contract.conditioning import (STAND_IN_CAMERA, Conditioning, conditioning, has_lights_for, needs_scene,
                                            stacked, stand_in)
from diviewer.contract.encoding import Encoding
from diviewer.errors import DiviewerError
from diviewer.scene import load_scene, sample_config
from diviewer.scene.camera import camera_params
from diviewer.scene.lights import light_params, light_scale

BOX = {"world_center": (0.0, 1.0, 0.0), "world_half": (1.5, 1.5, 1.5)}


def _encoding(version: int, lights: int = 1) -> Encoding:
    extra = dict(BOX) if version >= 3 else {}
    if version >= 4:
        extra["lights"] = lights
    return Encoding(exposure=1.0, depth_scale=10.0, version=version, **extra)


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


def test_encoding_1_takes_nothing(cornell):
    c = conditioning(None, None, (32, 32), _encoding(1))
    assert c == Conditioning() and c.inputs() == {} and not needs_scene(_encoding(1))


@settings(max_examples=12, deadline=None)
@given(version=st.integers(2, 4), seed=st.integers(0, 10_000), w=st.integers(8, 96), h=st.integers(8, 96))
def test_each_version_takes_its_parts_from_config_or_stored_dict(cornell, version, seed, w, h):
    config = sample_config(cornell, seed, "train")
    enc = _encoding(version, len(config.lights))
    c = conditioning(cornell, config, (w, h), enc)
    assert c.light_scale == light_scale(cornell, config)
    cam = config.camera
    if version >= 3:
        np.testing.assert_array_equal(c.camera, camera_params(cam.position, cam.target, cam.up, cam.fov, w, h))
    else:
        assert c.camera is None
    if version >= 4:
        np.testing.assert_array_equal(c.lights, light_params(config.lights, BOX["world_center"], BOX["world_half"]))
    else:
        assert c.lights is None
    stored = conditioning(cornell, config.to_dict(), (w, h), enc.to_dict())  # a dataset's frame, a model's metadata
    assert stored.light_scale == c.light_scale
    for a, b in ((stored.camera, c.camera), (stored.lights, c.lights)):
        assert (a is None and b is None) or np.array_equal(a, b)
    assert list(c.inputs()) == ["light_scale", "camera", "light"][:version - 1]


def test_refused_where_the_frame_cannot_give_it(cornell):
    with pytest.raises(DiviewerError, match="no stored configuration"):
        conditioning(cornell, None, (8, 8), _encoding(2))
    with pytest.raises(ValueError, match="needs the scene"):
        conditioning(None, cornell.default, (8, 8), _encoding(2))
    n = len(cornell.default.lights)
    with pytest.raises(ValueError, match=f"takes {n + 1} light"):
        conditioning(cornell, cornell.default, (8, 8), _encoding(4, n + 1))


@settings(max_examples=12, deadline=None)
@given(version=st.integers(1, 4), lights=st.integers(1, 3), scale=st.integers(1, 10_000).map(lambda k: k / 100),
       w=st.integers(8, 96), h=st.integers(8, 96))
def test_a_stand_in_takes_what_its_encoding_takes_as_given(version, lights, scale, w, h):
    """A frame of procedural buffers: the light scale and camera given, one sun per light the encoding takes."""
    enc = _encoding(version, lights)
    sun = (0.3, -1.0, 0.2)
    c = stand_in(enc.to_dict(), (w, h), light_scale=scale, sun=sun)
    assert c.light_scale == (scale if version >= 2 else None)
    cam = STAND_IN_CAMERA
    want = camera_params(cam["position"], cam["target"], cam["up"], cam["fov"], w, h) if version >= 3 else None
    assert (c.camera is None and want is None) or np.array_equal(c.camera, want)
    if version >= 4:
        direction = np.asarray(sun) / np.linalg.norm(sun)
        np.testing.assert_allclose(c.lights, np.tile(direction, lights), rtol=1e-6)
    else:
        assert c.lights is None
    assert list(c.inputs()) == ["light_scale", "camera", "light"][:version - 1]


def test_stacked_gives_float32_arrays_of_the_parts_taken(cornell):
    configs = [sample_config(cornell, s, "train") for s in (1, 2, 3)]
    enc = _encoding(4, len(configs[0].lights))
    conds = [conditioning(cornell, c, (16, 8), enc) for c in configs]
    scales, cams, lights = stacked(conds)
    assert scales.dtype == cams.dtype == lights.dtype == np.float32
    np.testing.assert_array_equal(scales, np.float32([light_scale(cornell, c) for c in configs]))
    np.testing.assert_array_equal(cams, [c.camera for c in conds])
    np.testing.assert_array_equal(lights, [c.lights for c in conds])
    assert stacked([conditioning(None, None, (16, 8), _encoding(1))] * 2) == (None, None, None)
    scales, cams, lights = stacked([conditioning(cornell, c, (16, 8), _encoding(2)) for c in configs])
    assert scales.shape == (3,) and cams is None and lights is None


def test_a_stored_configuration_has_the_lights_an_encoding_takes_or_not(cornell):
    stored = cornell.default.to_dict()
    n = len(stored["lights"])
    assert has_lights_for(stored, _encoding(4, n)) and not has_lights_for(stored, _encoding(4, n + 1))
    assert not has_lights_for(None, _encoding(4, n)) and not has_lights_for({**stored, "lights": []}, _encoding(4, n))
    assert all(has_lights_for(c, _encoding(v)) for v in (1, 2, 3) for c in (None, stored))  # takes none
