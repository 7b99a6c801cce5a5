"""Scripted viewer runs: actions applied before given frames (tests, ``diviewer view --script``, the bench).

An action is a callable(viewer), ``(name, kwargs)`` or ``{"action": name, **kwargs}``; a name is one of
the viewer's ``SCRIPT_ACTIONS`` or a ``ViewerState`` method (set_view_mode, set_light_direction, fly, ...).
"""

from __future__ import annotations

from diviewer.errors import DiviewerError

SCRIPT_ACTIONS = ("resize", "screenshot", "window_screenshot", "set_model", "request_model", "set_vsync",
                  "pick_window_point", "set_gi_res", "set_pipelined", "set_timing", "set_render_scale",
                  "set_target_fps")
"""Viewer methods a script (or the panel's requests) may call; any other name is looked up on the viewer's state."""


def normalise_script(script) -> dict[int, list]:
    """Script items (frame, action) / (frame, name, kwargs) / {"frame": i, "action": name, ...} by frame."""
    out: dict[int, list] = {}
    for item in script or ():
        if isinstance(item, dict):
            item = dict(item)
            frame = int(item.pop("frame"))
            out.setdefault(frame, []).append(item)
        elif len(item) == 2:
            out.setdefault(int(item[0]), []).append(item[1])
        else:
            out.setdefault(int(item[0]), []).append((item[1], item[2] if len(item) > 2 else {}))
    return out


def apply_action(viewer, action) -> None:
    """Apply one script action to ``viewer`` (a ``viewer.app.Viewer``) or its state."""
    if callable(action):
        action(viewer)
        return
    if isinstance(action, dict):
        action = dict(action)
        name, kwargs = action.pop("action"), action
    else:
        name, kwargs = action[0], (action[1] if len(action) > 1 else {})
    target = viewer if name in SCRIPT_ACTIONS else viewer.state
    fn = getattr(target, name, None)
    if fn is None or name.startswith("_"):
        raise DiviewerError(f"unknown viewer action '{name}'", field="script")
    fn(**kwargs)
