"""The interactive viewer: GLFW window, camera controls, imgui panel, background path-traced reference.

``diviewer.viewer.app.run_viewer`` opens it; ``diviewer.viewer.state`` and ``controls`` are pure
state and math (no GL), testable without a display.
"""
