"""One record per frame of an evaluation set: what a model takes, what it gives, the truth and the tone map.

The frames are those `diviewer eval` scores, prepared the same way (its checks, its crops, its inputs): a script
that measures something eval does not report iterates these instead of writing the loop again::

    from diviewer.evaluation.perframe import iter_frames
    from diviewer.metrics import psnr

    for fr in iter_frames("assets/evalsets/cornell", model="assets/models/cornell.onnx"):
        print(fr.key, fr.index, psnr(fr.tonemapped(fr.output), fr.tonemapped(fr.truth)))
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from diviewer.errors import DiviewerError
from diviewer.evaluation.evaluate import (area_direct_of, check_frames, model_input, run_model, stored_inputs,
                                          stored_scene)
from diviewer.evaluation.frames import EvalFrames, crop_frame, split_key
from diviewer.metrics import tonemap
from diviewer.contract.runtime import NeuralGI


@dataclass(frozen=True)
class EvalFrame:
    """One frame of an evaluation set at one of its split's shapes."""

    index: int
    """The frame's index in the set (its manifest's ``frame_list``)."""
    split: str
    """Its split (``unseen_configs``, ``moved_camera``, ...)."""
    shape: tuple[int, int]
    """(width, height) it is scored at: a centred crop of the stored frame."""
    key: str
    """The split and shape as `diviewer eval`'s JSON names them (``moved_camera`` or ``window_shapes@176x128``)."""
    entry: dict
    """Its manifest entry (the configuration: camera, lights, objects)."""
    inputs: dict[str, np.ndarray]
    """The buffers the model takes, by channel (depth (H, W), the others (H, W, C)), as eval feeds them: the stored
    frame cropped, with the area direct light in place for a model of it."""
    truth: np.ndarray
    """The path-traced radiance (H, W, 3), linear."""
    exposure: float
    """The set's tone-map exposure (one per scene; `tonemapped`)."""
    output: np.ndarray | None = None
    """The model's linear radiance (H, W, 3); None when no model was given."""

    def tonemapped(self, image: np.ndarray) -> np.ndarray:
        """``image`` through the tone map of eval's tone-mapped metrics at the set's exposure (values in [0, 1))."""
        return tonemap(image, self.exposure)


def iter_frames(evalset_dir: str | Path, model: str | Path | NeuralGI | None = None, *,
                splits: list[str] | None = None, provider: str | None = None, partial: bool = False,
                log=print) -> Iterator[EvalFrame]:
    """Each frame of ``evalset_dir`` (a full or compact set) at each of its split's shapes, split by split in the
    set's order, the shapes of a frame one after another.

    Args:
        model: an ONNX model (a path, or a `NeuralGI` already open) run on each frame; None: inputs and truth only.
        splits: the splits to go through (None: every split the set holds).
        provider: onnxruntime's provider for a model given as a path.
        partial: go through the frames present of an incomplete set (as ``eval --partial``); otherwise it is refused.

    Raises:
        DiviewerError: before the first frame, for a set that cannot be scored (changed after it was rendered,
            corrupt, incomplete), a model of another scene, or a split the set does not hold; at a frame, when the
            runtime refuses the model at that shape.
    """
    ev = EvalFrames(evalset_dir)
    net = model if isinstance(model, NeuralGI) or model is None else NeuralGI(Path(model), provider=provider)
    if net is not None and net.meta["scene_hash"] != ev.manifest["scene_hash"]:
        raise DiviewerError(f"the model was made for scene '{net.meta['scene']}' (another scene file than the "
                            f"evaluation set's '{ev.manifest['scene']}')", path=net.path, field="scene_hash")
    shapes_of = ev.splits()
    unknown = sorted(set(splits or ()) - set(shapes_of))
    if unknown:
        raise DiviewerError(f"the evaluation set has no split {', '.join(unknown)}; it holds "
                            f"{', '.join(shapes_of)}", path=ev.root, field="splits")
    problems = check_frames(ev, partial, log)
    area = area_direct_of(ev, {net.direct_samples} - {1}) if net is not None else {}
    scene = stored_scene(ev, [net] if net is not None else [])  # what each frame's conditioning needs
    for split in splits or list(shapes_of):
        idx, shapes = ev.present(split, problems), shapes_of[split]
        for i in idx:
            frame = ev.load(i)
            for shape in shapes:
                f = crop_frame(frame, shape[0])
                x, y = f, None
                if net is not None:
                    x = model_input(net, f, frame, area, i, shape[0])
                    y = run_model(net, x, **stored_inputs(net, scene, ev.entry(i), x))
                yield EvalFrame(index=i, split=split, shape=(int(shape[0]), int(shape[1])),
                                key=split_key(split, shape, shapes), entry=ev.entry(i), inputs=x, truth=f["pt"],
                                exposure=ev.exposure, output=y)
