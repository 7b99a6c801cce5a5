"""Where a derived dataset came from (its manifest's ``lineage``), and the sources a derivation refuses.

`diviewer data refine`, `area-direct` and `filter-truth` each write a new dataset from a source. Its manifest's
``lineage`` lists the steps from the capture, oldest first, one object each::

    {"operation": "filter-truth", "settings": {"levels": 1, ...},
     "source": {"path": ".../data_256spp", "hash": "<the source's Dataset.hash>",
                "manifest_sha256": "<sha256 of the source's manifest.json>", "kind": "capture"}}

A derived dataset's lineage is its source's and one step more, so a chain (refine, then area-direct, then
filter-truth) keeps every step. A manifest without ``lineage`` (a capture, or a dataset derived before the
record was written) reads as the steps its records say (``refined``, ``direct_area``, ``truth_filter``, each
marked ``"reconstructed": true``: those records keep no order between the operations).

Before any work a derivation verifies its source as `diviewer data check` does (`Dataset.check`, checksums
included): a corrupt frame is refused with its file and what is wrong, an absent one unless ``partial``. It
refuses an evaluation set (its frames are what `diviewer eval` scores against; a derived copy would keep the
set's name while its truth or inputs changed), and a source whose lineage holds a step the operation cannot
carry (`CARRIES`: refine's weighted mean needs a truth that is a plain mean of samples, so never a filtered
one). `diviewer eval` refuses an evaluation set with any step in its lineage (`refuse_derived_evalset`).
"""

from __future__ import annotations

from pathlib import Path

from diviewer.data.dataset import ABSENT, Dataset, sha256_file
from diviewer.data.evalset_format import is_evalset
from diviewer.errors import DiviewerError

OPERATIONS = {"refine": "refined", "area-direct": "direct_area", "filter-truth": "truth_filter"}
"""Each derivation and the manifest record (part of the dataset's identity) it writes."""
CHANGES = {"refine": "its truth mixed with more samples (`diviewer data refine`)",
           "area-direct": "its GL direct light rendered again over each pixel's area (`diviewer data area-direct`)",
           "filter-truth": "its truth's indirect light filtered (`diviewer data filter-truth`)"}
"""What each step changed, in words."""
CARRIES = {"refine": ("refine", "area-direct"), "area-direct": ("refine", "filter-truth"),
           "filter-truth": ("refine", "area-direct")}
"""The steps a source's lineage may hold for each derivation: refine averages new samples into a truth that must be a
plain mean of samples (a filtered one is not); area-direct renders the capture's pixel-centre light once; the truth is
filtered once. A step this table does not name (another diviewer's) is refused."""
KIND_CAPTURE = "capture"
"""A source's kind where its manifest names none."""


def lineage(manifest: dict, path: Path | None = None) -> list[dict]:
    """The steps that made a dataset, oldest first: its ``lineage``, or the steps its records say (an older
    manifest); [] for a capture or an evaluation set as rendered. A malformed ``lineage`` is refused by name."""
    if "lineage" in manifest:
        steps = manifest["lineage"]
        if not (isinstance(steps, list) and all(isinstance(s, dict) and isinstance(s.get("operation"), str)
                                                for s in steps)):
            raise DiviewerError("expected a list of {operation, source, settings} steps, got "
                                f"{repr(steps)[:80]}", path=path, field="lineage")
        return steps
    steps = []
    chain, r = [], manifest.get("refined")
    while isinstance(r, dict):
        chain.append(r)
        r = r.get("before")
    chain.reverse()  # the first refinement first
    for k, r in enumerate(chain):
        to = chain[k + 1].get("from_spp") if k + 1 < len(chain) else manifest.get("spp")
        steps.append(_reconstructed("refine", r, manifest.get("refined_from") if k + 1 == len(chain) else None,
                                    {"from_spp": r.get("from_spp"), "spp": to}))
    if isinstance(a := manifest.get("direct_area"), dict) and "from_hash" in a:  # not a capture's own area light
        steps.append(_reconstructed("area-direct", a, manifest.get("direct_area_from"), {"samples": a.get("samples")}))
    if isinstance(t := manifest.get("truth_filter"), dict):
        steps.append(_reconstructed("filter-truth", t, manifest.get("truth_filter_from"),
                                    {k: v for k, v in t.items() if k not in ("from_hash", "how")}))
    return steps


def _reconstructed(operation: str, record: dict, source_path, settings: dict) -> dict:
    return {"operation": operation, "source": {"path": source_path, "hash": record.get("from_hash")},
            "settings": settings, "reconstructed": True}


def with_step(src: Dataset, manifest: dict, operation: str, settings: dict) -> dict:
    """``manifest`` (the derived dataset's, built from ``src``'s) with its ``lineage``: the source's and this step."""
    step = {"operation": operation, "settings": settings,
            "source": {"path": str(src.root), "hash": src.hash,
                       "manifest_sha256": sha256_file(src.root / "manifest.json"),
                       "kind": src.manifest.get("kind", KIND_CAPTURE)}}
    manifest["lineage"] = [*lineage(src.manifest, src.root / "manifest.json"), step]
    return manifest


def derivation_source(src_dir: Path, out: Path, operation: str) -> Dataset:
    """The source of ``operation`` (`OPERATIONS`) into ``out``, refused before any work, in one line naming the file and
    the field, where it is an evaluation set, its lineage holds a step the operation cannot carry (`CARRIES`), or it
    is the output. Its frames are verified by `verified_frames`."""
    src = Dataset(src_dir)
    where = src.root / "manifest.json"
    if "compact" in src.manifest or is_evalset(src):
        raise DiviewerError(f"an evaluation set is not a source for `diviewer data {operation}`: `diviewer eval` "
                            f"scores against its frames, and a derived copy would carry its name with "
                            f"{CHANGES[operation].split(' (')[0]}; derive from a capture (`diviewer capture`)",
                            path=where, field="kind")
    for step in lineage(src.manifest, where):
        if step["operation"] not in CARRIES[operation]:
            what = CHANGES.get(step["operation"], f"a step this diviewer does not know ('{step['operation']}')")
            came = (step.get("source") or {}).get("path")
            raise DiviewerError(f"its lineage holds {what}, which `diviewer data {operation}` cannot carry; derive "
                                f"from the dataset before that step" + (f" ({came})" if came else ""),
                                path=where, field="lineage")
    if out.exists() and src.root.resolve() == Path(out).resolve():
        raise DiviewerError(f"{src_dir} is both the source and the output", field="--out")
    return src


def problem_field(problem: str) -> str:
    """The field a frame's problem (`Dataset.check_frame`'s words) is about: what a refusal names."""
    for start, field in (("missing", "frame_list"), ("incomplete", "frame_list"), ("checksum", "sha256"),
                         ("unreadable sidecar", "sidecar"), ("sidecar is frame", "index"), ("sidecar says", "split"),
                         ("shape", "resolution"), ("dtype", "dtype"), ("non-finite", "channels")):
        if problem.startswith(start):
            return field
    return "frames"


def verified_frames(src: Dataset, operation: str, partial: bool = False, log=print) -> list[dict]:
    """The source's frames to derive, after verifying every one as `diviewer data check` does (checksums included):
    a frame that is corrupt, unreadable, of another shape or swapped is refused; an absent one (``ABSENT``) too unless
    ``partial``, where the present frames are derived and the rest named in the log."""
    problems = src.check(verify_checksum=True)
    bad = [p for p in problems if not p.problem.startswith(ABSENT)]
    if bad:
        p = bad[0]
        more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
        raise DiviewerError(f"the source's frame {p.index} is unsound: {p.problem}{more}; `diviewer data check "
                            f"{src.root}` lists them, the command that made the source renders them again; nothing "
                            f"was derived", path=src.path(p.index), field=problem_field(p.problem))
    absent = {p.index for p in problems}
    if absent and not partial:
        p = problems[0]
        raise DiviewerError(f"the source is incomplete: {len(src.frames) - len(absent)} of {len(src.frames)} frames "
                            f"present (frame {p.index}: {p.problem}); finish it with the command that made it, or "
                            f"pass --partial to derive the present frames", path=src.root / "manifest.json",
                            field="frame_list")
    if absent:
        log(f"--partial: {len(absent)} of {len(src.frames)} source frames absent and left out "
            f"({', '.join(map(str, sorted(absent)[:8]))}{', ...' if len(absent) > 8 else ''})")
    return [f for f in src.frames if f["index"] not in absent]


def refuse_derived_evalset(manifest: dict, root: Path) -> None:
    """Refuse an evaluation set with a step in its lineage (its truth or inputs changed after `diviewer evalset`
    rendered them): scores against it would carry the set's name and measure something else."""
    where = Path(root) / "manifest.json"
    steps = lineage(manifest, where)
    if steps:
        words = "; ".join(CHANGES.get(s["operation"], f"'{s['operation']}'") for s in steps)
        came = (steps[0].get("source") or {}).get("path")
        raise DiviewerError(f"this evaluation set is not as `diviewer evalset` rendered it ({words}); score on the set "
                            f"it came from" + (f" ({came})" if came else ""), path=where, field="lineage")
