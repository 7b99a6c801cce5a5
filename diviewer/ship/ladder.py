"""`diviewer ship ladder`: a scene's K-ladder record written from two kinds of `diviewer eval` JSON, its verdict
put on the shipped card::

    diviewer ship ladder --scene cornell --test-split TEST.json --evalset EVAL.json
        --model K8=assets/models/cornell.onnx --model K16=runs/cornell/fly_eval/fly_k16_fp32.onnx
        [--tolerance 0.5] [--ship assets/models] [--note TEXT]

EVAL.json: `diviewer eval --model ...` on the evaluation set (the rule's figure: tone-mapped PSNR over every
frame of the set, >= 1024 spp); TEST.json: `diviewer eval --data CAPTURE --split test --model ...` (the capture's
test split, recorded beside it: its truth has the capture's spp, too noisy to part models near its floor; see
docs/build.md). The rule is the bench's and `diviewer build`'s (`diviewer.bench.frontier.smallest_sufficient_k`
on `diviewer.builder.scores.evalset_psnr_tm`): the smallest K within the tolerance of the best. With --ship,
SCENE_ladder.json is written there and the shipped SCENE.onnx's card (its JSON and its ONNX metadata alike,
`diviewer.builder.shipfiles.write_model_card`) gets the verdict; the chosen K must be the one shipped (this tool
records a ladder, it does not swap models).
"""

from __future__ import annotations

import json
from pathlib import Path

from diviewer import imageio
from diviewer.bench.frontier import smallest_sufficient_k
from diviewer.builder.scores import PICK_MEASURE, QUALITY, evalset_psnr_tm, evalset_scores, means_on_test_split
from diviewer.builder.shipfiles import write_model_card
from diviewer.errors import DiviewerError


def result_of(test: dict, model: Path) -> dict:
    """The `diviewer eval --data` result of ``model`` (its JSON holds one result per model)."""
    for r in test["results"]:
        if Path(r["model"]).resolve() == model.resolve():
            return r
    raise DiviewerError(f"{model} is not in the test-split results", field="--test-split")


def ladder(scene: str, test: dict, ev: dict, models: dict[int, Path], tol: float) -> dict:
    rows = []
    for k, path in sorted(models.items()):
        t = result_of(test, path)
        key = path.stem
        if any(key not in r["methods"] for r in ev["splits"].values()):
            raise DiviewerError(f"{key} is not among the evaluation set's methods", field="--evalset")
        card = json.loads(path.with_suffix(".json").read_text())
        rows.append({"K": k, "model": str(path), "steps": card.get("steps"), "bytes": path.stat().st_size,
                     "test_split": {"frames": t["frames"], "reference_spp": t.get("reference_spp"),
                                    "inference_ms": t.get("inference_ms"),
                                    **means_on_test_split(t)},
                     "evalset": evalset_scores(ev, key, (*QUALITY, "psnr_tm_object_unlit"))})
        rows[-1]["evalset_psnr_tm"] = evalset_psnr_tm(rows[-1]["evalset"])
    pick = smallest_sufficient_k({r["K"]: r["evalset_psnr_tm"] for r in rows}, tol)
    frames = sum(s["frames"] for s in rows[0]["evalset"].values())
    return {"scene": scene, "chosen_K": pick["K"], "measure": PICK_MEASURE,
            "rule": f"smallest K whose tone-mapped PSNR over the evaluation set ({frames} frames scored, "
                    f"{ev.get('reference_spp', '?')} spp) is within {tol} dB of the best K's "
                    f"({pick['best_psnr']:.2f} dB)", "rows": rows}


def record_ladder(scene: str, test_json: Path, evalset_json: Path, models: dict[int, Path], tol: float = 0.5,
                  ship: Path | None = None, note: str = "") -> dict:
    """The ladder record of ``models`` (K -> model) from the two eval JSONs; with ``ship``, SCENE_ladder.json written
    there and the shipped SCENE.onnx's card given the verdict (refused where the chosen K is not the one shipped)."""
    record = ladder(scene, json.loads(Path(test_json).read_text()), json.loads(Path(evalset_json).read_text()),
                    models, tol)
    record.update({"test_split_json": str(test_json), "evalset_json": str(evalset_json), "note": note})
    if ship is not None:
        shipped = ship / f"{scene}.onnx"
        card = json.loads(shipped.with_suffix(".json").read_text())
        if card["K"] != record["chosen_K"]:
            raise DiviewerError(f"the ladder chose K={record['chosen_K']}, the shipped model is K={card['K']}: ship "
                                f"that model first (`diviewer ship model`)", path=shipped, field="K")
        imageio.write_text(ship / f"{scene}_ladder.json", json.dumps(record, indent=1) + "\n")
        card["ladder"] = {"chosen_K": record["chosen_K"], "why": record["rule"] + (f"; {note}" if note else ""),
                          "file": f"{scene}_ladder.json"}
        write_model_card(shipped, shipped, card)
    return record
