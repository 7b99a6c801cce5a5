"""diviewer.evaluation.perframe.iter_frames: the frames `diviewer eval` scores, one record each, on the shipped
compact set of cornell."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.errors import DiviewerError
from diviewer.evaluation.frames import EvalFrames, default_evalset
from diviewer.evaluation.perframe import iter_frames
from diviewer.metrics import psnr, tonemap
from diviewer.scene import load_scene
from onnx_models import base_meta, direct_times

CORNELL = default_evalset("cornell")


def quiet(*_):
    pass


def test_every_split_shape_and_frame_once_with_the_truth_and_the_tone_map():
    ev = EvalFrames(CORNELL)
    frames = list(iter_frames(CORNELL, log=quiet))
    expected = [(f["index"], tuple(s)) for split, shapes in ev.splits().items() for f in ev.frames
                if f["split"] == split for s in shapes]
    assert [(fr.index, fr.shape) for fr in frames] == expected
    for fr in frames:
        w, h = fr.shape
        assert fr.output is None and fr.exposure == ev.exposure and fr.entry == ev.entry(fr.index)
        assert fr.truth.shape == (h, w, 3) and fr.inputs["depth"].shape == (h, w)
        assert fr.inputs["direct"].shape == (h, w, 3) and fr.truth.dtype == np.float32
        assert np.array_equal(fr.tonemapped(fr.truth), tonemap(fr.truth, ev.exposure))
    assert len({fr.key for fr in frames}) > len(ev.splits())  # window_shapes: a key per shape


def _twice(tmp_path):
    return direct_times(tmp_path / "twice.onnx", 1.5, meta={**base_meta(load_scene("cornell").file_hash, "cornell"),
                                                            "multiple": 2})


def test_a_models_output_is_what_it_gives_for_the_inputs(tmp_path):
    frames = list(iter_frames(CORNELL, _twice(tmp_path), splits=["moved_camera"], log=quiet))
    assert frames and {fr.split for fr in frames} == {"moved_camera"}
    for fr in frames:
        assert np.allclose(fr.output, 1.5 * fr.inputs["direct"], rtol=1e-6, atol=1e-6)
        assert fr.output.shape == fr.truth.shape


def _one_split(tmp_path, split: str):
    """A copy of the shipped compact set that lists only ``split``'s frames (eval scores what the manifest lists)."""
    import json
    import shutil

    copy = tmp_path / "one_split"
    shutil.copytree(CORNELL, copy)
    manifest = json.loads((copy / "manifest.json").read_text())
    manifest["frame_list"] = [f for f in manifest["frame_list"] if f["split"] == split]
    manifest["frames"] = len(manifest["frame_list"])
    (copy / "manifest.json").write_text(json.dumps(manifest))
    return copy


@pytest.mark.slow
def test_the_frames_score_as_eval_scores_them(tmp_path):
    from diviewer.evaluation.evaluate import evaluate_evalset

    model = _twice(tmp_path)
    frames = list(iter_frames(CORNELL, model, splits=["moved_camera"], log=quiet))
    one = _one_split(tmp_path, "moved_camera")
    scored = evaluate_evalset([model], one, log=quiet)["splits"]["moved_camera"]["methods"]["twice"]["per_frame"]
    mine = [{"index": fr.index, "psnr_tm": psnr(fr.tonemapped(fr.output), fr.tonemapped(fr.truth))} for fr in frames]
    assert [r["index"] for r in scored] == [r["index"] for r in mine]
    assert np.allclose([r["psnr_tm"] for r in scored], [r["psnr_tm"] for r in mine], atol=1e-9)


def test_a_model_of_another_scene_and_an_unknown_split_are_refused_before_any_frame(tmp_path):
    other = direct_times(tmp_path / "other.onnx", meta=base_meta("f" * 64, "elsewhere"))
    with pytest.raises(DiviewerError, match="another scene file"):
        next(iter_frames(CORNELL, other, log=quiet))
    with pytest.raises(DiviewerError, match="no split nowhere") as e:
        next(iter_frames(CORNELL, splits=["nowhere"], log=quiet))
    assert e.value.field == "splits"
