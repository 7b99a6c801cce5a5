"""The viewer's GI control: the GI resolutions it offers the panel for the loaded model."""

from __future__ import annotations

from types import SimpleNamespace

from diviewer.gl.neural import GISettings
from diviewer.scene import load_scene
from diviewer.viewer.gi import GIControl
from diviewer.viewer.models import GI_FRACTIONS
from diviewer.viewer.state import ViewerState


class Model:
    """What the GI sizes read of a model: trained at 64x48, stride 16, a runtime that pads any size."""

    multiple, resolution = 16, (64, 48)

    def check_size(self, w, h):
        return None


def test_the_offered_gi_resolutions_follow_the_model_and_the_sizes():
    renderer = SimpleNamespace(width=96, height=64)
    gi = GIControl(None, renderer, ViewerState(load_scene("cornell")), "model", GISettings())
    assert gi.offered() == ()  # no model, nothing to offer
    gi.model, gi.view_size = Model(), (192, 128)
    offered = gi.offered()
    assert [spec for spec, _ in offered] == ["model", *GI_FRACTIONS]
    assert dict(offered)["model"] == (72, 48) and dict(offered)["1/2"] == (48, 32)  # rows kept, the window's shape
    assert gi.offered() is offered  # the same sizes: not computed again
    renderer.width, renderer.height = 48, 32  # the render scale halved
    assert dict(gi.offered())["1/2"] == (24, 16) and dict(gi.offered())["model"] == (72, 48)
    gi.model = Model()  # another model: asked again
    assert gi.offered() == tuple((s, gi.sizes(gi.model, s)[0]) for s in ("model", *GI_FRACTIONS))
