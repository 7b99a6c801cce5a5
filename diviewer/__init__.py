"""diviewer: a real-time OpenGL viewer with a per-scene neural global-illumination pass.

The names a script uses (docs/examples/script_api.py), each imported on first use so that ``import diviewer``
stays cheap (no GL, no onnxruntime, no torch):

- `load_scene` (`diviewer.scene`): a shipped scene's name or a scene file to a `Scene`;
- `sample_config` (`diviewer.scene`): a frame's camera, lights and objects drawn from the scene's ranges;
- `render_frame` (`diviewer.headless`): one frame headless, its named buffers as numpy arrays, and with a model
  its neural GI image;
- `NeuralGI` (`diviewer.contract.runtime`): an ONNX model loaded and checked, run on raw buffers;
- `iter_frames` (`diviewer.evaluation.perframe`): an evaluation set frame by frame, the model's inputs, output and
  the path-traced truth;
- `evaluate_evalset` (`diviewer.evaluation.evaluate`): `diviewer eval`'s scores of models on an evaluation set;
- `DiviewerError` (`diviewer.errors`): what every user error raises.
"""

__version__ = "0.1.0"

_API = {"load_scene": "diviewer.scene", "sample_config": "diviewer.scene", "render_frame": "diviewer.headless",
        "NeuralGI": "diviewer.contract.runtime", "iter_frames": "diviewer.evaluation.perframe",
        "evaluate_evalset": "diviewer.evaluation.evaluate", "DiviewerError": "diviewer.errors"}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    """The public API's names, imported on first use."""
    if name not in _API:
        raise AttributeError(f"module 'diviewer' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_API[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
