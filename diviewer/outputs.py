"""Where commands write: output paths checked up front, strict JSON, and staged writes that leave
an earlier result intact until the whole new one is known good (temporary names, then renames)."""

from __future__ import annotations

import json
import math
import os
import tempfile
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

from diviewer.errors import DiviewerError
from diviewer.faults import ENVIRONMENT_ERRNOS, nearest_existing, disk_full, write_error  # noqa: F401 (re-exported)




def _writable_from(path: Path, option: str, folder: Path | None = None) -> None:
    """The folders that would be created for ``path`` (inside ``folder``, default ``path`` itself: a folder
    to make) can be: the nearest existing one is a writable folder."""
    anchor = nearest_existing(folder if folder is not None else path)
    if not anchor.is_dir():
        raise DiviewerError(f"{anchor} is a file, so {path} cannot be created under it", field=option)
    if not os.access(anchor, os.W_OK | os.X_OK):
        raise DiviewerError(f"folder {anchor} is not writable", field=option)


# What each command's folder holds, by the file that marks it, and the command that writes it.
FOLDER_WRITERS = {"dataset": "diviewer capture", "evalset": "diviewer evalset", "run": "diviewer train",
                  "render": "diviewer render", "build": "diviewer build"}
RUN_FILES = ("last.ckpt", "best.ckpt", "metrics.csv", "curves.png")
"""A training run's own files (diviewer train): never written by another command."""
BUILD_STATE = "build.json"
"""The file that marks a build's work folder (diviewer build's state: format ``diviewer-build``)."""
BUILD_FILES = (BUILD_STATE, "ladder.json", "evalset_eval.json", "replaced_eval.json")
"""A build's own files in its work folder; with every output its state records (`_build_outputs`) and its
models/ folder, never written by another command."""
SHIPPED_SUFFIXES = ("_ladder_curves.png", "_ladder.json", "_curves.png", "_metrics.csv")
"""Files shipped beside a model NAME.onnx as NAME<suffix> (diviewer build's ship stage, `diviewer ship model`)."""
DATASET_FILES = ("manifest.json", "frames", "thumbs")
"""A dataset's own files and folders (diviewer capture, data): everything under ``frames`` and ``thumbs``."""
OWNED_FILES = {"dataset": DATASET_FILES, "evalset": (*DATASET_FILES, "summary.json", "frames.zip"),
               "run": RUN_FILES, "build": BUILD_FILES}
"""Each folder kind's own files by name (a folder named: all it holds): the one table `owner` (and so every
writer's check) reads. An evaluation set's ``frames.zip`` is a compact set's frames (`diviewer evalset
--compact`)."""
CHECKPOINT_SUFFIXES = (".ckpt", ".pt", ".pth")
MANIFEST_BYTES = 1 << 28
"""Manifests larger than this are not parsed to tell a dataset from an evaluation set (both are protected)."""


def folder_kind(folder: str | Path) -> str | None:
    """Whose folder ``folder`` is: 'dataset', 'evalset', 'run' (training), 'render', 'build' (a build's work
    folder, by its state file), or None (nobody's)."""
    folder = Path(folder)
    manifest = folder / "manifest.json"
    try:
        if manifest.is_file():
            kind = None
            if manifest.stat().st_size < MANIFEST_BYTES:
                try:
                    data = json.loads(manifest.read_text())
                    kind = data.get("kind") if isinstance(data, dict) else None
                except (ValueError, UnicodeDecodeError):
                    pass  # a damaged manifest still marks a dataset: protected all the same
            return "evalset" if kind == "evalset" else "dataset"
        if _build_state(folder) is not None:
            return "build"
        if any((folder / name).is_file() for name in RUN_FILES[:3]):
            return "run"
        if (folder / "frame.json").is_file() and any(folder.glob("*.exr")):
            return "render"
    except OSError:
        return None
    return None


def _build_state(folder: Path) -> dict | None:
    """The build state file in ``folder`` (parsed), or None where there is none (a build.json of another format is
    not one). A state file that cannot be read or parsed still marks a build's folder (an empty record): protected
    all the same, as a damaged manifest marks a dataset."""
    state = folder / BUILD_STATE
    try:
        if not state.is_file():
            return None
        if state.stat().st_size >= MANIFEST_BYTES:
            return {}
        data = json.loads(state.read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return {}
    return data if isinstance(data, dict) and data.get("format") == "diviewer-build" else None


def _build_outputs(state: dict) -> set[str]:
    """Every output a build's state records, and every file its ship stages wrote (paths relative to its work
    folder, or absolute)."""
    stages = state.get("stages")
    found = set(state["shipped"]) if isinstance(state.get("shipped"), dict) else set()
    for rec in (stages.values() if isinstance(stages, dict) else ()):
        outputs = rec.get("outputs") if isinstance(rec, dict) else None
        found |= set(outputs) if isinstance(outputs, dict) else set()
    return found


_BUILDING: ContextVar[tuple[str, ...]] = ContextVar("diviewer_building", default=())
"""The work folders of the builds this process runs (`building`): their own stages write their own files."""


@contextmanager
def building(work: str | Path):
    """Within the block, ``work``'s build (holding its lock) writes its own files: they are not another command's."""
    token = _BUILDING.set((*_BUILDING.get(), os.path.abspath(work), os.path.realpath(work)))
    try:
        yield
    finally:
        _BUILDING.reset(token)


def _build_owner(path: Path) -> str | None:
    """What of a build ``path`` is, where it is one of a build's files (`BUILD_FILES`, its models/, or an output its
    state records, at any depth of its work folder): a description naming the build's folder, else None."""
    parts = path.absolute().parts
    for depth in range(1, len(parts)):
        folder = Path(*parts[:-depth])
        state = _build_state(folder)
        if state is None or str(folder) in _BUILDING.get() or os.path.realpath(folder) in _BUILDING.get():
            continue
        inside = parts[len(parts) - depth:]
        outputs = _build_outputs(state)
        recorded = "/".join(inside) in outputs or str(path.absolute()) in outputs
        if recorded or (depth == 1 and inside[0] in BUILD_FILES) or (depth == 2 and inside[0] == "models"):
            return f"a file of the build {_shown(folder, path)} ({FOLDER_WRITERS['build']} wrote it)"
    return None


def _is_model_card(path: Path) -> bool:
    if path.with_suffix(".onnx").is_file():
        return True
    try:
        if path.is_file() and path.stat().st_size < MANIFEST_BYTES:
            data = json.loads(path.read_text())
            return isinstance(data, dict) and {"format", "input", "output", "scene_hash"} <= data.keys()
    except (OSError, ValueError, UnicodeDecodeError):
        pass
    return False


CAMERA_PATH_FORMAT = "diviewer-camera-path"
"""The ``format`` of a camera-path file (`diviewer.scene.camera_path`): a recorded flight, never written over."""


def _is_camera_path(path: Path) -> bool:
    try:
        if path.is_file() and path.stat().st_size < MANIFEST_BYTES:
            data = json.loads(path.read_text())
            return isinstance(data, dict) and data.get("format") == CAMERA_PATH_FORMAT
    except (OSError, ValueError, UnicodeDecodeError):
        pass
    return False


def owner(path: str | Path) -> tuple[str, str] | None:
    """What another command made at ``path`` (existing, or a name inside such a folder): (kind, description).

    Kinds: 'model', 'checkpoint', 'path' (a camera path), 'dataset', 'evalset', 'run', 'render', 'build' (a build's
    state, ladder record, scores and models, and what ships beside a model), 'lock'. None: nobody's file, free to
    write.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if path.name.startswith(".diviewer") and path.name.endswith(".lock"):
        return "lock", "a run's lock file"
    built = _build_owner(path)
    if built is not None:
        return "build", built
    for tail in SHIPPED_SUFFIXES:
        if path.name.endswith(tail) and len(path.name) > len(tail) and \
                path.with_name(path.name[:-len(tail)] + ".onnx").is_file():
            return "build", f"a file shipped with the model {path.with_name(path.name[:-len(tail)] + '.onnx')}"
    if suffix == ".onnx" and path.exists():
        return "model", "a model"
    if suffix == ".json" and _is_model_card(path):
        return "model", "a model card"
    if suffix in CHECKPOINT_SUFFIXES and path.exists():
        return "checkpoint", "a checkpoint"
    if suffix == ".json" and _is_camera_path(path):
        return "path", "a recorded camera path"
    parts = path.absolute().parts
    for depth in range(1, len(parts)):  # the dataset or evaluation set this lies in, at any depth
        folder = Path(*parts[:-depth])
        inside = parts[len(parts) - depth:]
        if not (folder / "manifest.json").is_file():
            continue
        kind = folder_kind(folder)
        if inside[0] in OWNED_FILES[kind] and (len(inside) == 1 or inside[0] in ("frames", "thumbs")):
            what = {"manifest.json": "the manifest", "summary.json": "the summary"}.get(inside[0], "a frame")
            return kind, f"{what} of the {KIND_NAMES[kind]} {_shown(folder, path)}"
    kind = folder_kind(path.parent)
    if kind == "run" and path.name in OWNED_FILES["run"]:
        return "run", f"a file of the training run {path.parent}"
    if kind == "render" and path.exists() and suffix in (".exr", ".png", ".json"):
        return "render", f"a file of the render {path.parent}"
    return None


def check_output_dir(path: str | Path, option: str = "--out", writes: str | None = None) -> Path:
    """Refuse an output folder that is a file, cannot be created or written, or is another command's folder
    (or lies inside a dataset or an evaluation set), before any work.

    Args:
        writes: the kind of folder the command writes ('dataset', 'evalset', 'run', 'render'): one of its
            own kind is resumed or replaced; None checks only that the folder can be written.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise DiviewerError(f"{path} is a file; give a folder", field=option)
    if writes is not None:
        kind = folder_kind(path) if path.is_dir() else None
        if kind is not None and kind != writes:
            raise DiviewerError(f"{path} is {with_article(KIND_NAMES[kind])} ({FOLDER_WRITERS[kind]} wrote it), not "
                                f"{with_article(KIND_NAMES[writes])}; give another folder", field=option)
        for parent in path.absolute().parents:
            if (parent / "manifest.json").is_file():
                kind = folder_kind(parent)
                raise DiviewerError(f"{path} lies inside the {KIND_NAMES[kind]} {_shown(parent, path)}; give a "
                                    f"folder outside it",
                                    field=option)
    _writable_from(path, option)
    return path


def with_article(noun: str) -> str:
    return ("an " if noun[0] in "aeiou" else "a ") + noun


def _shown(folder: Path, path: Path) -> str:
    """``folder`` as the user would write it: relative when they gave a relative path."""
    return os.path.relpath(folder) if not path.is_absolute() else str(folder)


KIND_NAMES = {"dataset": "dataset", "evalset": "evaluation set", "run": "training run folder",
               "render": "render folder", "build": "build work folder"}


def check_output_file(path: str | Path, option: str = "--out", protect: tuple = (), suffix: str | tuple | None = None,
                      replaces: str | None = None) -> Path:
    """Refuse an output file that is a folder, lies under a file, is unwritable, has the wrong suffix, is one of
    ``protect``, or is another command's file (a model, a model card, a checkpoint, a dataset's or an
    evaluation set's manifest or frames, a training run's files): the one rule of every writer.

    Args:
        protect: files the command reads (its inputs) or writes besides this one: never overwritten.
        suffix: the extension (or extensions) the file must have (e.g. ``.onnx``), or None.
        replaces: the kind of file the command itself writes (e.g. 'model' for export): one of that kind
            may be replaced; every other kind is refused.
    """
    path = Path(path)
    if path.is_dir() or str(path).endswith(os.sep):
        raise DiviewerError(f"{path} is a folder; give a file name", field=option)
    if suffix is not None:
        allowed = (suffix,) if isinstance(suffix, str) else tuple(suffix)
        if path.suffix.lower() not in allowed:
            raise DiviewerError(f"expected a {' or '.join(allowed)} file name, got {path.name}", field=option)
    for other in protect:
        if other is not None and _same_file(path, Path(other)):
            raise DiviewerError(f"{path} is also {other}, which this command reads or writes itself; "
                                f"give another file name", field=option)
    found = owner(path)
    if found is not None and found[0] != replaces:
        raise DiviewerError(f"{path} is {found[1]}, which this command must not overwrite; give another file name",
                            field=option)
    _writable_from(path, option, folder=path.parent)  # an existing file is overwritten, not made a folder
    if path.exists() and not os.access(path, os.W_OK):
        raise DiviewerError(f"{path} is not writable", field=option)
    return path


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return a.samefile(b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def strict(obj):
    """``obj`` with every non-finite float replaced by None, so that it is strict JSON (no NaN/Infinity)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict(v) for v in obj]
    if hasattr(obj, "item") and hasattr(obj, "dtype"):  # numpy scalars
        return strict(obj.item())
    return obj


def dumps(obj, **kwargs) -> str:
    """Strict JSON text: non-finite numbers become null (``json`` would write NaN/Infinity, which is not JSON)."""
    return json.dumps(strict(obj), allow_nan=False, **kwargs)


def dumps_rows(obj, indent: int = 1) -> str:
    """Strict JSON laid out by rows: a list or object whose members are all numbers, strings, booleans or null
    stays on one line (a frame's record, a curve), larger ones open one member a line. Reads as ``json.loads``
    reads any JSON; a fifth smaller than ``indent=1`` for the evaluation JSONs, whose bulk is per-frame records."""
    return _rows(strict(obj), 0, indent)


def _rows(obj, depth: int, step: int) -> str:
    members = obj.values() if isinstance(obj, dict) else obj if isinstance(obj, list) else None
    if members is None or not any(isinstance(v, (dict, list)) for v in members):
        return json.dumps(obj, allow_nan=False)
    pad, end = " " * (depth + step), " " * depth
    if isinstance(obj, dict):
        rows = [f"{pad}{_key(k)}: {_rows(v, depth + step, step)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(rows) + "\n" + end + "}"
    return "[\n" + ",\n".join(pad + _rows(v, depth + step, step) for v in obj) + "\n" + end + "]"


def _key(k) -> str:
    """A member's name as ``json`` writes it: a number, boolean or null key becomes its JSON text, quoted."""
    return json.dumps(k if isinstance(k, str) else json.dumps(k))


def write_json(path: str | Path, obj) -> None:
    """Write strict JSON laid out by rows (``dumps_rows``) atomically (temporary name, then rename)."""
    from diviewer.imageio import write_text

    write_text(path, dumps_rows(obj))


class Staging:
    """Files written under temporary names beside their final ones, renamed into place together.

    ``stage(final)`` returns the temporary path to write; ``commit`` renames them all (renames
    cannot run out of space); ``discard`` removes them, leaving whatever was there before.
    """

    def __init__(self):
        self._pending: list[tuple[Path, Path]] = []

    def __call__(self, final: str | Path) -> Path:
        final = Path(final)
        try:
            final.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=final.suffix, dir=final.parent)
        except OSError as exc:
            raise (write_error(exc, {exc.filename: final}) or exc) from None
        os.close(fd)
        self._pending.append((Path(tmp), final))
        return Path(tmp)

    def commit(self) -> None:
        mask = os.umask(0)
        os.umask(mask)
        for tmp, final in self._pending:
            os.chmod(tmp, 0o666 & ~mask)  # mkstemp makes 0600; results get ordinary permissions
            os.replace(tmp, final)
        self._pending.clear()

    def discard(self) -> None:
        for tmp, _ in self._pending:
            tmp.unlink(missing_ok=True)
        self._pending.clear()


@contextmanager
def staged():
    """A Staging committed when the block succeeds and discarded when it raises (a full disk then names
    the user's file, not the temporary one)."""
    st = Staging()
    try:
        yield st
    except BaseException as exc:
        pending = {tmp: final for tmp, final in st._pending}
        st.discard()
        fault = write_error(exc, pending) if pending else None
        if fault is not None:
            raise fault from exc
        raise
    try:
        st.commit()
    except OSError as exc:
        fault = write_error(exc, {tmp: final for tmp, final in st._pending})
        st.discard()
        if fault is not None:
            raise fault from exc
        raise


# Outputs by (command, destination), checked before any work (diviewer.outputs: the one rule of every writer).
# Folders: the kind of folder the command writes (it resumes or replaces one of its own kind, no other).
OUTPUT_DIRS = {("render", "out"): "render", ("capture", "out"): "dataset", ("train", "out"): "run",
               ("data", "out"): "dataset", ("evalset", "out"): "evalset"}
# Files: (the suffix required, the kind of file the command may replace, the companion files written beside it).
OUTPUT_FILES = {("eval", "out"): (".json", None, ()), ("bench", "json"): (".json", None, ()),
                ("bench", "plot"): (".png", None, ()), ("view", "screenshot"): (".png", None, (".json",)),
                ("view", "window_screenshot"): (".png", None, ()), ("view", "stats"): (".json", None, ()),
                ("baseline", "out"): (".onnx", "model", (".json",)), ("export", "out"): (".onnx", "model", (".json",))}
OUTPUT_DESTS = ("out", "screenshot", "window_screenshot", "stats", "json", "plot")
INPUT_DESTS = ("model", "models", "checkpoint", "data", "evalset", "calib_data", "init_from", "sources", "config")
"""Options naming what a command reads: never one of its outputs."""


def _inputs(args) -> list[Path]:
    """The paths a parsed command line reads."""
    found = []
    for dest in INPUT_DESTS:
        v = getattr(args, dest, None)
        for item in v if isinstance(v, list) else [v]:
            if item is not None and str(item).lower() not in ("auto", "none"):
                found.append(Path(item))
    return found


def check_command_outputs(command: str, args, options: dict[str, str]) -> None:
    """Every output option of ``command`` (parsed ``args``; ``options``: destination -> option string) checked
    by the one rule, before any work: folders by kind, files by suffix and owner, never one of the inputs."""
    inputs = _inputs(args)
    for dest in OUTPUT_DESTS:
        v = getattr(args, dest, None)
        if v is None or dest not in options:
            continue
        if (command, dest) in OUTPUT_DIRS:
            check_output_dir(v, options[dest], writes=OUTPUT_DIRS[command, dest])
            for source in inputs:
                if source.exists() and Path(v).exists() and source.resolve() == Path(v).resolve():
                    raise DiviewerError(f"{v} is also the input {source}; give another folder", field=options[dest])
        elif (command, dest) in OUTPUT_FILES:
            suffix, replaces, companions = OUTPUT_FILES[command, dest]
            check_output_file(v, options[dest], protect=tuple(inputs), suffix=suffix, replaces=replaces)
            for companion in companions:
                check_output_file(Path(v).with_suffix(companion), options[dest], protect=tuple(inputs),
                                  replaces=replaces)


def is_scratch(name: str) -> bool:
    """Whether ``name`` is a command's scratch file (the benchmark's converted models), not one of the user's."""
    import tempfile

    tmp, path = Path(tempfile.gettempdir()).resolve(), Path(name).resolve()
    inside = path.relative_to(tmp).parts if path.is_relative_to(tmp) else ()
    return bool(inside) and inside[0].startswith("diviewer-")
