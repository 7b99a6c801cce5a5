"""diviewer: a real-time OpenGL viewer with a per-scene neural global-illumination pass."""

__version__ = "0.1.0"
