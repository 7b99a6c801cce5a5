"""`diviewer ship model`: an exported model shipped as its scene's model (assets/models/SCENE.onnx), with what a
shipped card carries beyond `diviewer export`'s: how it was made, its compact-set scores beside the model it
replaces, the ladder's verdict and the rebuild command. `diviewer build` does the same at the end of a full build;
this is for a model trained by hand::

    diviewer ship model --model runs/cornell/fly_eval/fly_area4_k8_fp32.onnx --run runs/cornell/fly_area4_k8
        --eval docs/data/compact/EVAL.json --command "diviewer capture ..." [--command ...] --note TEXT
        --ladder-why TEXT [--ladder-file cornell_ladder.json] [--ship assets/models] [--previous-eval OLD.json]
        [--ladder-run 8 runs/cornell/fly_k8 --ladder-run 16 ...]

EVAL.json: `diviewer eval --model MODEL --model assets/models/SCENE.onnx --out EVAL.json` on the compact evaluation
set (the card records the tone-mapped region scores of both, per split: ``evalset_compact``). A model that ships
with an edited scene file (a new ``scene_hash``) cannot be scored on the old model's set, nor the old model on the
new: ``--previous-eval`` then names the old model's JSON on the same frames (the set made from the old scene
file), and ``--eval`` holds the new model's. The card and the ONNX
metadata are written together (`diviewer.builder.shipfiles.write_model_card`); the run's curves.png and metrics.csv
are copied beside them, and with ``--ladder-run`` every K's curves on one figure (SCENE_ladder_curves.png). The
shipped card's recipe must be the scene's recipe file (tests/train/test_recipe.py).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from diviewer import imageio
from diviewer.builder.shipfiles import write_ladder_curves, write_model_card
from diviewer.errors import DiviewerError

SCORES = ("psnr_tm", "ssim_tm", "psnr_tm_object", "psnr_tm_object_unlit", "ssim_tm_object_unlit", "psnr_tm_shade",
          "ssim_tm_shade", "stride_shade")
"""The per-split means a card keeps of each model (``stride_shade``: the decoder-stride pattern in the shade, as a
fraction of the irradiance; an eval JSON from before 2026-11-30 has none)."""


def split_scores(ev: dict, method: str, path: Path) -> dict:
    """``method``'s mean scores per split of an eval JSON, rounded as cards keep them."""
    out = {}
    for name, split in ev["splits"].items():
        if method not in split["methods"]:
            raise DiviewerError(f"no method '{method}' in split {name}", path=path, field="splits")
        row = split["methods"][method]
        # a region the split has none of (no moving object in the scene) is scored None: left out
        out[name] = {q: round(row[q]["mean"], 3) for q in SCORES
                     if isinstance(row.get(q), dict) and row[q]["mean"] is not None}
        if row.get("truth_margin"):  # its training truth over its error (diviewer.evaluation.truthmargin)
            out[name]["truth_margin"] = {k: v if not isinstance(v, float) else round(v, 2)
                                         for k, v in row["truth_margin"].items()}
    return out


def mean_psnr(scores: dict) -> float:
    """The mean over splits of a card's per-split tone-mapped PSNR (`split_scores`)."""
    return sum(row["psnr_tm"] for row in scores.values()) / max(len(scores), 1)


def ship(model: Path, run: Path, eval_json: Path, commands: list[str], note: str, ladder_why: str,
         ladder_file: str | None, dest: Path, previous_eval: Path | None = None,
         ladder_runs: dict[int, Path] | None = None, replace_worse: bool = False) -> dict:
    """Ship ``model`` as its scene's model in ``dest``; refused, before anything is written, where the model it
    replaces scores better on the same frames (the mean over splits of tone-mapped PSNR) unless ``replace_worse``."""
    card = json.loads(model.with_suffix(".json").read_text())
    scene = card["scene"]
    shipped = dest / f"{scene}.onnx"
    ev = json.loads(eval_json.read_text())
    before = previous_eval or eval_json
    compact = {"json": str(eval_json), "this_model": split_scores(ev, model.stem, eval_json),
               "previous_shipped": split_scores(json.loads(before.read_text()), shipped.stem, before)}
    if previous_eval is not None:
        compact["previous_json"] = str(previous_eval)
    new, old = mean_psnr(compact["this_model"]), mean_psnr(compact["previous_shipped"])
    if shipped.is_file() and new < old and not replace_worse:
        raise DiviewerError(f"{model} scores {new:.2f} dB where the model it would replace, {shipped}, scores "
                            f"{old:.2f} (tone-mapped PSNR, the mean of the splits of {eval_json}); nothing was "
                            f"replaced: --replace-worse ships it anyway", field="--model")
    card.update(commands=commands, note=note, rebuild=f"diviewer build --scene {scene}",
                ladder={"chosen_K": card["K"], "why": ladder_why, "file": ladder_file or f"{scene}_ladder.json"},
                evalset_compact=compact)
    if ladder_runs:  # every K's curves on one figure, sized from the ladder record beside the model
        card["ladder"]["curves"] = f"{scene}_ladder_curves.png"
        record = dest / card["ladder"]["file"]
        write_ladder_curves(json.loads(record.read_text()) if record.is_file() else {"rows": []}, ladder_runs,
                            dest / card["ladder"]["curves"])
    write_model_card(model, shipped, card)
    for name, suffix in (("curves.png", "_curves.png"), ("metrics.csv", "_metrics.csv")):
        if (run / name).is_file():
            with imageio.atomic_path(dest / f"{scene}{suffix}") as tmp:
                shutil.copyfile(run / name, tmp)
    return card
