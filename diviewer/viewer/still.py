"""A still view converges: the motion state of each frame (moving, refining, still). Pure Python, no GL.

Dynamic resolution (``scale.py``) trades sharpness for frame rate, a trade that pays only while something moves.
Each frame the viewer hands ``StillTracker.update`` a key of everything that decides the image (the frame's
camera, lights and objects, the scene's meshes, the window's framebuffer size, the view mode, the model, the GI
settings); the tracker answers:

- ``moving``: the key changed within the last ``wait`` frames: draw at the dynamic scale (its frame times
  feed the scale controller);
- ``refining``: the key has held for ``wait`` frames: draw at the refined scale (1, or the controller's ceiling
  above 1: supersampled) for ``refine_frames`` frames (the pipelined GI one frame behind and the shadow maps
  drawn in bands then catch up);
- ``still``: refined and unchanged: present the refined image again without drawing it (``can_rest`` False
  keeps it refining: a shadow map still drawn in bands, the progressive reference on screen).

A change returns the next frame to ``moving`` at once. The tracker counts the frames of each state.
"""

from __future__ import annotations

from dataclasses import dataclass

MOTION_STATES = ("moving", "refining", "still")
"""The states a frame is drawn in, in the order a view comes to rest."""


@dataclass(frozen=True)
class StillSettings:
    """When a view that stopped changing is refined, and for how long before it is only presented."""

    refine: bool = True
    """Refine a still view (False: every frame at the dynamic scale, as while moving)."""
    wait: int = 2
    """Unchanged frames drawn at the dynamic scale before refining (a pause between two mouse events does not
    cost a frame at full scale)."""
    refine_frames: int = 3
    """Frames drawn at the refined scale before the image is presented without drawing (inference one frame
    behind needs two to show the refined frame's GI)."""


class StillTracker:
    """The motion state of each frame from a key of what decides the image (compared with ``==``)."""

    def __init__(self, settings: StillSettings = StillSettings()):
        if settings.wait < 0 or settings.refine_frames < 1:
            raise ValueError(f"still view: wait >= 0 and refine_frames >= 1, got {settings}")
        self.settings = settings
        self.state = "moving"
        self.counts = dict.fromkeys(MOTION_STATES, 0)
        """Frames drawn in each state."""
        self._key: object = None
        self._first = True
        self._unchanged = 0
        """Frames the key has held (0: it changed this frame)."""
        self._refined = 0

    def update(self, key: object, can_rest: bool = True) -> str:
        """The state of the frame about to be drawn, whose image ``key`` decides; counted."""
        if self._first or key != self._key:
            self._first, self._key, self._unchanged, self._refined = False, key, 0, 0
        else:
            self._unchanged += 1
        s = self.settings
        if not s.refine or self._unchanged < s.wait:
            state = "moving"
        elif self._refined < s.refine_frames or not can_rest:
            state = "refining"
            self._refined += 1
        else:
            state = "still"
        self.state = state
        self.counts[state] += 1
        return state


def still_key(viewer) -> tuple:  # viewer: a viewer.app.Viewer
    """What decides the image (``StillTracker``'s key): the frame, the meshes, the window, the view mode, the
    model, the GI and dynamic-resolution settings."""
    st = viewer.state
    return (st.config, st.scene_revision, tuple(viewer.window.fb_size), st.view_mode, st.compare, st.model_name,
            viewer.gi.settings, viewer.gi.size, viewer.scaler.settings, viewer._pending_model)


def can_rest(viewer) -> bool:
    """Whether a refined view may be presented without drawing: no shadow map still drawn in bands, no
    progressive reference on screen, the temporal history (where it refines the view) full."""
    t = viewer.temporal
    accumulating = t is not None and not viewer.scaler.enabled and not t.converged
    return not (viewer.renderer.shadows_pending or accumulating
                or any(m.name == "reference" for m in viewer.state.modes_shown()))
