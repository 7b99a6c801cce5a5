"""An evaluation set's frames for scoring, from a full set (diviewer.evaluation.evalset) or a compact one, checked first.

The compact set is what the repository ships (``assets/evalsets/<scene>/``, the default of ``eval`` and
``bench``): a few frames of every split of a full set, written by ``diviewer evalset --compact`` (``compact_choice``:
spread over the split's meshes, so a split of several unseen objects keeps each of them):

- ``manifest.json``: the full set's manifest fields (scene, hash, splits, left-out splits, the scene's
  tone-map exposure, ladder sample counts) with its frame list cut to the chosen frames; each frame records
  its stored width (the split's widest shape: the square splits are stored cropped to the model's width),
  the sha256 of its decoded array and, for the path-tracer ladder, its scores (below); each distinct frame
  object list is stored once (``diviewer.data.object_lists``: Sponza's 170 static objects, not 15 copies);
- ``frames.zip``: per frame and channel, the float16 array split into its high and low bytes (the
  high bytes, sign and exponent, compress well), LZMA-compressed in a zip (``np.load`` reads it).

Stored images: the GL inputs, the >= 1024-spp truth ``pt``, the second-seed render ``pt_b`` (noise floor) and
the object mask. The ladder (1 to 256 spp) is stored as its per-frame scores, computed with
``diviewer.evaluation.evaluate.score_frame`` on the full set's float32 frames at export, per shape: its images are only
ever compared with ``pt``, and as noise they would not compress (each rung costs as much as ``pt``;
cornell's 24 frames with the ladder's images would be ~10 MB, without ~4 MB).
"""

from __future__ import annotations

import hashlib
import io
import zipfile
from pathlib import Path

import numpy as np

from diviewer.data.dataset import ABSENT, FrameProblem, read_manifest  # noqa: F401 (ABSENT: eval's, re-exported)
from diviewer.data.object_lists import share_object_lists
from diviewer.errors import DiviewerError

COMPACT_FILE = "frames.zip"
COMPACT_DTYPE = np.float16
COMPACT_CHANNELS = ("depth", "normal", "albedo", "direct", "pt", "pt_b", "object")
"""Channels a compact set stores as images (those the full set has)."""
COMPACT_FRAMES = 6
"""Frames of each split a compact set keeps unless asked for another count."""
DEFAULT_EVALSETS: Path | None = None
"""Where the shipped compact sets are; None: ``assets/evalsets`` (diviewer.paths: the checkout's or the wheel's)."""


def default_evalset(scene_name: str) -> Path:
    """The compact evaluation set the repository ships for a scene (eval and bench default to it)."""
    from diviewer.paths import assets_dir

    return (DEFAULT_EVALSETS or assets_dir() / "evalsets") / scene_name


def split_key(split: str, shape, shapes) -> str:
    """The result key of a split at one shape: the split's name, or ``name_WxH`` where it has several."""
    return split if len(shapes) == 1 else f"{split}_{shape[0]}x{shape[1]}"


def crop(image: np.ndarray, width: int) -> np.ndarray:
    """The centred ``width`` columns of an (H, W, ...) image: the narrower frame at the same vertical fov."""
    w = image.shape[1]
    if width > w or (w - width) % 2:
        raise ValueError(f"cannot crop {w} columns centrally to {width}")
    o = (w - width) // 2
    return image[:, o:o + width]


def crop_frame(frame: dict[str, np.ndarray], width: int) -> dict[str, np.ndarray]:
    return {k: crop(v, width) for k, v in frame.items()}


def array_sha256(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()


class EvalFrames:
    """An evaluation set opened for scoring: its splits, shapes and frames, full or compact."""

    def __init__(self, path: str | Path):
        self.root = Path(path)
        if not (self.root / "manifest.json").is_file():
            raise DiviewerError("no evaluation set here (no manifest.json); make one with `diviewer evalset --scene "
                                "S --out DIR`, or leave --evalset out for the shipped compact set", path=self.root)
        manifest = read_manifest(self.root)
        if manifest.get("kind") != "evalset":
            raise DiviewerError("not an evaluation set (a training capture?); make one with "
                                "`diviewer evalset --scene S --out DIR`, or pass a capture with --data", path=path)
        self.compact = "compact" in manifest
        if self.compact:
            self.manifest, self.ds = manifest, None
        else:
            from diviewer.data.dataset import Dataset

            self.ds = Dataset(self.root)
            self.manifest = self.ds.manifest
        self.info = self.manifest["evalset"]
        self.frames = self.manifest["frame_list"]
        self._entry = {f["index"]: f for f in self.frames}
        self._zip = None

    # --- what the set holds ----------------------------------------------------------------------------------------

    @property
    def subset(self) -> str:
        """Which of the rendered frames the set holds, for a reader of an evaluation's JSON: ``compact`` names how
        a set is stored, and a compact set may keep every frame of the set it came from."""
        if not self.compact:
            return f"every frame rendered ({len(self.frames)})"
        c = self.manifest["compact"]
        whole = len(self.frames) == c.get("full_frames")
        return (f"{'every frame' if whole else 'a subset'}: {len(self.frames)} of the full set's "
                f"{c.get('full_frames', '?')} ({c['frames_per_split']} per split at most)")

    @property
    def exposure(self) -> float:
        return float(self.info["tonemap"]["exposure"])

    @property
    def height(self) -> int:
        return int(self.manifest["resolution"][1])

    def splits(self) -> dict[str, list[list[int]]]:
        """Split -> its shapes [[w, h], ...], in plan order (an evaluation set from before shapes: its resolution)."""
        out = {}
        for name, info in self.info["splits"].items():
            out[name] = info["shapes"] if isinstance(info, dict) else [list(self.manifest["resolution"])]
        return out

    def left_out(self) -> dict[str, str]:
        return dict(self.info.get("left_out") or {})

    def entry(self, index: int) -> dict:
        return self._entry[index]

    def stream(self, index: int) -> int | None:
        return self._entry[index].get("stream")

    def bench_frames(self) -> tuple[list[int], tuple[int, int]]:
        """The frames the bench scores and their shape: those of seed streams 0 and 1 (the scene's camera
        protocol: the frames evaluation sets had before moved_camera and window_shapes) at their square
        shape; every frame at the set's resolution for an evaluation set from before streams."""
        if not all("stream" in f for f in self.frames):
            return [f["index"] for f in self.frames], tuple(self.manifest["resolution"])
        idx = [f["index"] for f in self.frames if f["stream"] in (0, 1)]
        shapes = self.splits()
        shape = shapes[self._entry[idx[0]]["split"]][0]
        return idx, (int(shape[0]), int(shape[1]))

    def ladder_images(self) -> bool:
        """True when the ladder's frames are stored (full set); a compact set has their scores instead."""
        return not self.compact

    def ladder_rows(self, index: int, key: str) -> dict[str, dict]:
        """A compact set's stored ladder scores of one frame at one split key: method -> score_frame row."""
        return self._entry[index]["ladder_scores"][key]

    # --- checks ---------------------------------------------------------------------------------------------------

    def problems(self) -> list[FrameProblem]:
        """Every listed frame that is missing, incomplete or unsound (checksums verified, as `data check`)."""
        if not self.compact:
            return self.ds.check(verify_checksum=True)
        out = []
        for f in self.frames:
            try:
                arr = self._read(f["index"])
            except FileNotFoundError:
                out.append(FrameProblem(f["index"], "missing"))
                continue
            except Exception as exc:  # a broken zip: zipfile and numpy raise several types
                out.append(FrameProblem(f["index"], f"unreadable: {type(exc).__name__}: {exc}"))
                continue
            if array_sha256(arr) != f.get("sha256"):
                out.append(FrameProblem(f["index"], "checksum mismatch (corrupted or edited)"))
            elif not np.all(np.isfinite(arr)):
                out.append(FrameProblem(f["index"], "non-finite values"))
        return out

    def absent(self) -> list[int]:
        """The listed frames that are not there, found without reading them (a dataset's frames checked without
        their checksums, a compact set's by its zip's names); `problems` verifies the rest."""
        if not self.compact:
            return [f["index"] for f in self.frames
                    if self.ds.check_frame(f["index"], verify_checksum=False) is not None]
        try:
            with zipfile.ZipFile(self.root / COMPACT_FILE) as z:
                names = set(z.namelist())
        except (OSError, zipfile.BadZipFile):
            names = set()
        return [f["index"] for f in self.frames if not set(_zip_names(f["index"])) <= names]

    def present(self, split: str, problems: list[FrameProblem]) -> list[int]:
        bad = {p.index for p in problems}
        return [f["index"] for f in self.frames if f["split"] == split and f["index"] not in bad]

    # --- frames ---------------------------------------------------------------------------------------------------

    def load(self, index: int) -> dict[str, np.ndarray]:
        """One frame as float32 arrays by channel (depth (H, W), the others (H, W, C)) at its stored width."""
        if not self.compact:
            return self.ds.load(index)
        arr = self._read(index).astype(np.float32)
        out, c = {}, 0
        for name, n in self.manifest["channels"]:
            out[name] = arr[..., c:c + n]
            c += n
        out["depth"] = out["depth"][..., 0]
        return out

    def _read(self, index: int) -> np.ndarray:
        path = self.root / COMPACT_FILE
        if self._zip is None:
            if not path.is_file():
                raise FileNotFoundError(path)
            self._zip = zipfile.ZipFile(path)
        hi_name, lo_name = _zip_names(index)
        try:
            hi = np.load(io.BytesIO(self._zip.read(hi_name)))
            lo = np.load(io.BytesIO(self._zip.read(lo_name)))
        except KeyError:
            raise FileNotFoundError(f"{path}:{index:06d}") from None
        if hi.shape != lo.shape or hi.dtype != np.uint8 or lo.dtype != np.uint8:
            raise ValueError("high and low bytes differ in shape or type")
        return ((hi.astype(np.uint16) << 8) | lo).view(COMPACT_DTYPE)


# --- the compact set ----------------------------------------------------------------------------------------------

def _zip_names(index: int) -> tuple[str, str]:
    """A compact set's members holding frame ``index``: its float16 values' high bytes and low bytes."""
    return f"{index:06d}.hi.npy", f"{index:06d}.lo.npy"


def _bytes_npy(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.ascontiguousarray(a), allow_pickle=False)
    return buf.getvalue()


def frame_meshes(entry: dict) -> tuple[str, ...]:
    """The meshes a frame shows (its configuration's objects), sorted: what tells one scene content from another."""
    return tuple(sorted(str(o.get("mesh")) for o in entry.get("config", {}).get("objects", [])))


def compact_choice(entries: list[dict], n: int) -> list[int]:
    """The indices of ``n`` of one split's frames (``entries`` in the full set's order), in that order: the first
    frame of each distinct set of meshes in turn, then the second of each, and so on. A split whose frames all
    show the same meshes (Sponza's) keeps its first ``n``; cornell's unseen objects keep every test mesh even where
    the first frames happen to show only some of them."""
    groups: dict[tuple, list[int]] = {}
    for e in entries:
        groups.setdefault(frame_meshes(e), []).append(e["index"])
    chosen, rank = [], 0
    while len(chosen) < min(n, len(entries)):
        for members in groups.values():
            if rank < len(members) and len(chosen) < n:
                chosen.append(members[rank])
        rank += 1
    order = {e["index"]: k for k, e in enumerate(entries)}
    return sorted(chosen, key=order.__getitem__)


def _compact_request(src: "EvalFrames", full_dir: Path, out: Path, frames_per_split: int | None, log) -> int:
    """`write_compact`'s refusals, before any work, and the frames per split it takes."""
    from diviewer.data.lineage import refuse_derived_evalset

    if src.compact:
        raise DiviewerError("already a compact evaluation set; give the full set it came from", path=full_dir)
    refuse_derived_evalset(src.manifest, src.root)
    if out.exists() and out.resolve() == src.root.resolve():
        raise DiviewerError("the compact set cannot be written into the full set it is made from", path=out)
    there = [name for name in ("manifest.json", COMPACT_FILE) if (out / name).exists()]
    if there:
        raise DiviewerError(f"{out} holds {' and '.join(there)} already (a set there is never overwritten); give a new "
                            f"folder, or move that one away first", path=out, field="--out")
    have = {split: sum(f["split"] == split for f in src.frames) for split in src.splits()}
    fewest = min(have.values())
    if frames_per_split is None:
        frames_per_split = min(COMPACT_FRAMES, fewest)
        if frames_per_split < COMPACT_FRAMES:
            log(f"{frames_per_split} frames per split: the fewest a split of {full_dir} has")
    if isinstance(frames_per_split, bool) or not isinstance(frames_per_split, int) or frames_per_split < 1:
        raise DiviewerError(f"must be a whole number of at least 1, got {frames_per_split!r}",
                            field="--frames-per-split")
    if frames_per_split > fewest:
        short = ", ".join(f"{split} {n}" for split, n in have.items() if n < frames_per_split)
        raise DiviewerError(f"{frames_per_split} frames per split asked for, but the full set's splits have fewer "
                            f"({short}); ask for at most {fewest}", path=src.root / "manifest.json",
                            field="--frames-per-split")
    return frames_per_split


def write_compact(full_dir: Path, out: Path, frames_per_split: int | None = None, log=print, jobs: int = 1) -> dict:
    """Write the compact set of a full evaluation set into a new folder: ``frames_per_split`` frames of each split
    (None: `COMPACT_FRAMES`, or the fewest a split has where that is fewer), spread over its meshes
    (``compact_choice``).

    Refused before any work: a folder that holds a set (or any dataset) already, never overwritten; more frames per
    split than a split has; a full set whose frames were changed after `diviewer evalset` rendered them (a step in
    its lineage). The chosen frames must be present and sound in the full set; the rest of it need not be complete.
    ``jobs``: processes the ladder's images are scored in (``scoring.Scorer``).
    """
    from diviewer.evaluation.scoring import Scorer, ladder_methods
    from diviewer.metrics import flat_mask

    src = EvalFrames(full_dir)
    out = Path(out)
    splits = src.splits()
    frames_per_split = _compact_request(src, full_dir, out, frames_per_split, log)
    problems = {p.index: p.problem for p in src.problems()}
    names = [n for n, _ in src.manifest["channels"] if n in COMPACT_CHANNELS]
    ladder = ladder_methods(src)
    chosen, blobs = [], {}
    with Scorer(jobs) as scorer:
        for split, shapes in splits.items():
            idx = compact_choice([f for f in src.frames if f["split"] == split], frames_per_split)
            missing = [i for i in idx if i in problems]
            if missing:
                raise DiviewerError(f"split {split}: frame(s) {', '.join(map(str, missing))} of the "
                                    f"{frames_per_split} chosen are not ready ({problems[missing[0]]}); let "
                                    f"`diviewer evalset` finish them, or ask for fewer with --frames-per-split",
                                    path=full_dir)
            stored = max(w for w, _ in shapes)
            for i in idx:
                f = crop_frame(src.load(i), stored)
                arr = np.concatenate([f[n][..., None] if f[n].ndim == 2 else f[n] for n in names], axis=-1)
                arr16 = arr.astype(COMPACT_DTYPE)
                if not np.all(np.isfinite(arr16)):
                    raise DiviewerError(f"frame {i}: values beyond float16's range; the compact set cannot hold it",
                                        path=full_dir)
                u = arr16.view(np.uint16)
                hi_name, lo_name = _zip_names(i)
                blobs[hi_name] = _bytes_npy((u >> 8).astype(np.uint8))
                blobs[lo_name] = _bytes_npy((u & 0xFF).astype(np.uint8))
                scores = {}
                for shape in shapes:
                    g = crop_frame(f, shape[0])
                    mask = flat_mask(g["depth"], g["normal"], g["albedo"], g["direct"])
                    scores[split_key(split, shape, shapes)] = {  # futures, resolved below
                        m: scorer.submit(g[ch], g, src.exposure, mask) for m, ch in ladder.items()}
                entry = {k: v for k, v in src.entry(i).items()}
                entry.update(stored_width=stored, sha256=array_sha256(arr16), ladder_scores=scores)
                chosen.append(entry)
        for entry in chosen:
            entry["ladder_scores"] = {k: {m: f.result() for m, f in row.items()}
                                      for k, row in entry["ladder_scores"].items()}
    manifest = {k: v for k, v in src.manifest.items() if k not in ("frame_list",)}
    manifest.update(resolution=[max(e["stored_width"] for e in chosen), src.height], dtype="float16",
                    channels=[[n, c] for n, c in src.manifest["channels"] if n in names], frames=len(chosen),
                    frame_list=chosen)
    manifest["compact"] = {
        "from": str(src.root), "frames_per_split": frames_per_split, "file": COMPACT_FILE,
        "per_split": {split: sum(e["split"] == split for e in chosen) for split in splits},
        "choice": "per split, the first frame of each distinct set of meshes in turn (compact_choice)",
        "storage": "per frame and channel group: float16 split into high and low bytes (uint8 .npy), LZMA zip",
        "ladder": "scores per frame and shape (diviewer.evaluation.evaluate.score_frame on the full set's float32 frames); "
                  "its images are not stored", "full_frames": len(src.frames)}
    from diviewer.outputs import dumps_rows, staged

    with staged() as stage:  # both files or neither: an interrupted write leaves the folder as it was
        with zipfile.ZipFile(stage(out / COMPACT_FILE), "w", compression=zipfile.ZIP_LZMA) as z:
            for name, blob in blobs.items():
                z.writestr(name, blob)
        stage(out / "manifest.json").write_text(dumps_rows(share_object_lists(manifest)))
    size = sum(p.stat().st_size for p in out.iterdir() if p.is_file())
    log(f"compact evaluation set: {len(chosen)} frames ({frames_per_split} per split of "
        f"{', '.join(splits)}) in {out}, {size / 2**20:.2f} MB")
    return {"frames": len(chosen), "bytes": size}
