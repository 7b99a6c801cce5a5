"""Which model the viewer runs: a file, the scene's shipped models (``auto``) or none, and why not."""

from __future__ import annotations

import math
from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.scene.model import Scene


def model_candidates(scene: Scene) -> list[Path]:
    """The models ``--model auto`` tries, in order: the shipped ones named for this scene
    (assets/models/<scene>*.onnx), then the one `diviewer build` writes by default (runs/<file stem>/<scene>.onnx
    under the current folder)."""
    from diviewer.paths import default_work_dir, models_dir

    try:
        folder = models_dir()
        shipped = sorted(folder.glob(f"{scene.name}*.onnx")) if folder.is_dir() else []
    except FileNotFoundError:
        shipped = []
    built = default_work_dir(scene.path if scene.path is not None else scene.name) / f"{scene.name}.onnx"
    return shipped + ([built] if built.is_file() else [])


def open_model(spec: str | Path | None, scene: Scene, provider: str | None = None):
    """Load the model ``spec`` asks for (a path, ``auto`` or ``none``) for ``scene``.

    Returns:
        (NeuralGI or None, message): the message says why there is no model, or which was chosen.
    """
    from diviewer.contract.runtime import NeuralGI, choose_providers

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
    refusals = []
    for path in candidates:
        try:
            return NeuralGI(path, scene=scene, provider=provider), ""
        except DiviewerError as exc:
            refusals.append(str(exc))
    return None, no_model_message(scene, refusals)


def no_model_message(scene: Scene, refusals: list[str] = ()) -> str:
    """One line for ``--model auto`` without a model that fits: where it looked, that the view goes on without
    neural GI, and what `diviewer build` would do for this scene."""
    from diviewer.paths import default_work_dir, models_dir, scenes_dir

    try:
        where = models_dir()
    except FileNotFoundError:
        where = Path("assets/models")
    shipped = scene.path is None or Path(scene.path).resolve() == (scenes_dir() / f"{scene.name}.toml").resolve()
    spec = scene.name if shipped else scene.path
    built = default_work_dir(spec) / f"{scene.name}.onnx"
    found = (f"no model in {where} or {built} fits scene '{scene.name}' ({'; '.join(refusals)})" if refusals
             else f"no model for scene '{scene.name}' in {where} or {built}")
    build = f"`diviewer build --scene {spec}` captures, trains and writes one to {built}, where --model auto finds it"
    return f"{found}: showing direct light only, without neural GI; {build}"


MIN_GI_SHARE = 1 / 16
"""The smallest fraction of the window the GI may run at (``--gi-res``)."""

GI_FRACTIONS = ("1/1", "1/2", "1/3", "1/4", "1/6", "1/8")
"""GI resolutions offered as fractions of the window's framebuffer (the panel's list, ``--gi-res``)."""


def runtime_pads(model) -> bool:
    """Whether the runtime runs ``model`` at any size (padding to its stride inside), or only at multiples of
    its stride: asked of the runtime's own size check, with a width one past a multiple."""
    check = getattr(model, "check_size", None)
    if check is None:
        return True
    try:
        check(int(model.multiple) + 1, int(model.resolution[1]))
    except DiviewerError:
        return False
    return True


def gi_share(spec: str) -> float:
    """The share of the window a GI resolution ``N/D`` asks for (NaN where it is not a fraction)."""
    try:
        num, den = (float(x) for x in str(spec).split("/"))
        return num / den
    except (ValueError, ZeroDivisionError):
        return math.nan


def gi_resolution(spec: str, window: tuple[int, int], trained: tuple[int, int], multiple: int,
                  pads: bool = False, shape: tuple[int, int] | None = None) -> tuple[int, int]:
    """The GI resolution ``spec`` asks for, for a model of stride ``multiple`` trained at ``trained``.

    ``model`` keeps the training row count and takes the width from the shape of ``shape`` (the window; default
    ``window``): a 1024x768 window gives 171x128 for a model trained at 128x128, the network seeing the
    window's own shape. A fraction (``1/4``) scales ``window`` (the shading resolution). Where the runtime
    ``pads`` to the stride these sizes are used as they are; where it does not, each side is snapped to the
    nearest multiple of the stride (at least one stride; ``model`` then squashes a wide window into the
    training width). An explicit ``WxH`` must then already be a multiple of the stride, or it is refused.
    """
    spec = str(spec).strip().lower()
    m = max(1, int(multiple))
    snap = (lambda v: max(1, round(v))) if pads else (lambda v: max(m, round(v / m) * m))
    if spec == "model":
        sw, sh = shape or window
        rows = int(trained[1])
        return snap(rows * sw / max(sh, 1)), rows
    if "/" in spec:
        share = gi_share(spec)
        if not (math.isfinite(share) and MIN_GI_SHARE <= share <= 1.0):
            raise DiviewerError(f"GI resolution '{spec}' is not a fraction of the window from 1/16 to 1 like 1/4",
                                field="--gi-res")
        return tuple(snap(s * share) for s in window)
    from diviewer.frames import parse_resolution

    try:
        w, h = parse_resolution(spec, "")
    except DiviewerError as exc:
        raise DiviewerError(f"GI resolution '{spec}': use 'model', a fraction of the window (1/2, 1/4, 1/6) "
                            f"or WxH ({exc})", field="--gi-res") from exc
    if not pads and (w % m or h % m):
        near = lambda s: f"{m}" if s < m else f"{s // m * m} or {(s // m + 1) * m}"
        raise DiviewerError(f"GI resolution {w}x{h} is not a multiple of the model's stride {m} "
                            f"(width {near(w)}, height {near(h)})", field="--gi-res")
    return w, h


def gi_sizes(model, spec: str, render_size: tuple[int, int], shape: tuple[int, int]) -> tuple[tuple, tuple]:
    """(the GI size the runtime runs ``model`` at, the size ``spec`` asks for) at the shading size ``render_size``
    of a window of ``shape``; they differ where the runtime cannot pad the asked shape to the model's stride."""
    wanted = gi_resolution(spec, render_size, model.resolution, model.multiple, pads=True, shape=shape)
    if runtime_pads(model):
        return wanted, wanted
    return gi_resolution(spec, render_size, model.resolution, model.multiple, shape=shape), wanted


def meta_lines(meta: dict) -> list[tuple[str, str]]:
    """The model card as (key, value) rows for the panel."""
    rows = []
    for key in ("scene", "K", "levels", "resolution", "multiple", "target", "precision", "epoch", "dataset_hash"):
        if key in meta:
            v = meta[key]
            rows.append((key, f"{v[:12]}..." if key.endswith("hash") and isinstance(v, str) else str(v)))
    for key, v in meta.items():
        if isinstance(v, dict) and any(w in key for w in ("val", "metric")):
            for k2, v2 in v.items():
                rows.append((f"{key}.{k2}", f"{v2:.4g}" if isinstance(v2, float) else str(v2)))
        elif key.startswith("val") and not isinstance(v, (dict, list)):
            rows.append((key, f"{v:.4g}" if isinstance(v, float) else str(v)))
    return rows
