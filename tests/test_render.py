"""diviewer/render.py's checks that need no GL."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diviewer.errors import DiviewerError


def test_an_overflow_names_the_textured_emitter_by_its_brightest_texel():
    """A frame with non-finite values is refused naming the strongest emitter; a textured emitter's strength is its
    factor times its brightest texel, so a dim factor over a bright texture outranks a brighter untextured one."""
    from diviewer.render import check_finite
    from diviewer.scene.loader import parse_scene

    data = {"camera": {"position": [0, 0, 0], "target": [0, 0, -1], "fov": 40},
            "materials": {"lamp": {"albedo": [0.5, 0.5, 0.5], "emission": [2.0, 2.0, 2.0]},
                          "plain": {"albedo": [0.5, 0.5, 0.5], "emission": [5.0, 5.0, 5.0]}},
            "meshes": {"box": {"shape": "box", "size": [1, 1, 1]}},
            "objects": [{"name": "lamp", "mesh": "box", "material": "lamp"},
                        {"name": "plain", "mesh": "box", "material": "plain", "position": [2, 0, 0]}],
            "lights": []}
    scene = parse_scene(data)
    texture = np.full((2, 2, 3), 0.1, np.float32)
    texture[1, 0] = 4.0  # one texel of 4 under a factor of 2: 8, above the plain emitter's 5
    lamp = dataclasses.replace(scene.materials["lamp"], emission_texture=texture)
    textured = dataclasses.replace(scene, materials={**scene.materials, "lamp": lamp})
    frame = {"direct": np.array([[[np.inf, 0.0, 0.0]]], np.float32)}
    with pytest.raises(DiviewerError, match=r"materials\.lamp\.emission = 8"):
        check_finite(textured, textured.default, frame, ("direct",))
    with pytest.raises(DiviewerError, match=r"materials\.plain\.emission = 5"):
        check_finite(scene, scene.default, frame, ("direct",))
