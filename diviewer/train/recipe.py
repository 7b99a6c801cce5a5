"""Recipes: how a scene's model is made, as a TOML file (assets/recipes/NAME.toml, or any path).

A recipe has up to six tables, each the fields of one settings dataclass, spelled as its field names, each field
with a spec of what it accepts (`diviewer.train.recipe_fields`), checked with the rules between fields when the
recipe is read:

- ``[recipe]``: ``name`` (default: the file's stem), ``description``, ``scene`` (the scene it was made for);
- ``[capture]``: `diviewer.data.capture.CaptureSettings` (frames, width, height, spp, split_fractions, ...), and
  ``refine_from`` (optional, `CAPTURE_EXTRA`): capture at that many samples per pixel, then raise the truth to
  ``spp`` with `diviewer data refine` (a model can train on the capture before the refinement ends), and
  ``truth_filter`` (optional, a table: `diviewer.data.truth_filter.TruthFilter`): train on the truth with its indirect
  light filtered over each surface (`diviewer data filter-truth`);
- ``[evalset]``: `diviewer.evaluation.evalset.EvalSetSettings` (frames_per_split, spp, ladder, ...; width and height
  default to the capture's);
- ``[train]``: `diviewer.train.config.TrainConfig`, every field but ``data``, ``out`` and ``recipe``;
- ``[export]``: `diviewer.train.export.ExportSettings` (fp16, half_weights, verify_frames);
- ``[ladder]``: ``K`` (the widths `diviewer build` trains), ``tolerance_db`` (the smallest K within this
  many dB of the best K's tone-mapped PSNR on the evaluation set is shipped;
  `diviewer.bench.frontier.smallest_sufficient_k`, `diviewer.builder.pipeline.PICK_MEASURE`) and ``max_mb``
  (optional: the largest model file the pick may ship; a larger K is trained, scored and recorded, not shipped).

`diviewer train --recipe R` trains ``[train]``; `diviewer build` runs every table. A run records where its
recipe came from (`record`): name, file, sha256 and the fields the command line changed; the checkpoint's
config and the model card's ``recipe.train`` hold the resolved fields.
"""

from __future__ import annotations

import dataclasses
import hashlib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from diviewer.errors import DiviewerError
from diviewer.paths import assets_dir
from diviewer.train.recipe_fields import check_recipe_tables

DEFAULT_RECIPE = "cornell"
"""The recipe `diviewer train` uses when none is given: the best measured one (the shipped cornell model's:
transposed decoder, L1 alone, demodulated indirect target, cosine anneal), not the paper's (`paper`), which the
README's ablations put about 10 dB behind at the same budget."""

CAPTURE_EXTRA = ("refine_from", "truth_filter")
"""[capture] keys that are not CaptureSettings fields: ``refine_from`` (spp of the capture `diviewer build` renders
before refining it to ``spp``; absent: captured at ``spp``) and ``truth_filter`` (the filter `diviewer build` runs
over the truth before training; absent: trained on the truth as rendered)."""

NOT_TRAIN = ("data", "out", "recipe")
"""TrainConfig fields a recipe cannot set: where this run reads and writes, and the recipe record itself."""


def recipes_dir() -> Path:
    """The folder of shipped recipes."""
    return assets_dir() / "recipes"


def shipped_recipes() -> list[str]:
    """Names of the shipped recipes."""
    return sorted(p.stem for p in recipes_dir().glob("*.toml"))


@dataclass(frozen=True)
class Recipe:
    """A parsed and checked recipe file; each table as a dict of dataclass fields, as the file gives them."""

    name: str
    """Its name ([recipe] name, else the file's stem)."""
    path: Path
    """The file it was read from."""
    sha256: str
    """sha256 of the file's bytes: which version of the recipe a model was made with."""
    description: str = ""
    """One line: what it is and where it comes from."""
    scene: str | None = None
    """The scene the recipe was made for (a shipped name or a .toml path), if it names one."""
    capture: dict[str, Any] = field(default_factory=dict)
    """CaptureSettings fields."""
    evalset: dict[str, Any] = field(default_factory=dict)
    """EvalSetSettings fields."""
    train: dict[str, Any] = field(default_factory=dict)
    """TrainConfig fields (not data, out, recipe)."""
    export: dict[str, Any] = field(default_factory=dict)
    """ExportSettings fields."""
    ladder: tuple[int, ...] = ()
    """Widths K `diviewer build` trains (empty: the [train] K alone)."""
    tolerance_db: float = 0.5
    """The ladder rule's tolerance in dB (tone-mapped PSNR on the evaluation set's truth, as `diviewer bench`)."""
    max_mb: float | None = None
    """The largest exported model file (MB) the pick may ship (a repository's budget, a download's); None: any.
    Not in `content_sha256`: a build keys the pick's record on it (`diviewer.builder.pipeline`), and trains nothing
    again where it changes."""

    def content_sha256(self) -> str:
        """sha256 of what the recipe asks for (every table's values and the ladder's tolerance), not of its bytes:
        comments, layout and the description leave it as it is, and so do the ladder's widths (a build keys them
        on their own, `diviewer.builder.state`: another ladder resumes a build)."""
        return self._values_sha256(export=True)

    def model_sha256(self) -> str:
        """`content_sha256` without the ``[export]`` table: what the capture, the evaluation set, the training and
        the pick ask for. A build keys on it, and on the export settings apart (`diviewer.builder.state`): an edited
        ``[export]`` exports the trained Ks again and trains nothing."""
        return self._values_sha256(export=False)

    def _values_sha256(self, export: bool) -> str:
        import json

        body = {"scene": self.scene, "capture": self.capture, "evalset": self.evalset, "train": self.train,
                **({"export": self.export} if export else {}), "tolerance_db": self.tolerance_db}
        return hashlib.sha256(json.dumps(body, sort_keys=True, default=str).encode()).hexdigest()

    def ks(self) -> tuple[int, ...]:
        """The K ladder, or the recipe's own K (TrainConfig's default where it names none)."""
        if self.ladder:
            return self.ladder
        from diviewer.train.config import TrainConfig

        return (int(self.train.get("K", _defaults(TrainConfig)["K"])),)

    def record(self, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
        """What a checkpoint and a model card record of the recipe: name, file, sha256, and the fields the
        command line changed (``overrides``: field -> value)."""
        return {"name": self.name, "file": display_path(self.path), "sha256": self.sha256,
                "overrides": dict(sorted((overrides or {}).items()))}


def display_path(path: Path) -> str:
    """A shipped recipe as ``assets/recipes/NAME.toml`` (the same on every machine), any other as given."""
    try:
        return str(Path("assets") / Path(path).resolve().relative_to(assets_dir().resolve()))
    except ValueError:
        return str(path)


def resolve_recipe_path(recipe: str | Path) -> Path:
    """A shipped recipe's name (``cornell``) or a path to a .toml file."""
    p = Path(recipe)
    if p.suffix == ".toml" or len(p.parts) > 1 or p.is_file():
        if not p.is_file():
            raise DiviewerError(f"recipe file not found: {p}", field="--recipe")
        return p
    shipped = recipes_dir() / f"{recipe}.toml"
    if not shipped.is_file():
        raise DiviewerError(f"no shipped recipe named '{recipe}'; shipped recipes: {', '.join(shipped_recipes())}; "
                            f"or pass a path to a .toml file", field="--recipe")
    return shipped


def load_recipe(recipe: str | Path) -> Recipe:
    """Read and check a recipe by shipped name or path: unknown tables and keys, a value of the wrong type or out of
    range (`diviewer.train.recipe_fields`: each field's spec), and values the rules between fields or its dataclasses
    refuse, are errors naming the file and ``table.field``, before anything runs."""
    path = resolve_recipe_path(recipe)
    blob = path.read_bytes()
    try:
        data = tomllib.loads(blob.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DiviewerError(f"not valid TOML: {exc}", path=path) from exc
    checked = check_recipe_tables(data, path, not_train=NOT_TRAIN)
    head, ladder = checked.get("recipe", {}), checked.get("ladder", {})
    rec = Recipe(name=head.get("name", path.stem), path=path, sha256=hashlib.sha256(blob).hexdigest(),
                 description=head.get("description", ""), scene=head.get("scene"),
                 capture=_as_given(data.get("capture", {})), evalset=_as_given(data.get("evalset", {})),
                 train=_as_given(data.get("train", {})), export=_as_given(data.get("export", {})),
                 ladder=ladder.get("K", ()), tolerance_db=ladder.get("tolerance_db", 0.5),
                 max_mb=ladder.get("max_mb"))
    _build_settings(rec)
    return rec


def _as_given(values: dict) -> dict[str, Any]:
    """A table's values as the file gives them (TOML arrays as tuples): the recipe's hashes are of these."""
    return {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}


def _build_settings(rec: Recipe) -> None:
    """Build each table's dataclass once: the rules between fields that live in them (an fp16 export with half
    weights) refuse when the recipe is read, naming ``table.field``."""
    for table, build in (("train", lambda: train_cfg(rec, data=".", out=".")), ("capture", lambda: truth_filter(rec)),
                         ("capture", lambda: capture_settings(rec)), ("evalset", lambda: evalset_settings(rec)),
                         ("export", lambda: export_settings(rec))):
        try:
            build()
        except DiviewerError as exc:
            field = exc.field if exc.field is None or "." in exc.field else f"{table}.{exc.field.lstrip('-')}"
            text = str(exc).split(": ", 1)[-1] if exc.field else str(exc)
            raise DiviewerError(text, path=rec.path, field=field or table) from None


def train_cfg(rec: Recipe, overrides: dict[str, Any] | None = None, **fields):
    """The TrainConfig of a recipe: its [train] fields, then ``overrides``, then ``fields`` (data, out, ...)."""
    return _train_cls()(**{**rec.train, **(overrides or {}), **fields})


def capture_settings(rec: Recipe, **overrides):
    """The CaptureSettings of a recipe (split fractions as a tuple), with ``overrides``: the truth it asks for
    (``spp``), whether captured so or refined to it (`refine_from`)."""
    return _capture_cls()(**{**{k: v for k, v in rec.capture.items() if k not in CAPTURE_EXTRA}, **overrides})


def refine_from(rec: Recipe) -> int | None:
    """The spp a build captures at before refining to the recipe's ``spp`` ([capture] refine_from), or None (checked
    below ``spp`` when the recipe was read)."""
    return rec.capture.get("refine_from")


def truth_filter(rec: Recipe):
    """The `diviewer.data.truth_filter.TruthFilter` a build runs over the truth ([capture] truth_filter), or None."""
    from diviewer.data.truth_filter import TruthFilter

    table = rec.capture.get("truth_filter")
    if table is None:
        return None
    try:
        return TruthFilter.from_dict(table, "capture.truth_filter")
    except DiviewerError as exc:
        raise DiviewerError(str(exc).split(": ", 1)[-1] if exc.field else str(exc), path=rec.path,
                            field=exc.field) from None


def evalset_settings(rec: Recipe, **overrides):
    """The EvalSetSettings of a recipe; width and height default to its capture's."""
    cap = capture_settings(rec)
    return _evalset_cls()(**{"width": cap.width, "height": cap.height, **rec.evalset, **overrides})


def export_settings(rec: Recipe):
    """The ExportSettings of a recipe."""
    return _export_cls()(**rec.export)


def _defaults(cls) -> dict[str, Any]:
    return {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}


def _train_cls():
    from diviewer.train.config import TrainConfig

    return TrainConfig


def _capture_cls():
    from diviewer.data.capture import CaptureSettings

    return CaptureSettings


def _evalset_cls():
    from diviewer.evaluation.evalset import EvalSetSettings

    return EvalSetSettings


def _export_cls():
    from diviewer.train.export import ExportSettings

    return ExportSettings
