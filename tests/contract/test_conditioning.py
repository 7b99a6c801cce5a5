"""A frame's conditioning (diviewer.contract.conditioning): what each encoding version takes, derived alike from a scene
configuration and from the dict a dataset stores, and refused where the frame cannot give it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from diviewer.contract.conditioning import Conditioning, conditioning, needs_scene
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
