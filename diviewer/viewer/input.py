"""Keyboard and mouse: one table binds keys to actions, and the shortcut list (panel, README) is read from it.

``Input`` receives GLFW's events after imgui has seen them (``imgui_gl.GlfwImgui`` calls its ``on_*``)
and applies them to the viewer's state, the window (vsync, quit) and the screenshot queue; it never calls the app,
which copies imgui's wishes (``wants_keyboard``, ``wants_mouse``) and the image's size (``view_size``) into it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from diviewer.viewer.view_modes import VIEW_MODES

LIGHT_STEP = 5.0
"""Degrees an arrow key turns the light."""
CLICK_SLOP = 3.0
"""Pixels the pointer may travel between press and release for a click (more is a drag)."""


@dataclass(frozen=True)
class Binding:
    """One row of the controls: keys (chords such as ``Ctrl+S``) and what they do."""

    label: str
    help: str
    chords: tuple[str, ...] = ()
    """GLFW key names, with ``Ctrl+`` / ``Shift+`` when the modifier is required; empty for the mouse and the
    held movement keys (handled by ``Input`` itself)."""
    run: Callable[["Input", str], Any] | None = None
    """Called with the input handler and the chord that matched."""
    repeat: bool = False
    """Also on key repeat (held arrows keep turning the light)."""
    listed: bool = True
    """Shown in the shortcut list (the per-mode digits are summarised in one row)."""


def _turn_light(i: "Input", chord: str) -> None:
    st = i.state
    if not st.config.lights:
        return
    az, el = st.light_angles()
    az += LIGHT_STEP * ((chord == "RIGHT") - (chord == "LEFT"))
    el = min(max(el + LIGHT_STEP * ((chord == "UP") - (chord == "DOWN")), -89.0), 89.0)
    st.set_light_direction(az, el)


def _next_object(i: "Input", _chord: str) -> None:
    st = i.state
    names = [o.name for o in st.config.objects]
    k = names.index(st.selected) + 1 if st.selected in names else 0
    st.select_object(names[k % len(names)])


def _toggle_panel(i: "Input", _chord: str) -> None:
    i.state.show_panel = not i.state.show_panel


BINDINGS: tuple[Binding, ...] = (
    Binding("W A S D", "fly forward / left / back / right (orbit: pan the centre)"),
    Binding("Q / E", "down / up"),
    Binding("Shift", "move 4x faster"),
    Binding("right mouse drag", "look around"),
    Binding("left mouse drag", "orbit (orbit camera) / look (fly camera)"),
    Binding("left click", "select the object under the cursor"),
    Binding("mouse wheel", "flying speed (fly) / zoom (orbit)"),
    Binding("C", "switch fly / orbit camera", ("C",), lambda i, _: i.state.toggle_controller()),
    Binding("R", "reset the camera", ("R",), lambda i, _: i.state.reset_camera()),
    Binding("O", "overview: the camera above the scene's box, looking at its centre", ("O",),
            lambda i, _: i.state.overview_camera()),
    Binding("Shift+R", "reset the whole frame (lights, objects, camera)", ("Shift+R",), lambda i, _: i.state.reset()),
    Binding("arrow keys", "light azimuth (left/right) and elevation (up/down)", ("LEFT", "RIGHT", "UP", "DOWN"),
            _turn_light, repeat=True),
    Binding("L", "animate the light", ("L",), lambda i, _: i.state.toggle_animation()),
    Binding("P", "play the camera path (the --path file, else the scene's own walk)", ("P",),
            lambda i, _: i.state.toggle_path()),
    Binding("Ctrl+R", "record the camera path / stop and save it as JSON", ("Ctrl+R",),
            lambda i, _: i.state.toggle_recording()),
    Binding("Tab", "select the next object", ("TAB",), _next_object),
    Binding("1 ... 0", "view modes: " + ", ".join(f"{m.key} {m.name}" for m in VIEW_MODES if m.key)),
    *(Binding(m.key, m.label, (m.key,), lambda i, _, name=m.name: i.state.set_view_mode(name), listed=False)
      for m in VIEW_MODES if m.key),
    Binding("+ / -", "exposure up / down half a stop", ("EQUAL", "KP_ADD", "MINUS", "KP_SUBTRACT"),
            lambda i, chord: i.state.set_exposure(i.state.exposure + (0.5 if chord in ("EQUAL", "KP_ADD") else -0.5))),
    Binding("F12 or Ctrl+S", "screenshot (PNG + frame JSON)", ("F12", "Ctrl+S"),
            lambda i, _: i.shots.request(i.state.shot_path)),
    Binding("V", "vsync on / off", ("V",), lambda i, _: i.window.set_vsync(not i.window.vsync)),
    Binding("H or F1", "show / hide the panel", ("H", "F1"), _toggle_panel),
    Binding("Esc", "quit", ("ESCAPE",), lambda i, _: i.window.request_close()),
)
"""The controls, in the order the panel and the README list them."""

SHORTCUTS: tuple[tuple[str, str], ...] = tuple((b.label, b.help) for b in BINDINGS if b.listed)
"""(keys, what they do) for the panel and the README."""


def shortcuts_markdown() -> str:
    """The shortcut list as the README's Markdown table (a test keeps the README equal to it)."""
    return "\n".join(["| keys | action |", "| --- | --- |", *(f"| {k} | {what} |" for k, what in SHORTCUTS)])


def _split(chord: str) -> tuple[str, bool, bool]:
    """(key name, needs Ctrl, needs Shift) of a chord such as ``Ctrl+S``."""
    *mods, key = chord.split("+")
    return key, "Ctrl" in mods, "Shift" in mods


def pick_window_point(state, window, x: float, y: float, view_size: tuple[int, int]) -> str | None:
    """Select the object under window point (x, y) (screen units, y down) of the image shown at ``view_size``."""
    point = window.to_image(x, y, view_size)
    if point is None:
        return state.select_object(None)
    return state.pick(*point, *view_size)


class Input:
    """Applies GLFW events to ``state`` (a ViewerState), ``window`` (``viewer.window.Window``) and ``shots`` (the
    screenshot queue, ``viewer.screenshots.Screenshots``)."""

    def __init__(self, state, window, shots, glfw):
        self.state, self.window, self.shots, self.glfw = state, window, shots, glfw
        self.mouse = {"left": False, "right": False, "x": 0.0, "y": 0.0, "dragged": 0.0}
        self.view_size = (1, 1)
        """The framebuffer size the image is shown at (the app's ``view_size``), for picking."""
        self.wants_keyboard = self.wants_mouse = False
        """Whether imgui took the keyboard / the mouse in its last frame (the app copies them after each)."""

    def _matches(self, chord: str, key: int, ctrl: bool, shift: bool) -> bool:
        name, needs_ctrl, needs_shift = _split(chord)
        if needs_ctrl != ctrl or (needs_shift and not shift):
            return False
        if len(name) == 1 and name.isdigit():
            # Digits by the layout's name for the key, as the user reads it on the keycap.
            return self.glfw.get_key_name(key, 0) == name
        return key == getattr(self.glfw, f"KEY_{name}", None)

    def binding_for(self, key: int, mods: int) -> tuple[Binding, str] | None:
        """The binding a key press triggers and the chord that matched; a chord that needs Shift wins over one
        that does not (Shift+R before R), and Ctrl must be held exactly when a chord asks for it."""
        glfw = self.glfw
        ctrl, shift = bool(mods & glfw.MOD_CONTROL), bool(mods & glfw.MOD_SHIFT)
        found = None
        for b in BINDINGS:
            for chord in b.chords:
                if self._matches(chord, key, ctrl, shift):
                    if _split(chord)[2]:
                        return b, chord
                    found = found or (b, chord)
        return found

    # --- GLFW callbacks (after imgui) -------------------------------------------------------------
    def on_key(self, key: int, action: int, mods: int) -> None:
        glfw = self.glfw
        if action not in (glfw.PRESS, glfw.REPEAT) or self.wants_keyboard:
            return
        hit = self.binding_for(key, mods)
        if hit is None:
            return
        binding, chord = hit
        if action == glfw.PRESS or binding.repeat:
            binding.run(self, _split(chord)[0])

    def on_mouse_button(self, button: int, action: int, mods: int) -> None:
        glfw, m = self.glfw, self.mouse
        which = {glfw.MOUSE_BUTTON_LEFT: "left", glfw.MOUSE_BUTTON_RIGHT: "right"}.get(button)
        if which is None:
            return
        if action == glfw.PRESS:
            if self.wants_mouse:
                return
            m[which] = True
            m["dragged"] = 0.0
        elif action == glfw.RELEASE and m[which]:
            m[which] = False
            if which == "left" and m["dragged"] < CLICK_SLOP:
                pick_window_point(self.state, self.window, m["x"], m["y"], self.view_size)  # where on_cursor saw it

    def on_cursor(self, x: float, y: float) -> None:
        m = self.mouse
        dx, dy = x - m["x"], y - m["y"]
        m["x"], m["y"] = x, y
        if m["right"]:
            self.state.look(dx, dy)
        elif m["left"]:
            m["dragged"] += abs(dx) + abs(dy)
            if m["dragged"] >= CLICK_SLOP:
                self.state.drag(dx, dy)

    def on_scroll(self, dx: float, dy: float) -> None:
        if not self.wants_mouse:
            self.state.scroll(dy)

    def held_keys(self, dt: float) -> None:
        """WASD/QE movement for the keys held during the last ``dt`` seconds."""
        glfw, window = self.glfw, self.window
        if self.wants_keyboard:
            return
        down = window.key_down
        if down(glfw.KEY_LEFT_CONTROL) or down(glfw.KEY_RIGHT_CONTROL):
            return
        f = down(glfw.KEY_W) - down(glfw.KEY_S)
        r = down(glfw.KEY_D) - down(glfw.KEY_A)
        u = down(glfw.KEY_E) - down(glfw.KEY_Q)
        if f or r or u:
            self.state.fly(f, r, u, dt, fast=down(glfw.KEY_LEFT_SHIFT) or down(glfw.KEY_RIGHT_SHIFT))
