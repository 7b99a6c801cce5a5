"""Record a `diviewer eval` of a shipped model in its card: say the full evaluation set's scores beside the compact
set's (``evalset_compact``, written when it shipped), in the card and the ONNX metadata together, the weights
untouched.

Usage: python tools/card_eval.py --eval docs/data/sponza_walk/eval_full_k8.json --model assets/models/sponza.onnx
           [--method sponza] [--key evalset_full]

``--method`` is the model's name in the eval JSON (default: the model file's stem). The card takes the scores only
if that method scored these weights: its ``checkpoint_sha256`` (`diviewer eval` records it since 2026-11-28) must be
the card's; in an older JSON without it, the card of the model file the method names must carry the card's. The
record keeps the per-split means a shipped card keeps (`ship_model.SCORES`), each split's frame count and the
evaluation set it was scored on.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from diviewer.build.pipeline import write_model_card  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.runtime import read_metadata  # noqa: E402
from ship_model import split_scores  # noqa: E402


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


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--eval", type=Path, required=True, help="diviewer eval JSON that scored the model")
    ap.add_argument("--model", type=Path, required=True, help="the shipped model (its card beside it)")
    ap.add_argument("--method", default=None, help="the model's name in the JSON (default: the file's stem)")
    ap.add_argument("--key", default="evalset_full", help="the card's field for the record (default evalset_full)")
    a = ap.parse_args(argv)
    card = record_eval(a.model, a.eval, a.key, a.method)
    print(f"{a.model}: {a.key} recorded from {a.eval} ({', '.join(card[a.key]['this_model'])})")
    return card


if __name__ == "__main__":
    try:
        main()
    except DiviewerError as exc:
        sys.exit(f"card_eval: {exc}")
