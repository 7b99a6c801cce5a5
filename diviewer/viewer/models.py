"""Which model the viewer runs: a file, the scene's shipped models (``auto``) or none, and why not."""

from __future__ import annotations

from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.scene.model import Scene


def model_candidates(scene: Scene) -> list[Path]:
    """The shipped models named for this scene: assets/models/<scene>*.onnx."""
    from diviewer.paths import models_dir

    try:
        folder = models_dir()
    except FileNotFoundError:
        return []
    return sorted(folder.glob(f"{scene.name}*.onnx")) if folder.is_dir() else []


def open_model(spec: str | Path | None, scene: Scene, provider: str | None = None):
    """Load the model ``spec`` asks for (a path, ``auto`` or ``none``) for ``scene``.

    Returns:
        (NeuralGI or None, message): the message says why there is no model, or which was chosen.
    """
    from diviewer.runtime import NeuralGI, choose_providers

    spec = "auto" if spec is None else str(spec)
    if spec.lower() == "none":
        return None, "neural GI is off (no model requested)"
    if provider:
        import onnxruntime as ort

        # A missing provider is the user's error, not the model's.
        choose_providers(ort.get_available_providers(), provider)
    if spec.lower() != "auto":
        try:
            return NeuralGI(spec, scene=scene, provider=provider), ""
        except DiviewerError as exc:
            return None, f"model refused: {exc}"
    candidates = model_candidates(scene)
    if not candidates:
        from diviewer.paths import models_dir

        try:
            where = models_dir()
        except FileNotFoundError:
            where = "assets/models"
        return None, (f"no model for scene '{scene.name}' in {where} (train and export one: diviewer train, "
                      f"diviewer export); showing direct light only")
    refusals = []
    for path in candidates:
        try:
            return NeuralGI(path, scene=scene, provider=provider), ""
        except DiviewerError as exc:
            refusals.append(str(exc))
    return None, "no compatible model for this scene: " + "; ".join(refusals)
