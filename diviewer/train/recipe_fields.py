"""What each field of a recipe accepts (`diviewer.fieldspec`), table by table, and the rules between fields.

`diviewer.train.recipe.load_recipe` checks a recipe through `check_recipe_tables` when it reads it, so a value
that would fail after hours of capture or training is refused at once, naming the file and ``table.field``
(`diviewer build --dry-run` reads the recipe first, so it refuses what the run would). The tables mirror their
settings dataclasses (``[capture]`` `diviewer.data.capture.CaptureSettings`, ``[evalset]``
`diviewer.evaluation.evalset.EvalSetSettings`, ``[train]`` `diviewer.train.config.TrainConfig` (its own `TRAIN_FIELDS`),
``[export]`` `diviewer.train.export.ExportSettings`, ``[capture] truth_filter`` `diviewer.data.truth_filter.
TruthFilter`); tests/train/test_recipe.py holds every field of those dataclasses to a spec here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from diviewer.errors import DiviewerError
from diviewer.fieldspec import MAX_SIZE, Bool, Choice, Float, Floats, Int, Ints, Maybe, Table, Text, check_fields
from diviewer.train.config import TRAIN_FIELDS

SEED = Int(0, 2**32 - 1)
"""A seed: numpy's seed streams take 32-bit seeds."""
SPP = Int(1, 1 << 20)
"""Samples per pixel."""
MAX_DEPTH = Int(2, 1024)
"""A path length limit (2: direct light only)."""
K = Int(1, 1024)
"""A generator base width."""
MAX_LADDER_K = 256
"""The widest K a build's ladder trains (a recipe's ``ladder.K``, ``build --ks``): the generator's weights, and the
memory its training allocates, grow as K squared; the paper's ladder (assets/recipes/paper.toml) stops at 128."""

TRUTH_FILTER = {
    "levels": Int(1, 5), "normal_power": Float(0.0, 1024.0), "plane": Float(1e-6, 1e3),
    "range_sigma": Float(0.0, 1e3),
}
"""`diviewer.data.truth_filter.TruthFilter`'s fields (a recipe's ``[capture] truth_filter`` and `diviewer data
filter-truth`'s options): the exponent stays where the normals' cosine to its power is a finite float."""

CAPTURE = {
    "frames": Int(1, 1_000_000), "width": Int(16, MAX_SIZE), "height": Int(16, MAX_SIZE),
    "gt": Choice(("pt", "vxgi")), "spp": SPP, "max_depth": MAX_DEPTH, "seed": SEED,
    "split_fractions": Floats(3, Float(0.0, 1.0)), "dtype": Choice(("float16", "float32")),
    "thumbs": Int(0, 1000), "vxgi_resolution": Int(16, 256, power_of_two=True), "direct_samples": Int(1, 16),
    "refine_from": SPP, "truth_filter": Table(TRUTH_FILTER),
}
"""[capture]: CaptureSettings' fields, then ``refine_from`` and ``truth_filter`` (`diviewer.train.recipe.
CAPTURE_EXTRA`)."""

EVALSET = {
    "frames_per_split": Int(1, 100_000), "width": Int(16, MAX_SIZE), "height": Int(16, MAX_SIZE),
    "window_widths": Maybe(Ints(Int(16, MAX_SIZE), distinct=True)), "spp": SPP,
    "ladder": Ints(SPP, increasing=True), "max_depth": MAX_DEPTH, "seed": SEED,
    "dtype": Choice(("float16", "float32")), "thumbs": Int(0, 1000),
}
"""[evalset]: EvalSetSettings' fields (>= 16 pixels a side: SSIM's window is 11)."""

EXPORT = {"fp16": Bool(), "half_weights": Bool(), "int8_weights": Bool(), "verify_frames": Int(1, 1000),
          "layout": Choice(("NHWC", "NCHW"))}
"""[export]: ExportSettings' fields."""

LADDER = {"K": Ints(Int(1, MAX_LADDER_K), min_len=0, max_len=16, increasing=True), "tolerance_db": Float(0.0, 100.0),
          "max_mb": Float(0.0, 1e6, lo_open=True)}
"""[ladder]: the widths `diviewer build` trains, the pick's tolerance in dB, the largest model it ships (MB)."""

HEAD = {"name": Text(200), "description": Text(), "scene": Text()}
"""[recipe]: name, description, scene."""

TABLES = {"recipe": HEAD, "capture": CAPTURE, "evalset": EVALSET, "train": TRAIN_FIELDS, "export": EXPORT,
          "ladder": LADDER}
"""Every table's fields."""


def check_recipe_tables(data: dict[str, Any], path: Path, not_train: tuple[str, ...] = ()) -> dict[str, dict]:
    """Every table of a parsed recipe checked field by field and then across fields; returns the checked tables.
    ``not_train``: [train] keys the command sets, refused with that reason."""
    out = {}
    for table, value in data.items():
        if table not in TABLES:
            raise DiviewerError(f"unknown table [{table}]; a recipe has {', '.join(f'[{t}]' for t in TABLES)}",
                                path=path, field=table)
        if not isinstance(value, dict):
            raise DiviewerError(f"must be a table [{table}], got {value!r}", path=path, field=table)
        specs = TABLES[table]
        for key in value:
            if table == "train" and key in not_train:
                raise DiviewerError(f"unknown key '{key}' (set by the command, not the recipe); [train] takes "
                                    f"{', '.join(sorted(specs))}", path=path, field=f"train.{key}")
        out[table] = check_fields(value, specs, table, path)
    import dataclasses

    from diviewer.data.capture import CaptureSettings

    cap = {**{f.name: f.default for f in dataclasses.fields(CaptureSettings)}, **out.get("capture", {})}
    _check_capture(cap, path)
    _check_evalset(out.get("evalset", {}), cap, path)
    return out


def _check_capture(cap: dict[str, Any], path: Path) -> None:
    """``cap``: the [capture] table over CaptureSettings' defaults."""
    from diviewer.data.capture import split_counts

    fr = cap["split_fractions"]
    if abs(sum(fr) - 1.0) > 1e-6:
        raise DiviewerError(f"must add up to 1 (train, val, test), got {list(fr)} (sum {sum(fr):g})", path=path,
                            field="capture.split_fractions")
    counts = split_counts(fr, cap["frames"])
    if min(counts) < 1:
        raise DiviewerError(f"give {cap['frames']} frames as {counts[0]} train, {counts[1]} val and {counts[2]} "
                            f"test: training needs train and val frames and the ladder's pick test frames; raise "
                            f"each fraction or capture.frames", path=path, field="capture.split_fractions")
    n = cap.get("refine_from")
    if n is not None and not n < cap["spp"]:
        raise DiviewerError(f"must be below capture.spp ({cap['spp']}): the capture is refined up to spp, got {n}",
                            path=path, field="capture.refine_from")


_EVALSET_FIELDS = {"--frames-per-split/--res": "frames_per_split", "--window-widths": "window_widths",
                   "--res/--window-widths": "window_widths", "--spp": "spp", "--ladder": "ladder", "--dtype": "dtype"}
"""EvalSetSettings.check names its options; in a recipe they are [evalset] fields."""


def _check_evalset(ev: dict[str, Any], cap: dict[str, Any], path: Path) -> None:
    from diviewer.evaluation.evalset import EvalSetSettings

    spp = ev.get("spp", EvalSetSettings.spp)
    if "ladder" in ev and not ev["ladder"][-1] < spp:
        raise DiviewerError(f"must be sample counts below evalset.spp ({spp}), got {list(ev['ladder'])}", path=path,
                            field="evalset.ladder")
    size = {"width": cap["width"], "height": cap["height"]}  # the capture's, as evalset_settings gives them
    try:
        EvalSetSettings(**{**size, **ev}).check()
    except DiviewerError as exc:
        name = _EVALSET_FIELDS.get(exc.field or "", "frames_per_split")
        text = str(exc).split(": ", 1)[-1] if exc.field else str(exc)
        where = "" if name in ev or name not in size else " (the capture's, as [evalset] gives none)"
        raise DiviewerError(text + where, path=path, field=f"evalset.{name}") from None
