"""Fixtures shared by the GL tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def sponza():
    """The shipped Sponza scene (262k triangles), loaded once for every GL test that draws it."""
    from diviewer.scene import load_scene

    return load_scene("sponza")
