"""The sampler's free cameras (diviewer.scene.sampler with a CameraRegion): inside the declared ranges,
held-out boxes for test only, the scene camera kept on request and for the declared share of frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.scene import load_scene, sample_config
from diviewer.scene.loader import parse_scene
from diviewer.scene.model import box_contains


@pytest.fixture(scope="module")
def cornell():
    return load_scene("cornell")


def _angle(camera, region) -> float:
    d = np.subtract(camera.target, camera.position)
    t = np.subtract(region.target, camera.position)
    return math.acos(float(np.clip(np.dot(d, t) / np.linalg.norm(d) / np.linalg.norm(t), -1, 1)))


def test_cameras_stay_in_the_declared_ranges_and_train_never_in_a_test_box(cornell):
    region = cornell.ranges.camera_region
    assert region is not None and len(region.test_regions) == 2
    seen = {"train": 0, "val": 0, "test": 0}
    in_test = {"train": 0, "val": 0, "test": 0}
    for split in seen:
        for seed in range(300):
            cam = sample_config(cornell, seed, split).camera
            if cam == cornell.default.camera:
                assert split != "test"  # test frames always put the camera in a held-out box
                continue
            seen[split] += 1
            assert box_contains(region.region, cam.position)
            assert region.fov[0] <= cam.fov <= region.fov[1]
            jitter = np.abs(np.subtract(cam.target, region.target))
            assert np.all(jitter <= np.asarray(region.target_jitter) + 1e-9)
            assert _angle(cam, region) <= region.max_look_offset(cam.position) + 1e-9
            in_test[split] += region.in_test_region(cam.position)
    assert in_test["train"] == 0  # never a held-out camera for training
    assert in_test["test"] == seen["test"] == 300
    assert 0 < in_test["val"] < seen["val"]  # validation draws anywhere


def test_default_share_and_camera_default(cornell):
    default = cornell.default.camera
    kept = sum(sample_config(cornell, s, "train").camera == default for s in range(1000))
    assert abs(kept / 1000 - cornell.ranges.camera_region.default_share) < 0.05
    for seed in range(20):
        moved, fixed = sample_config(cornell, seed, "test"), sample_config(cornell, seed, "test", camera="default")
        assert fixed.camera == default
        assert moved.lights == fixed.lights and moved.objects == fixed.objects  # the camera's own stream
    with pytest.raises(ValueError, match="camera must be one of"):
        sample_config(cornell, 0, "train", camera="orbit")


def _scene(camera_range: dict) -> dict:
    return {"scene": {"name": "t"}, "camera": {"position": [0, 1, 4], "target": [0, 1, 0]},
            "meshes": {"box": {"shape": "box", "size": [1, 1, 1]}}, "materials": {"white": {}},
            "objects": [{"name": "box", "mesh": "box", "material": "white"}],
            "ranges": {"camera": camera_range}}


@pytest.mark.parametrize("camera_range, field, words", [
    ({"region": [[1, 0, 0], [0, 1, 1]]}, "ranges.camera.region", "min must be below its max"),
    ({"region": [[0, 0, 0], [1, 1, 1]], "fov": [60, 30]}, "ranges.camera.fov", "min <= max"),
    ({"region": [[0, 0, 0], [1, 1, 1]], "test_regions": [[[5, 5, 5], [6, 6, 6]]]}, "ranges.camera.test_regions",
     "does not overlap"),
    ({"region": [[0, 0, 0], [1, 1, 1]], "test_regions": [[[-1, -1, -1], [2, 2, 2]]]}, "ranges.camera.test_regions",
     "cover (almost) all"),
    ({"region": [[0, 0, 0], [1, 1, 1]], "default_share": 1.5}, "ranges.camera.default_share", "<= 1"),
    ({"region": [[0, 0, 0], [1, 1, 1]], "target_jitter": [-1, 0, 0]}, "ranges.camera.target_jitter", ">= 0"),
    ({"region": [[0, 0, 0], [1, 1, 1]], "spin": 3}, "ranges.camera", "spin"),
])
def test_camera_region_refusals_name_the_field(camera_range, field, words):
    with pytest.raises(DiviewerError) as err:
        parse_scene(_scene(camera_range))
    assert field in str(err.value) and words in str(err.value), str(err.value)
