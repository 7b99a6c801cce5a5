"""The frame walk (G-buffer -> network -> screen) and the recipe walk (recipe file -> the trainer's settings) pass
through each diviewer module without going back, measured on a real run with `sys.setprofile`.

A walk is recorded as the 'call' events into functions of ``diviewer.*`` modules (a function's module is its
globals' ``__name__``: methods, properties, dataclass-made ``__init__`` and comprehensions included), each with the
diviewer module of its nearest caller. Its stops are the modules of those calls, consecutive calls into one module
collapsed. A module called again after the walk left it is a re-entry; most are the walk coming back from a callee
and going on in its caller, or a module below several others called from each (a scene's dataclasses, the uniform
setter). A trip back is the walk going back to a module it came from: a call from module N into module M where M
had already led, directly or through others, to N in the same walk (a callback into a caller, or a later stage
reaching back into an earlier one). No module of either walk may be entered on a trip back, so the modules of each
walk can be ordered with every call pointing forward.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from walks import Walk, walk

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "assets" / "models" / "cornell.onnx"


@pytest.fixture(scope="module")
def frame_walk(gl_context):
    """One headless frame of cornell with its shipped model through the public API, after a warm-up frame (imports,
    shader sources, the model's lean path read once)."""
    import diviewer

    scene = diviewer.load_scene("cornell")
    config = diviewer.sample_config(scene, 3, "train")
    kwargs = dict(size=(24, 16), model=MODEL, provider="cpu")
    diviewer.render_frame(scene, config, **kwargs)
    w = walk(diviewer.render_frame, scene, config, **kwargs)
    assert w.result["neural"].shape == (16, 24, 3)
    return w


@pytest.fixture(scope="module")
def recipe_walk(tmp_path_factory):
    """`diviewer train --recipe FILE` to its TrainConfig (the trainer's settings, before any data is read), for a
    recipe file written here, after a warm-up read."""
    from diviewer.commands.parser import CommandParser
    from diviewer.commands.train import add_parser, resolve_config

    tmp = tmp_path_factory.mktemp("recipe")
    recipe = tmp / "tiny.toml"
    recipe.write_text('[recipe]\nscene = "cornell"\ndescription = "a tiny recipe"\n\n'
                      '[capture]\nframes = 20\nwidth = 32\nheight = 32\nspp = 4\n\n'
                      '[train]\nK = 8\nepochs = 1\nbatch_size = 2\n\n[export]\nfp16 = false\n\n[ladder]\nK = [8]\n')
    ap = CommandParser()
    add_parser(ap.add_subparsers(dest="command"))
    args = ap.parse_args(["train", "--recipe", str(recipe), "--data", str(tmp / "data"), "--out", str(tmp / "run")])
    resolve_config(args)
    w = walk(resolve_config, args)
    assert (w.result.K, w.result.epochs, w.result.recipe["file"]) == (8, 1, str(recipe))
    return w


def test_the_frame_walk_goes_from_the_gbuffer_to_the_network_to_the_screen(frame_walk):
    stops = frame_walk.stops
    order = [stops.index(m) for m in ("diviewer.headless", "diviewer.gl.renderer", "diviewer.gl.neural")]
    assert order == sorted(order), stops[:12]
    assert {"diviewer.contract.runtime", "diviewer.gl.lean"} <= set(stops)


def test_the_frame_walk_never_goes_back(frame_walk):
    assert frame_walk.trips_back() == {}, frame_walk.summary()


def test_the_recipe_walk_reads_the_recipe_then_builds_the_trainers_settings(recipe_walk):
    stops = recipe_walk.stops
    assert stops[0] == "diviewer.commands.train"
    assert stops.index("diviewer.train.recipe") < len(stops) - 1 - stops[::-1].index("diviewer.train.config")


def test_the_recipe_walk_never_goes_back(recipe_walk):
    assert recipe_walk.trips_back() == {}, recipe_walk.summary()


def test_the_trip_back_rule_finds_a_callback_and_a_later_stage_reaching_back():
    """The rule on planted walks: a callback (A -> B -> A) and a later stage calling an earlier one (A -> B,
    B -> C, C -> A) are trips back; a module called from two others, or a caller going on after a call
    returned, is not."""
    forward = Walk([("a", "f", None), ("b", "g", "a"), ("c", "h", "b"), ("c", "h", "a"), ("a", "i", "a")])
    assert forward.trips_back() == {} and forward.stops == ["a", "b", "c", "a"]
    assert forward.reentries() == [("a", "a")]
    callback = Walk([("a", "f", None), ("b", "g", "a"), ("a", "helper", "b")])
    assert callback.trips_back() == {("b", "a"): ["helper"]}
    later = Walk([("a", "f", None), ("b", "g", "a"), ("c", "h", "b"), ("a", "again", "c")])
    assert later.trips_back() == {("c", "a"): ["again"]}
