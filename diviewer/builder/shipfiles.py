"""The files a build ships beside its model: the ladder's curves, and the model with its card in its metadata."""

from __future__ import annotations

from pathlib import Path

from diviewer import imageio


def write_ladder_curves(ladder: dict, runs: dict[int, Path], path: Path) -> None:
    """SCENE_ladder_curves.png: every K of the ladder record ``ladder`` on one figure, from each K's metrics.csv
    (``runs``: K -> its run folder, or the metrics.csv itself as kept beside a shipped model), labelled with the K
    and its model's size."""
    from diviewer.train.report import draw_ladder_curves, read_metrics

    size = {r["K"]: r["bytes"] for r in ladder["rows"]}
    draw_ladder_curves({f"K = {k} ({size[k] / 1e6:.1f} MB)" if k in size else f"K = {k}":
                        read_metrics(run if run.is_file() else run / "metrics.csv")
                        for k, run in sorted(runs.items())}, path)


def write_model_card(src: Path, dst: Path, card: dict) -> None:
    """Write ``src``'s model to ``dst`` with ``card`` as its metadata and beside it as dst.json, so the two agree."""
    import onnx

    from diviewer.outputs import dumps, staged
    from diviewer.contract.runtime import META_KEY

    model = onnx.load(str(src))
    onnx.helper.set_model_props(model, {META_KEY: dumps(card, sort_keys=True)})
    with staged() as stage:  # the model and its card land together, or neither does
        onnx.save(model, str(stage(dst)))
        imageio.write_text(stage(dst.with_suffix(".json")), dumps(card, indent=2, sort_keys=True))
