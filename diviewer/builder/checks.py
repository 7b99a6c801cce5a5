"""What `diviewer build` checks before its first stage, in a dry run too: its folders, its widths, its training
device, its capture's splits, and the model file its ship stage would replace."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.train.recipe_fields import MAX_LADDER_K as MAX_K


def check_ks(ks, field: str = "--ks", path: Path | None = None) -> None:
    """Every width of the ladder a whole number from 1 to `MAX_K`."""
    bad = [k for k in ks if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= MAX_K]
    if bad:
        raise DiviewerError(f"each K must be a whole number from 1 to {MAX_K}, got {', '.join(map(str, bad))}",
                            path=path, field=field)


def check_device(device: str | None, field: str = "--device", path: Path | None = None) -> None:
    """The training device is one this machine has: auto, cpu, or cuda[:N] where torch sees that CUDA device.
    torch is imported only where CUDA is asked for."""
    device = device or "auto"
    index = device[5:] if device.startswith("cuda:") else None
    if device not in ("auto", "cpu", "cuda") and not (index is not None and index.isdigit()):
        raise DiviewerError(f"must be auto, cpu, cuda or cuda:N, got {device!r}", path=path, field=field)
    if not device.startswith("cuda"):
        return
    if importlib.util.find_spec("torch") is None:
        raise DiviewerError("training needs torch: pip install 'diviewer[train]'", path=path, field=field)
    from diviewer.train.distributed import cuda_device_count

    count = cuda_device_count()
    if count == 0:
        raise DiviewerError(f"{device} asked for, but torch sees no CUDA device here; use --device cpu or auto",
                            path=path, field=field)
    if index is not None and int(index) >= count:
        raise DiviewerError(f"{device} asked for, but torch sees {count} CUDA device(s) (cuda:0 to "
                            f"cuda:{count - 1})", path=path, field=field)


def check_folders(work: Path, ship: Path) -> None:
    """The work folder is a build's (or new) and writable; the ship folder a folder that can be written, and none
    of another command's (a dataset, a training run, another build's work folder) nor inside a dataset."""
    import os

    from diviewer.outputs import FOLDER_WRITERS, KIND_NAMES as _KIND_NAMES, check_output_dir, folder_kind
    from diviewer.outputs import with_article as _a

    check_output_dir(work, "--work", writes="build")
    check_output_dir(ship, "--ship")
    if os.path.abspath(ship) == os.path.abspath(work):
        return
    kind = folder_kind(ship) if Path(ship).is_dir() else None
    inside = next((p for p in Path(os.path.abspath(ship)).parents if (p / "manifest.json").is_file()), None)
    if kind is not None:
        raise DiviewerError(f"{ship} is {_a(_KIND_NAMES[kind])} ({FOLDER_WRITERS[kind]} wrote it); ship into a "
                            f"folder of models, or leave --ship out to ship into the work folder", field="--ship")
    if inside is not None:
        raise DiviewerError(f"{ship} lies inside the {_KIND_NAMES[folder_kind(inside)]} {inside}; give a folder "
                            f"outside it", field="--ship")


def check_splits(capture, path: Path | None = None) -> None:
    """The capture's split fractions give it train, val and test frames (as `diviewer capture` splits them), which
    the training and the ladder's test scores need."""
    import numpy as np

    fr = np.asarray(capture.split_fractions, dtype=np.float64)
    if fr.shape != (3,) or np.any(fr < 0) or fr.sum() <= 0:
        raise DiviewerError(f"split fractions must be 3 non-negative numbers, got {capture.split_fractions}",
                            path=path, field="capture.split_fractions")
    counts = np.floor(fr / fr.sum() * capture.frames).astype(int)
    counts[0] += capture.frames - counts.sum()
    if not all(counts):
        raise DiviewerError(f"{capture.frames} frames split {list(capture.split_fractions)} give "
                            f"{dict(zip(('train', 'val', 'test'), counts.tolist()))} frames: training needs train and "
                            f"val frames and the ladder test frames; capture more frames or change the fractions",
                            path=path, field="capture.split_fractions")


def shipped_file(plan) -> Path | None:
    """The model the ship stage writes (SHIP/SCENE.onnx), or None where the plan ships nowhere."""
    return None if plan.ship is None else plan.ship / f"{plan.scene_name}.onnx"


def own_ship(plan, dst: Path) -> bool:
    """Whether ``dst`` is a file this build shipped (its state's ship record, or `SHIPPED`), unchanged since."""
    from diviewer.builder.state import SHIPPED, output_key
    from diviewer.data.dataset import sha256_file

    try:
        data = json.loads((plan.work / "build.json").read_text())
        recorded = {**data.get(SHIPPED, {}), **data.get("stages", {}).get("ship", {}).get("outputs", {})}
    except (OSError, ValueError, AttributeError, TypeError):
        return False
    digest = recorded.get(output_key(dst, plan.work))
    return digest is not None and dst.is_file() and sha256_file(dst) == digest


def replaced_model(plan) -> Path | None:
    """The model file the ship stage would replace that this build did not write (None: nothing to replace)."""
    dst = shipped_file(plan)
    return dst if dst is not None and dst.exists() and not own_ship(plan, dst) else None


def check_replacement(plan, ship_given: bool, replace_worse: bool) -> str | None:
    """Refuse to replace a model file without ``--ship``; else the line saying what the ship stage replaces."""
    dst = replaced_model(plan)
    if dst is None:
        return None
    if not dst.is_file():
        raise DiviewerError(f"{dst} is not a model file; move it away or give another --ship", path=dst,
                            field="--ship")
    if not ship_given:
        raise DiviewerError(f"a model this build did not make is there; the build replaces a model only when told "
                            f"to (--ship {dst.parent}), or give another --work", path=dst, field="--ship")
    rule = ("the new model replaces it whatever the scores (--replace-worse)" if replace_worse else
            "the new model replaces it only if it scores at least as well; else the build refuses and replaces "
            "nothing")
    return (f"ship replaces {dst}: it is scored on the same evaluation set as the ladder first and kept in "
            f"{plan.work / 'replaced'}; {rule}")
