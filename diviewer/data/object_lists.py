"""Frame configurations' object lists stored once in a manifest (torch-free).

Every frame of a manifest records its configuration: camera, lights and objects. A scene whose objects do not
move (Sponza: 170 static objects) repeats the same object list in every frame: 37 kB a frame in the shipped
compact evaluation set, 206 MB of a 3,400-frame capture's manifest. A manifest may instead hold each distinct
list once, in ``object_lists``, and a frame's ``config.objects`` names its list: ``{"list": k}``.

``share_object_lists`` writes that form (every dataset and evaluation set manifest, ``capture.open_or_create``,
and the compact set's), ``expand_object_lists`` reads it back (``diviewer.data.dataset.read_manifest`` calls
it), so every reader of a manifest sees each frame's full object list and nothing downstream knows the
difference. A manifest without ``object_lists`` is read as it is.
"""

from __future__ import annotations

import json
from pathlib import Path

from diviewer.errors import DiviewerError

FIELD = "object_lists"


def _objects(entry) -> object:
    """A frame entry's ``config.objects``, or None where the entry or its configuration is not a table."""
    config = entry.get("config") if isinstance(entry, dict) else None
    return config.get("objects") if isinstance(config, dict) else None


def share_object_lists(manifest: dict) -> dict:
    """The manifest with each distinct frame object list stored once in ``object_lists`` (in order of first use)
    and every frame's ``config.objects`` naming its list. A frame without an object list is left as it is; so is
    a manifest that already shares its lists. The input is not changed."""
    if FIELD in manifest:
        return manifest
    lists: list[list] = []
    index_of: dict[str, int] = {}
    frames = []
    for entry in manifest.get("frame_list", []):
        objects = _objects(entry)
        if not isinstance(objects, list):
            frames.append(entry)
            continue
        key = json.dumps(objects, sort_keys=True)
        if key not in index_of:
            index_of[key] = len(lists)
            lists.append(objects)
        frames.append({**entry, "config": {**entry["config"], "objects": {"list": index_of[key]}}})
    if not lists:
        return manifest
    out = {k: v for k, v in manifest.items() if k != "frame_list"}
    out[FIELD] = lists
    out["frame_list"] = frames
    return out


def expand_object_lists(manifest: dict, path: Path | None = None) -> dict:
    """The manifest with every frame's ``{"list": k}`` replaced by a copy of ``object_lists[k]`` and
    ``object_lists`` dropped; a manifest without ``object_lists`` is returned as it is. A malformed table or
    reference is refused naming the field."""
    if FIELD not in manifest:
        return manifest
    lists = manifest[FIELD]
    if not (isinstance(lists, list) and all(isinstance(x, list) for x in lists)):
        raise DiviewerError(f"expected a list of object lists, got {repr(lists)[:80]}", path=path, field=FIELD)
    frames = manifest.get("frame_list")
    if not isinstance(frames, list):
        return manifest  # read_manifest's own check names frame_list
    # Each frame gets its own copy (a reader may edit one frame's list), parsed from the list's JSON: 2.4x faster
    # than copy.deepcopy. A 3,400-frame Sponza manifest reads in 3.6 s so, 4.7-5.5 s unshared (docs/architecture.md).
    texts = [json.dumps(x) for x in lists]
    out_frames = []
    for k, entry in enumerate(frames):
        ref = _objects(entry)
        if isinstance(ref, dict):
            j = ref.get("list")
            if not (isinstance(j, int) and not isinstance(j, bool) and 0 <= j < len(lists)) or len(ref) != 1:
                raise DiviewerError(f"expected {{\"list\": 0..{len(lists) - 1}}} (an index into {FIELD}), got "
                                    f"{repr(ref)[:80]}", path=path, field=f"frame_list[{k}].config.objects")
            entry = {**entry, "config": {**entry["config"], "objects": json.loads(texts[j])}}
        out_frames.append(entry)
    out = {k: v for k, v in manifest.items() if k not in (FIELD, "frame_list")}
    out["frame_list"] = out_frames
    return out
