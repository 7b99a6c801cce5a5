"""`diviewer ship eval`: a `diviewer eval` of a shipped model recorded in its card: say the full evaluation set's
scores beside the compact set's (``evalset_compact``, written when it shipped), in the card and the ONNX metadata
together, the weights untouched::

    diviewer ship eval --eval docs/data/sponza_walk/eval_full_k8.json --model assets/models/sponza.onnx
        [--method sponza] [--key evalset_full]

``--method`` is the model's name in the eval JSON (default: the model file's stem). The card takes the scores only
if that method scored these weights: its ``checkpoint_sha256`` (`diviewer eval` records it since 2026-11-28) must be
the card's; in an older JSON without it, the card of the model file the method names must carry the card's. The
record keeps the per-split means a shipped card keeps (`diviewer.ship.model.SCORES`), each split's frame count and the
evaluation set it was scored on.
"""

from __future__ import annotations

import json
from pathlib import Path

from diviewer.builder.shipfiles import write_model_card
from diviewer.errors import DiviewerError
from diviewer.contract.runtime import read_metadata
from diviewer.ship.model import split_scores


def scored_checkpoint(row: dict, eval_json: Path, method: str) -> str:
    """The checkpoint hash of the weights ``method`` scored: recorded in the row, or read from the model it names."""
    if row.get("checkpoint_sha256"):
        return row["checkpoint_sha256"]
    named = Path(row.get("model") or "")
    if not named.is_file():
        raise DiviewerError(f"method '{method}' records no checkpoint_sha256 and its model file '{named}' is not "
                            f"here: cannot tell which weights it scored", path=eval_json, field="checkpoint_sha256")
    return read_metadata(named).get("checkpoint_sha256") or ""


def record_eval(model: Path, eval_json: Path, key: str = "evalset_full", method: str | None = None) -> dict:
    """Add ``eval_json``'s scores of ``model`` to its card as ``key``; returns the card as written."""
    card = read_metadata(model)
    method = method or model.stem
    try:
        ev = json.loads(eval_json.read_text())
        splits = ev["splits"]
    except (OSError, ValueError, KeyError) as exc:
        raise DiviewerError(f"not a `diviewer eval` JSON: {exc}", path=eval_json, field="splits") from exc
    scores = split_scores(ev, method, eval_json)
    for name, split in splits.items():
        got = scored_checkpoint(split["methods"][method], eval_json, method)
        if got != card.get("checkpoint_sha256"):
            raise DiviewerError(f"split {name}: method '{method}' scored checkpoint {got[:16] or 'unknown'}, not "
                                f"{model}'s {str(card.get('checkpoint_sha256'))[:16]}", path=eval_json,
                                field="checkpoint_sha256")
    card[key] = {"json": str(eval_json), "evalset": ev.get("evalset"), "reference_spp": ev.get("reference_spp"),
                 "frames": {name: split.get("frames") for name, split in splits.items()}, "this_model": scores}
    write_model_card(model, model, card)
    return card
