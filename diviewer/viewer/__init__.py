"""The interactive viewer. ``session.run_viewer`` opens it; each room is one file:

app (the frame loop), session (a run from start to end), still (a still view refined), window (size, HiDPI
scale, letterbox, window-to-image mapping), input (the key table), panel (imgui; never imports app: it is drawn
from a panel_view.PanelView and returns the actions it asks for),
screenshots, sources (the view modes' textures), models (which model), gi (the model's neural pass and the GI
resolution policy), script (scripted runs), report (a run's summary and stats JSON), view_modes, stats, command
(``diviewer view``'s arguments). ``state``, ``controls``, ``still``,
``view_modes`` and ``stats`` are pure state and math (no GL), testable without a display. The display
pass is ``diviewer.gl.display``; the path-traced preview ``diviewer.reference.progressive``.
"""
