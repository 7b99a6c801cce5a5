"""A frame's buffers (diviewer.gl.frame): the renderer returns them as one value whose direct light is decided once
(the direct pass's target, computed inline by the reader, or area-sampled), and the neural pass reads that value."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from diviewer.gl.frame import Frame
from diviewer.gl.renderer import Renderer


@pytest.fixture(scope="module")
def cornell():
    from diviewer.scene import load_scene

    return load_scene("cornell")


def test_the_renderer_returns_its_targets_with_the_direct_light_decided(ctx, cornell):
    r = Renderer(ctx, cornell, 24, 16)
    try:
        r.render(cornell.default)
        f = r.buffers(inline=True)  # drawn already: the pass's target
        assert (f.direct_from, f.samples, f.size, f.view) == ("pass", 1, (24, 16), r.frame_view)
        assert f.textures == {k: r.textures[k] for k in ("depth", "normal", "albedo", "direct")} and f.defines() == {}
        r.render(cornell.default, direct=False)
        assert r.buffers().direct_from == "pass" and not r.direct_pending  # not asked inline: the pass runs now
        r.render(cornell.default, direct=False)
        f = r.buffers(inline=True)
        assert f.inline and f.direct is r.textures["emission"] and r.direct_pending  # left to the reader
        assert f.light is cornell.default.lights[0] and f.defines()["INLINE_DIRECT"] == 1
        two = dataclasses.replace(cornell.default, lights=cornell.default.lights * 2)
        r.render(two, direct=False)
        assert r.buffers(inline=True).direct_from == "pass"  # more than one light: the pass draws them
        assert r.buffers(samples=4).direct_from == "area" and r.buffers(samples=4).samples == 4
    finally:
        r.release()


def test_one_buffer_by_name_leaves_a_deferred_direct_pass_deferred_but_for_direct(ctx, cornell):
    """`Renderer.buffer` (what the viewer's view modes show): the G-buffer's textures as drawn, the direct pass still
    deferred; ``direct`` is `buffers`' own, the deferred pass run then."""
    r = Renderer(ctx, cornell, 24, 16)
    try:
        two = dataclasses.replace(cornell.default, lights=cornell.default.lights * 2)  # no inline light: a pass
        r.render(two, direct=False)
        for name in ("depth", "normal", "albedo"):
            assert r.buffer(name) is r.textures[name] and r.direct_pending
        assert r.buffer("direct") is r.buffers().direct is r.textures["direct"] and not r.direct_pending
        deferred = r.read("direct")
        r.render(two)
        np.testing.assert_array_equal(deferred, r.read("direct"))  # the pass it ran is the frame's own
        with pytest.raises(KeyError, match="emission"):
            r.buffer("emission")
    finally:
        r.release()


def test_a_frame_is_consistent(ctx):
    tex = ctx.texture((2, 2), 4, dtype="f4")
    try:
        with pytest.raises(ValueError, match="direct_from"):
            Frame((2, 2), tex, tex, tex, tex, direct_from="guess")
        with pytest.raises(ValueError, match="sample"):
            Frame((2, 2), tex, tex, tex, tex, samples=2)
        with pytest.raises(ValueError, match="sample"):
            Frame((2, 2), tex, tex, tex, tex, direct_from="area")
    finally:
        tex.release()


def test_the_neural_pass_composites_the_frame_it_ran_on(ctx, cornell):
    """run() decides the direct light once; something reading the direct buffer between run() and composite()
    (a view mode, VXGI) changes nothing; a frame of a model of another area's samples is refused; a frame given to
    run() is read until run() is called without one."""
    pytest.importorskip("onnx")
    from diviewer.gl.neural import GISettings, NeuralPass
    from diviewer.contract.runtime import NeuralGI

    net = NeuralGI("assets/models/cornell.onnx", scene=cornell)
    net.direct_samples = 1  # as a model of the light at each pixel's centre: inline where it can
    r = Renderer(ctx, cornell, 32, 32)
    p = NeuralPass(ctx, r, net, None, GISettings(lean=False))
    try:
        finals = []
        for read_between in (False, True):
            r.render(cornell.default, direct=False)
            p.run(**p.inputs_for(cornell, cornell.default))
            assert p.inline_direct and p.frame.inline
            if read_between:
                r.ensure_direct()
            finals.append(np.frombuffer(p.composite().read(), np.float16))
            assert p.inline_direct
        np.testing.assert_array_equal(*finals)
        with pytest.raises(ValueError, match="samples"):
            p.run(**p.inputs_for(cornell, cornell.default), frame=r.buffers(samples=2))
        given = r.buffers()
        p.run(**p.inputs_for(cornell, cornell.default), frame=given)
        assert p.frame is given and not p.inline_direct
        r.render(cornell.default, direct=False)  # a new frame: run() without one reads it
        p.run(**p.inputs_for(cornell, cornell.default))
        assert p.frame.view is r.frame_view and p.inline_direct
    finally:
        p.release()
        r.release()
