"""The panel drawn from a `PanelView` in an imgui frame without a window: every section, and the viewer actions its
widgets ask for, returned as requests the app applies (named actions of `script.SCRIPT_ACTIONS`)."""

from __future__ import annotations

import dataclasses
import inspect
from pathlib import Path

import pytest
from imgui_bundle import imgui

from diviewer.scene import load_scene
from diviewer.viewer.panel import Panel
from diviewer.viewer.panel_view import PanelView
from diviewer.viewer.script import SCRIPT_ACTIONS
from diviewer.viewer.state import ViewerState

MODEL = Path(__file__).resolve().parents[2] / "assets" / "models" / "cornell.onnx"
VIEW = PanelView(window_size=(800, 600), fb_size=(800, 600), vsync=True, render_size=(400, 300), render_scale=0.5,
                 gi_size=(128, 96), target_fps=0.0, motion="moving", frame_counts=(("moving", 3), ("refining", 0),
                                                                                    ("still", 0)),
                 model_path=MODEL, candidates=(MODEL,), gi_sizes=(("model", (171, 128)), ("1/2", (200, 150))),
                 gi_note="", neural=True, pipelined=False, latency_ms=0.0, inline_direct=True,
                 unavailable=(("reference", "Mitsuba is not installed"),), reference_available=False,
                 reference_status="Mitsuba is not installed", reference_ready=False, gl_renderer="llvmpipe",
                 timing_method="timer queries", timer_sync=True)


@pytest.fixture
def ui():
    """An imgui context of 800x600 with no window; ``frame(fn)`` runs ``fn`` inside one of its frames."""
    ctx = imgui.create_context()
    io = imgui.get_io()
    io.set_ini_filename(None)
    io.display_size = imgui.ImVec2(800, 600)
    io.backend_flags |= imgui.BackendFlags_.renderer_has_textures  # the font atlas is left to a renderer

    def frame(fn):
        io.delta_time = 1.0 / 60.0
        imgui.new_frame()
        try:
            return fn()
        finally:
            imgui.render()

    yield frame
    imgui.destroy_context(ctx)


@pytest.fixture
def panel(monkeypatch):
    """A panel on cornell's state with every section open."""
    monkeypatch.setattr(imgui, "collapsing_header", lambda *a, **k: True)
    return Panel(ViewerState(load_scene("cornell")))


def _touch(monkeypatch, widget: str, label: str, value=None) -> None:
    """Make imgui's ``widget`` labelled ``label`` report a change to ``value`` (a button: pressed)."""
    real = getattr(imgui, widget)

    def touched(lbl, *args, **kwargs):
        out = real(lbl, *args, **kwargs)
        if lbl != label:
            return out
        return True if widget == "button" else (True, value)

    monkeypatch.setattr(imgui, widget, touched)


def _choose(monkeypatch, combo: str, item: str) -> None:
    """Make the combo labelled ``combo`` open with ``item`` clicked."""
    begin, selectable = imgui.begin_combo, imgui.selectable
    monkeypatch.setattr(imgui, "begin_combo", lambda lbl, *a, **k: lbl == combo or begin(lbl, *a, **k))
    monkeypatch.setattr(imgui, "end_combo", lambda: None)  # only the combo opened here is ever open
    monkeypatch.setattr(imgui, "selectable", lambda lbl, sel, *a, **k: (True, True) if lbl == item
                        else selectable(lbl, sel, *a, **k))


def _is_viewer_action(name: str, kwargs: dict) -> bool:
    from diviewer.viewer.app import Viewer

    inspect.signature(getattr(Viewer, name)).bind(None, **kwargs)  # raises for arguments the action does not take
    return name in SCRIPT_ACTIONS


@pytest.mark.parametrize("view", [VIEW, dataclasses.replace(VIEW, model_path=None, candidates=(), gi_sizes=(),
                                                            neural=False, unavailable=(("net_output", "no model"),),
                                                            pipelined=True, reference_ready=True)],
                         ids=["model", "no model"])
def test_every_section_draws_from_the_view_and_asks_for_nothing_untouched(ui, panel, view):
    panel.state.set_view_mode("split", a="net_output", b="reference")
    assert ui(lambda: panel.draw(view)) == []
    ui(lambda: panel.overlay((0, 0, 800, 600), ["Network output: raw GI: no model"], view))
    assert panel.state.message == ""


@pytest.mark.parametrize("widget, label, value, asked", [
    ("checkbox", "vsync (V)", False, ("set_vsync", {"on": False})),
    ("checkbox", "per-stage timing", False, ("set_timing", {"on": False})),
    ("checkbox", "inference one frame behind (worker thread)", True, ("set_pipelined", {"on": True})),
    ("slider_int", "target fps (0 off)", 30, ("set_target_fps", {"fps": 30})),
    ("slider_float", "render scale", 0.75, ("set_render_scale", {"scale": 0.75})),
    ("button", "save (F12)", None, ("screenshot", {"path": "diviewer_cornell.png"})),
])
def test_a_widget_touched_returns_its_viewer_action(ui, panel, monkeypatch, widget, label, value, asked):
    _touch(monkeypatch, widget, label, value)
    assert ui(lambda: panel.draw(VIEW)) == [asked]
    assert _is_viewer_action(*asked)


@pytest.mark.parametrize("combo, item, asked", [
    ("model", "none (direct light only)", ("request_model", {"spec": "none"})),
    ("GI resolution", "1/2 of the shading size: 200x150", ("set_gi_res", {"spec": "1/2"})),
])
def test_a_model_or_gi_resolution_chosen_is_requested(ui, panel, monkeypatch, combo, item, asked):
    _choose(monkeypatch, combo, item)
    assert ui(lambda: panel.draw(VIEW)) == [asked]
    assert _is_viewer_action(*asked)


def test_the_panel_changes_the_state_itself(ui, panel, monkeypatch):
    """What lives in the state (the screenshot's file, the exposure) the panel changes directly: no request."""
    _touch(monkeypatch, "input_text", "file", "shot.png")
    _touch(monkeypatch, "slider_float", "exposure (EV)", 1.5)
    assert ui(lambda: panel.draw(VIEW)) == []
    assert panel.state.shot_path == "shot.png" and panel.state.exposure == 1.5
