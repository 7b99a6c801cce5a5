"""The state file of a build (WORK/build.json): which stages are finished and the outputs they left.

Written atomically after every stage, so a killed build loses at most the stage it was in (whose own work
resumes: capture and evaluation-set frames, training from last.ckpt). A finished stage is skipped only after
its outputs are checked again: a file whose sha256 differs from the one recorded, or that is gone, runs the
stage again.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

from diviewer import imageio
from diviewer.data.dataset import sha256_file
from diviewer.errors import DiviewerError

FORMAT = "diviewer-build"
VERSION = 1
LADDER_STAGES = ("evaluate", "pick", "ship")
"""The stages that read every K of the ladder: run again when the ladder changes (the others keep)."""
REPLANNABLE = ("ks", "export")
"""Plan fields a finished build may change: the K ladder (`LADDER_STAGES` run again) and the export settings (every
``export_kK`` and `LADDER_STAGES` run again); anything else is another build, but for `BEFORE_TRAINING`."""
BEFORE_TRAINING = ("recipe", "train")
"""Plan fields a build may also change while no stage from the training on has finished (a capture refined for
hours, the training settings edited before any K trains): nothing finished depends on them. The recipe's own key
changes with its [train] table; a changed capture or evaluation set is keyed apart, and stays another build."""


class BuildState:
    """The stages a build in one work folder has finished, keyed by the plan they belong to."""

    def __init__(self, path: Path, plan_key: dict[str, Any], save_upgrade: bool = False):
        """Open (or start) the state of ``path`` for ``plan_key``. ``save_upgrade``: where the file's key is of
        the same plan written by an older version, write this version's key at once (a dry run leaves it)."""
        self.path = Path(path)
        self.data: dict[str, Any] = {"format": FORMAT, "version": VERSION, "plan": plan_key, "stages": {}}
        self.ladder_change: tuple[list[int], list[int]] | None = None
        """(old Ks, new Ks) where this build's ladder differs from the one the work folder was built with."""
        self.export_change: tuple[dict, dict] | None = None
        """(old, new) export settings where the recipe's ``[export]`` differs from the one the folder was built with."""
        self.train_change: tuple[dict, dict] | None = None
        """(old, new) training settings where the recipe changed before any K was trained (`BEFORE_TRAINING`)."""
        if self.path.is_file():
            try:
                old = json.loads(self.path.read_text())
            except (json.JSONDecodeError, UnicodeDecodeError) as exc:
                raise DiviewerError(f"not a build state file ({exc}); delete it to start the build again",
                                    path=self.path) from exc
            if old.get("format") != FORMAT:
                raise DiviewerError("not a build state file; use another --work", path=self.path, field="format")
            old_plan = old.get("plan", {})
            changed = sorted(k for k in set(plan_key) | set(old_plan)
                             if not _same(k, old_plan.get(k), plan_key.get(k), self.path.parent))
            untrained = not any(_from_training(name) for name in old.get("stages", {}))
            if changed and set(changed) <= {*REPLANNABLE, *(BEFORE_TRAINING if untrained else ())}:
                # the same capture and evaluation set with more (or fewer) widths, exported otherwise, or (before any
                # K trained) trained otherwise: every finished K keeps its training, what reads the exports runs again
                if set(changed) & set(BEFORE_TRAINING):
                    self.train_change = (old_plan.get("train") or {}, plan_key.get("train") or {})
                if "ks" in changed:
                    self.ladder_change = (list(old_plan["ks"]), list(plan_key["ks"]))
                if "export" in changed:
                    self.export_change = (old_plan["export"], plan_key["export"])
                redo = lambda name: name in LADDER_STAGES or ("export" in changed and name.startswith("export_k"))
                _keep_shipped(old, old.get("stages", {}).get("ship"))
                old["stages"] = {name: rec for name, rec in old.get("stages", {}).items() if not redo(name)}
            elif changed:
                raise DiviewerError(f"this work folder holds a build of another plan (differs in {', '.join(changed)});"
                                    f" run the same command as before to resume it, or give another --work",
                                    path=self.path, field="plan")
            upgraded = old["plan"] != plan_key
            old["plan"] = plan_key  # the same plan; its key as this version writes it (the recipe's bytes may differ)
            self.data = old
            if upgraded and save_upgrade:  # this version's key lets the next run change what REPLANNABLE allows
                self.save()

    def done(self, stage: str, root: Path) -> dict[str, Any] | None:
        """The stage's record if it finished and its outputs are still what it wrote, else None."""
        rec = self.data["stages"].get(stage)
        if not rec or not rec.get("done"):
            return None
        for rel, digest in rec.get("outputs", {}).items():
            p = root / rel
            if not p.is_file() or sha256_file(p) != digest:
                return None
        return rec

    def finish(self, stage: str, root: Path, outputs: list[Path], result: dict[str, Any] | None = None,
               seconds: float | None = None) -> None:
        """Record a finished stage (its outputs' sha256, relative to ``root``) and write the file atomically."""
        self.data["stages"][stage] = {
            "done": True, "finished": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
            "seconds": None if seconds is None else round(seconds, 1),
            "outputs": {output_key(Path(p), root): sha256_file(Path(p)) for p in outputs},
            "result": result or {}}
        if stage == "ship":
            _keep_shipped(self.data, self.data["stages"][stage])
        self.save()

    def save(self) -> None:
        imageio.write_text(self.path, json.dumps(self.data, indent=1, sort_keys=True, default=str) + "\n")


SHIPPED = "shipped"
"""The state's record of every file a ship stage of this build wrote (relative key -> sha256), kept when the ship
runs again: the build's own model there is replaced without a word, anyone else's only as --ship allows."""


def _keep_shipped(data: dict[str, Any], ship: dict[str, Any] | None) -> None:
    """Add the outputs of the ship record ``ship`` to ``data``'s `SHIPPED` record."""
    if isinstance(ship, dict) and isinstance(ship.get("outputs"), dict):
        data.setdefault(SHIPPED, {}).update(ship["outputs"])


IDENTITY = {"scene": "hash", "given_evalset": "manifest_sha256"}
"""Plan fields named by identity (the member compared) and by their path from the work folder."""


def _captured_scene(root: Path) -> str | None:
    """The scene identity the work folder's capture (``root``/data) records, or None where there is none."""
    try:
        data = json.loads((root / "data" / "manifest.json").read_text())
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    return data.get("scene_hash") if isinstance(data, dict) else None


def _from_training(stage: str) -> bool:
    """Whether a stage depends on the training settings: a K's training or export, or what reads every K."""
    return stage.startswith(("train_k", "export_k")) or stage in LADDER_STAGES


def _same(field: str, old: Any, new: Any, root: Path = Path(".")) -> bool:
    """Whether a field of the plan key is the same plan. The scene, and an evaluation set made before, are the same
    when their identity is (`IDENTITY`; the ``path`` from the work folder ``root`` may differ: a project moved with
    them); a key written before named them by their absolute path, which is compared as then, or, for the scene of a
    project moved since, by the identity its capture records. The recipe is the same when what it asks for is: the
    sha256 of its values without ``[export]`` (an edited comment is the same recipe, and the export settings are
    the field ``export``). A key written before that compares the values with ``[export]``, and one older still
    the file's bytes, as each did then."""
    if field in IDENTITY and isinstance(new, dict):
        if isinstance(old, dict):
            return old.get(IDENTITY[field]) == new.get(IDENTITY[field])
        if old == os.path.normpath(os.path.join(os.path.abspath(root.resolve()), str(new.get("path")))):
            return True
        # a project moved before the scene was keyed by identity: the capture in it records the scene's
        return field == "scene" and new.get("hash") is not None and _captured_scene(root) == new["hash"]
    if field == "recipe" and isinstance(old, dict) and isinstance(new, dict):
        if "model_sha256" in old:  # the export settings are a field of their own
            return (old.get("name"), old["model_sha256"]) == (new.get("name"), new.get("model_sha256"))
        if "content_sha256" in old:
            return (old.get("name"), old["content_sha256"]) == (new.get("name"), new.get("content_sha256"))
        return (old.get("name"), old.get("sha256")) == (new.get("name"), new.get("sha256"))
    if field == "export" and old is None:
        return True  # a key written before the export settings were keyed apart: its recipe hash covered them
    return old == new


def output_key(path: Path, root: Path) -> str:
    """How a stage's output is recorded, so that `BuildState.done` finds it from ``root`` whatever the working
    folder: relative to ``root`` where it lies under it as named (through a link too: a work folder whose ``data``
    links to another build's capture), else its absolute path (``root / absolute`` is that path)."""
    named, base = Path(os.path.abspath(path)), Path(os.path.abspath(root))
    if named.is_relative_to(base):
        return str(named.relative_to(base))
    resolved = path.resolve()
    return str(resolved.relative_to(root.resolve())) if resolved.is_relative_to(root.resolve()) else str(resolved)
