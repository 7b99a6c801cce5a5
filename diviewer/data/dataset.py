"""The dataset on disk and its reader (torch-free).

Layout of a dataset folder::

    manifest.json         what was captured and how: scene (hash and text), resolution, channels,
                          ground truth settings, seeds, library versions, every frame's split and
                          configuration
    frames/000042.npy     one frame: (H, W, C) float16 (or float32), channels as in the manifest,
                          top row first
    frames/000042.json    written after the .npy: its sha256, the Mitsuba variant, render times
    thumbs/000042.png     a few frames for people: GL direct | path traced | indirect

A frame counts as present only when both files exist and the checksum matches, so a frame whose
writing was interrupted is never read (and a resumed capture renders it again).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from diviewer import imageio
from diviewer.data.object_lists import expand_object_lists
from diviewer.contract.encoding import INPUT_CHANNELS, channel_slices
from diviewer.errors import DiviewerError

FORMAT = "diviewer-dataset"
FORMAT_VERSION = 1
CHANNELS = (*INPUT_CHANNELS, ("pt", 3), ("pt_direct", 3))
"""Stored channels: the network inputs (GL, diviewer.contract.encoding's layout) then the path-traced ground truth
(full, direct only)."""

# Manifest fields that define a dataset: a resumed capture or a shard must agree on all of them.
IDENTITY = ("format", "format_version", "scene", "scene_hash", "resolution", "channels", "dtype", "gt", "spp",
            "max_depth", "seed", "frames", "split_fractions", "render_settings")
DERIVED = ("refined", "direct_area", "truth_filter")
"""Records of a dataset derived from another (`diviewer data refine`, `area-direct`, `filter-truth`): part of its
identity."""
ABSENT = ("missing", "incomplete")
"""How `Dataset.check_frame`'s words for a frame not written yet begin (a partial run works around them); any other
problem is a frame that is there and unsound."""


def identity(manifest: dict) -> dict:
    """The fields that make a dataset what it is (``Dataset.hash``): IDENTITY, and the records of a dataset made
    by `diviewer.data.refine` (``refined``), `diviewer.data.area` (``direct_area``) or `diviewer.data.truth_filter`
    (``truth_filter``), absent from every other
    manifest, whose hash they leave as it was."""
    ident = {k: manifest.get(k) for k in IDENTITY}
    for key in DERIVED:
        if key in manifest:
            ident[key] = manifest[key]
    return ident


def frame_name(index: int) -> str:
    return f"{index:06d}"


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_manifest(root: Path) -> dict:
    path = Path(root) / "manifest.json"
    if not path.is_file():
        raise DiviewerError(f"not a dataset (no manifest.json): {root}")
    try:
        manifest = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DiviewerError(f"manifest is not valid JSON: {exc}", path=path) from exc
    if not isinstance(manifest, dict):
        raise DiviewerError(f"expected a JSON object, got {type(manifest).__name__}", path=path)
    if manifest.get("format") != FORMAT:
        raise DiviewerError(f"not a diviewer dataset manifest (format is {manifest.get('format')!r})", path=path,
                            field="format")
    version = manifest.get("format_version", 0)
    if not _is_int(version):
        raise DiviewerError(f"expected a whole number, got {version!r}", path=path, field="format_version")
    if version > FORMAT_VERSION:
        raise DiviewerError(f"dataset format {manifest['format_version']} is newer than this diviewer reads "
                            f"({FORMAT_VERSION}); upgrade diviewer", path=path, field="format_version")
    manifest = expand_object_lists(manifest, path)
    _check_manifest(manifest, path)
    return manifest


def _is_int(v, lo: int = 0) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= lo


def _check_manifest(m: dict, path: Path) -> None:
    """Refuse a manifest with missing keys or values of the wrong type, naming the field (not a traceback later)."""
    def bad(field: str, what: str):
        value = m.get(field, "<missing>")
        return DiviewerError(f"expected {what}, got {value if value == '<missing>' else repr(value)[:80]}",
                             path=path, field=field)

    for key in ("scene", "scene_hash"):
        if not isinstance(m.get(key), str):
            raise bad(key, "a string")
    res = m.get("resolution")
    if not (isinstance(res, list) and len(res) == 2 and all(_is_int(x, 1) for x in res)):
        raise bad("resolution", "[width, height] of whole numbers >= 1")
    ch = m.get("channels")
    if not (isinstance(ch, list) and ch and all(isinstance(c, list) and len(c) == 2 and isinstance(c[0], str)
                                                 and _is_int(c[1], 1) for c in ch)):
        raise bad("channels", "a list of [name, count] pairs")
    names = [c[0] for c in ch]
    if not {"depth", "normal", "albedo", "direct"} <= set(names) or len(set(names)) != len(names):
        raise bad("channels", "unique channels including depth, normal, albedo and direct")
    if m.get("dtype") not in ("float16", "float32"):
        raise bad("dtype", "float16 or float32")
    frames = m.get("frame_list")
    if not isinstance(frames, list):
        raise bad("frame_list", "a list of frames")
    seen = set()
    for k, f in enumerate(frames):
        where = f"frame_list[{k}]"
        # split: train/val/test in a capture, other names in an evaluation set (diviewer.evaluation.evalset)
        if not (isinstance(f, dict) and _is_int(f.get("index")) and isinstance(f.get("split"), str) and f["split"]):
            raise DiviewerError(f"expected {{index: whole number, split: name}}, got {repr(f)[:80]}",
                                path=path, field=where)
        if f["index"] in seen:
            raise DiviewerError(f"frame {f['index']} is listed twice", path=path, field=where)
        seen.add(f["index"])


@dataclass(frozen=True)
class FrameProblem:
    index: int
    problem: str


class Dataset:
    """A captured dataset: manifest, frame listing per split, frame loading with checks."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.manifest = read_manifest(self.root)
        self.width, self.height = self.manifest["resolution"]
        self.channels = tuple((str(n), int(c)) for n, c in self.manifest["channels"])
        self.slices = channel_slices(self.channels)
        self.num_channels = sum(c for _, c in self.channels)
        self.dtype = np.dtype(self.manifest["dtype"])
        self.frames = self.manifest["frame_list"]
        self._split_of = {f["index"]: f["split"] for f in self.frames}

    @property
    def hash(self) -> str:
        """Identity of the dataset: sha256 of its identity fields (checkpoints record it)."""
        return hashlib.sha256(json.dumps(identity(self.manifest), sort_keys=True).encode()).hexdigest()

    def path(self, index: int, suffix: str = ".npy") -> Path:
        return self.root / "frames" / (frame_name(index) + suffix)

    def entry(self, index: int) -> dict:
        """A frame's record in the manifest's frame list (index, split, seed, config, ...)."""
        if not hasattr(self, "_entries"):
            self._entries = {f["index"]: f for f in self.frames}
        return self._entries[index]

    def indices(self, split: str | None = None, present_only: bool = True) -> list[int]:
        out = [f["index"] for f in self.frames if split is None or f["split"] == split]
        if present_only:
            out = [i for i in out if self.path(i).is_file() and self.path(i, ".json").is_file()]
        return out

    def check_frame(self, index: int, verify_checksum: bool = True) -> str | None:
        """None if the frame is complete and sound, else what is wrong with it."""
        npy, meta = self.path(index), self.path(index, ".json")
        if not npy.is_file():
            return "missing"
        if not meta.is_file():
            return "incomplete (no .json sidecar: its writing was interrupted)"
        try:
            info = json.loads(meta.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            return f"unreadable sidecar: {exc}"
        if not isinstance(info, dict):
            return "unreadable sidecar: not a JSON object"
        # A sidecar records its own frame's index and split: files moved or swapped between frames
        # (which would leak a validation frame into training) no longer match their names.
        if "index" in info and info["index"] != index:
            return f"sidecar is frame {info['index']}'s, not {index}'s (files swapped or renamed)"
        if "split" in info and index in self._split_of and info["split"] != self._split_of[index]:
            return (f"sidecar says split '{info['split']}', the manifest '{self._split_of[index]}' "
                    f"(files from another frame or dataset)")
        if verify_checksum and sha256_file(npy) != info.get("sha256"):
            return "checksum mismatch (corrupted or truncated)"
        try:
            arr = np.load(npy, mmap_mode="r")
        except Exception as exc:  # numpy raises ValueError/OSError/EOFError for broken files
            return f"unreadable: {exc}"
        expected = (self.height, self.width, self.num_channels)
        if arr.shape != expected:
            return f"shape {arr.shape}, expected {expected}"
        if arr.dtype != self.dtype:
            return f"dtype {arr.dtype}, expected {self.dtype}"
        bad = ~np.isfinite(np.asarray(arr))
        if bad.any():
            names = [n for n, s in self.slices.items() if bad[..., s].any()]
            return f"non-finite values in {', '.join(names)}"
        return None

    def load(self, index: int) -> dict[str, np.ndarray]:
        """One frame as float32 arrays by channel name, plus ``pt_indirect`` (full minus direct)."""
        problem = self.check_frame(index, verify_checksum=False)
        if problem:
            raise DiviewerError(f"frame {index}: {problem}", path=self.path(index))
        arr = np.load(self.path(index)).astype(np.float32)
        out = {name: arr[..., s] for name, s in self.slices.items()}
        out["depth"] = out["depth"][..., 0]
        if "pt" in out and "pt_direct" in out:
            out["pt_indirect"] = out["pt"] - out["pt_direct"]
        return out

    def array(self, split: str, indices: list[int] | None = None) -> tuple[list[int], np.ndarray]:
        """Frames of a split stacked in RAM: (N, H, W, C) in the stored dtype, each checked.

        Args:
            indices: these frames, in this order (the trainer's subset); by default every present one.
        """
        idx = self.indices(split) if indices is None else list(indices)
        if not idx:
            raise DiviewerError(f"dataset has no '{split}' frames yet", path=self.root)
        out = np.empty((len(idx), self.height, self.width, self.num_channels), self.dtype)
        for k, i in enumerate(idx):
            problem = self.check_frame(i, verify_checksum=False)
            if problem:
                raise DiviewerError(f"frame {i}: {problem}; run `diviewer data check {self.root}`", path=self.path(i))
            out[k] = np.load(self.path(i))
        return idx, out

    def check(self, verify_checksum: bool = True) -> list[FrameProblem]:
        """Every frame the manifest lists: present, readable, right shape and dtype, finite, checksum."""
        problems = []
        for f in self.frames:
            p = self.check_frame(f["index"], verify_checksum)
            if p:
                problems.append(FrameProblem(f["index"], p))
        return problems


def write_frame(ds: Dataset, index: int, arr: np.ndarray, info: dict) -> None:
    """Write one frame atomically: the array, then its sidecar (with the checksum) marking it complete."""
    write_checked(ds.path(index), arr, info)


def write_checked(path: Path, arr: np.ndarray, info: dict) -> None:
    """An array at ``path`` (.npy) atomically, then its sidecar beside it (.json, ``info`` with the array's checksum)
    marking it complete: a frame of a dataset, or one frame's extra samples rendered elsewhere."""
    with imageio.atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, arr)
            f.flush()
            os.fsync(f.fileno())
    info = {**info, "sha256": sha256_file(path)}
    try:
        imageio.write_text(path.with_suffix(".json"), json.dumps(info, indent=1))
    except BaseException:
        path.unlink(missing_ok=True)  # no array without its sidecar: the frame is absent, not half there
        raise
