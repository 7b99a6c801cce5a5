"""`diviewer eval`: models against an evaluation set (or a dataset split), beside direct light (torch-free).

Every method is scored against the path-traced image (`pt`) with the same metrics as training's
validation: MSE, PSNR (peak 1) and SSIM on linear radiance, and the same on the tone-mapped image
(diviewer.metrics.tonemap). On an evaluation set (diviewer.evaluation.evalset) also: HDR-FLIP on linear radiance,
LDR-FLIP on the tone-mapped images, the checkerboard ratio over flat regions, and the equivalent sample
count; beside the models, direct light alone, the noise floor (a second seed at the reference's spp)
and the path tracer at each ladder count, per split. One tone map for every row of a frame (the evaluation set's
exposure, or each frame's metered one or fixed stops: diviewer.evaluation.exposures), and region metrics (the
object's pixels, those of them without direct light: diviewer.evaluation.scoring) with the share of frames in which
each model scores below direct light. Every split is scored at each of its
shapes (centred crops, diviewer.evaluation.frames); a model the runtime refuses at a shape is reported as refused.
The frames' checksums are verified first; a set changed after `diviewer evalset` rendered it (a step in its
lineage: diviewer.data.lineage) is refused, and an incomplete one unless ``partial`` (which names the frames scored
and those not). On a dataset split (``--data``) the tone map is the scene's too: the shipped evaluation
set's exposure when it is of the same scene file, else the dataset's: fitted on its train split's GL direct
light as training fits it (so a model trained on the dataset is scored at its own exposure).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from diviewer.contract.conditioning import conditioning, needs_scene
from diviewer.data.area import direct_samples
from diviewer.data.dataset import Dataset
from diviewer.data.lineage import refuse_derived_evalset
from diviewer.data.scales import dataset_scene
from diviewer.errors import DiviewerError
from diviewer.evaluation.exposures import (COMPACT_LADDER, FrameExposures, data_legend, exposure_mode, legend,
                                           scene_exposure, split_legend)
from diviewer.evaluation.frames import ABSENT, EvalFrames, crop_frame, default_evalset, split_key
from diviewer.evaluation.scoring import (EQUIVALENT_BY, EVAL_KEYS, KEYS, REGIONS, Scorer, aggregate, below_direct, done,
                                equivalent, ladder_methods, per_frame, pooled_bias, score, score_frame)
from diviewer.metrics import flat_mask
from diviewer.outputs import check_output_file, write_json
from diviewer.contract.runtime import NeuralGI, pack_buffers
from diviewer.evaluation.truthmargin import FILTERED_MARGIN, MARGIN_DB, model_truth_spp, truth_margin

SSIM_MIN = 11
"""SSIM's window (diviewer.metrics): smaller frames cannot be scored."""
__all__ = ["EQUIVALENT_BY", "EVAL_KEYS", "KEYS", "aggregate", "equivalent", "evaluate", "evaluate_evalset",
           "pooled_bias", "run_model", "scene_exposure", "score", "score_frame", "stored_inputs", "stored_scene"]


def run_model(net: NeuralGI, frame: dict[str, np.ndarray], light_scale: float | None = None,
              camera=None, light=None) -> np.ndarray:
    """A model's linear radiance for one frame's buffers: the one place eval and bench call the runtime.
    ``light_scale``: the frame's (diviewer.scene.lights.light_scale), which encoding-2 models need; ``camera``: the
    frame's camera at its size (`NeuralGI.camera`), which encoding-3 models need; ``light``: its lights
    (`NeuralGI.lights`), which encoding-4 models need."""
    return net.run(pack_buffers(frame), light_scale=light_scale, camera=camera, light=light)


def stored_scene(data, nets) -> Any:
    """The scene ``data`` (a dataset or an evaluation set) was captured from, where a frame's conditioning under one
    of the models ``nets`` needs it (`diviewer.contract.conditioning.needs_scene`); else None."""
    return dataset_scene(data) if any(needs_scene(n.encoding) for n in nets) else None


def stored_inputs(net: NeuralGI, scene, entry: dict, frame: dict[str, np.ndarray]) -> dict:
    """A model's conditioning of a stored frame (`diviewer.contract.conditioning`: an evaluation set's or a dataset's
    ``entry``, its buffers ``frame`` at the size it is run at; ``scene``: `stored_scene`'s), as `run_model`'s
    keyword arguments. The evaluation set's narrower shapes are centred crops at the same vertical fov, i.e. renders
    of that size; frames cropped off-centre (``crop_xy``) have no camera of their own."""
    h, w = frame["depth"].shape[:2]
    c = conditioning(scene, entry.get("config"), (w, h), net.encoding)
    if c.camera is not None and "crop_xy" in entry:
        raise DiviewerError("frames cropped off-centre from a wider render (crop_xy) have no camera of their own "
                            "to give a model with world-space inputs", field="--data")
    return c.inputs()


def evaluate(model_path: Path, data_dir: Path, split: str = "test", provider: str | None = None,
             out: Path | None = None, log=print, exposure: str | float = "scene") -> dict:
    """Score one model and direct light on a dataset's split; ``exposure``: `eval --exposure`
    (diviewer.evaluation.exposures)."""
    mode = exposure_mode(exposure)  # refuses a bad value before any work
    if out is not None:
        check_output_file(out, "--out", protect=(model_path, Path(model_path).with_suffix(".json")))
    ds = Dataset(data_dir)
    if min(ds.width, ds.height) < SSIM_MIN:
        raise DiviewerError(f"SSIM needs frames of at least {SSIM_MIN}x{SSIM_MIN} pixels, the dataset's are "
                            f"{ds.width}x{ds.height}", path=Path(data_dir) / "manifest.json", field="resolution")
    model = NeuralGI(model_path, provider=provider)
    if model.meta["scene_hash"] != ds.manifest["scene_hash"]:
        raise DiviewerError(f"the model was trained for scene '{model.meta['scene']}' (another scene file than "
                            f"the dataset's '{ds.manifest['scene']}')", path=model_path, field="scene_hash")
    n_data = direct_samples(ds.manifest)
    if model.direct_samples != n_data:
        raise DiviewerError(f"the model takes the direct light over {model.direct_samples}x{model.direct_samples} "
                            f"samples per pixel, the dataset holds it over {n_data}x{n_data}; score it on a dataset "
                            f"made with `diviewer data area-direct --samples {model.direct_samples}`",
                            path=Path(data_dir) / "manifest.json", field="direct_area")
    idx = ds.indices(split)
    if not idx:
        raise DiviewerError(f"the dataset has no '{split}' frames", path=data_dir)
    direct = ds.slices["direct"]
    exposure, exposure_from = scene_exposure(ds.manifest["scene"], ds.manifest["scene_hash"],
                                             (np.array(np.load(ds.path(i), mmap_mode="r")[..., direct])
                                              for i in ds.indices("train")))
    exposures = FrameExposures(mode, exposure)
    rows, times, black = {"neural": [], "direct": []}, [], []
    scene = stored_scene(ds, [model])
    for i in idx:
        f = ds.load(i)
        if not np.any(f["pt"] > 0):
            black.append(i)
        t0 = time.perf_counter()
        y = run_model(model, f, **stored_inputs(model, scene, ds.entry(i), f))
        times.append((time.perf_counter() - t0) * 1e3)
        x = exposures.factor(f["pt"])  # one exposure for the frame's every row
        rows["neural"].append(score(y, f["pt"], x))
        rows["direct"].append(score(f["direct"], f["pt"], x))
    summary = {
        "model": str(model_path), "data": str(data_dir), "split": split, "frames": len(idx),
        "scene": ds.manifest["scene"], "reference_spp": ds.manifest["spp"], "provider": model.provider,
        "edge_guard": model.edge_guard, "K": model.meta["K"], "target": model.meta["target"],
        "precision": model.meta["precision"],
        "tonemap": {"exposure": exposure, "from": exposure_from}, "exposure": exposures.record(),
        "inference_ms": {"median": float(np.median(times)), "p95": float(np.percentile(times, 95))},
        "black_reference_frames": black,
        "methods": {m: {k: {"mean": float(np.mean([r[k] for r in rs])), "std": float(np.std([r[k] for r in rs]))}
                        for k in KEYS} for m, rs in rows.items()},
    }
    if (used := exposures.split_record()) is not None:
        summary["exposure"].update(used)
    log(f"{summary['scene']} {split} split, {len(idx)} frames, against path tracing at {summary['reference_spp']} spp; "
        f"tone map exposure {exposure:.4g} ({exposure_from}){data_legend(summary['exposure'])}")
    log(f"{'method':<34} {'PSNR':>7} {'SSIM':>7} {'PSNR tm':>8} {'SSIM tm':>8}")
    for m, label in (("neural", _model_label(model.meta, Path(model_path))), ("direct", "direct light only")):
        s = summary["methods"][m]
        log(f"{label:<34} {s['psnr']['mean']:7.2f} {s['ssim']['mean']:7.4f} {s['psnr_tm']['mean']:8.2f} "
            f"{s['ssim_tm']['mean']:8.4f}")
    log(f"inference {summary['inference_ms']['median']:.1f} ms median ({model.provider})")
    if black:
        # PSNR and SSIM against an all-black image measure only how dark the other image is.
        log(f"warning: {len(black)} frame(s) have an all-black reference ({', '.join(map(str, black[:8]))}"
            f"{', ...' if len(black) > 8 else ''}); their scores say little: check the dataset's lights")
    if out is not None:
        write_json(out, summary)  # strict JSON: an infinite PSNR (identical images) is null
    return summary


# --- evaluation sets ---------------------------------------------------------------------------------------------

def _model_label(meta: dict, path: Path) -> str:
    if meta.get("kind") == "linear_baseline":
        return f"linear baseline ({meta.get('parameters', '?')} params)"
    return f"neural K={meta['K']} {meta['precision']} ({path.stem})"


def check_frames(ev: EvalFrames, partial: bool, log=print) -> list:
    """The frames' problems after refusing what cannot be scored honestly: a set whose truth or inputs were changed
    after `diviewer evalset` rendered them (a step in its lineage), a corrupt frame always, an absent one unless
    ``partial``."""
    refuse_derived_evalset(ev.manifest, ev.root)
    problems = ev.problems()
    bad = [p for p in problems if not p.problem.startswith(ABSENT)]
    if bad:
        listed = "; ".join(f"frame {p.index}: {p.problem}" for p in bad[:3])
        more = "; ..." if len(bad) > 3 else ""
        raise DiviewerError(f"{len(bad)} frame(s) of the evaluation set are unsound ({listed}{more}); "
                            f"`diviewer data check {ev.root}` lists them, the `diviewer evalset` command that made the "
                            f"set renders them again", path=ev.root)
    if problems and not partial:
        raise DiviewerError(f"the evaluation set is incomplete: {len(ev.frames) - len(problems)} of {len(ev.frames)} "
                            f"frames present; finish it with the `diviewer evalset` command that started it, or pass "
                            f"--partial to score the frames present", path=ev.root)
    if problems:
        log(f"--partial: {len(problems)} of {len(ev.frames)} frames absent; the frames scored are listed per split")
    return problems


def evaluate_evalset(model_paths: list[Path], evalset_dir: Path | None = None, provider: str | None = None,
                     out: Path | None = None, log=print, partial: bool = False, jobs: int = 1,
                     exposure: str | float = "scene") -> dict:
    """Score models, direct light, the noise floor and the path-tracer ladder on an evaluation set, per split
    and shape, with region metrics; ``evalset_dir`` None: the shipped compact set of the models' scene.
    ``jobs``: processes the images are scored in (``scoring.Scorer``); the models run here. ``exposure``: `eval
    --exposure` (diviewer.evaluation.exposures): 'scene', 'metered' or stops."""
    from diviewer.console import progress_bar

    mode = exposure_mode(exposure)  # refuses a bad value before any model is read
    nets = [NeuralGI(p, provider=provider) for p in model_paths]
    if evalset_dir is None:
        if not nets:
            raise DiviewerError("give an evaluation set (--evalset DIR)", field="--evalset")
        evalset_dir = default_evalset(nets[0].meta["scene"])
        if not (evalset_dir / "manifest.json").is_file():
            raise DiviewerError(f"no evaluation set ships for scene '{nets[0].meta['scene']}'; make one with "
                                f"`diviewer evalset --scene S --out DIR` and pass --evalset DIR", path=evalset_dir)
    ev = EvalFrames(evalset_dir)
    models = {}
    for path, net in zip(model_paths, nets):
        if net.meta["scene_hash"] != ev.manifest["scene_hash"]:
            raise DiviewerError(f"the model was made for scene '{net.meta['scene']}' (another scene file than the "
                                f"evaluation set's '{ev.manifest['scene']}')", path=path, field="scene_hash")
        models[path.stem if path.stem not in models else f"{path.stem}_{len(models)}"] = net
    problems = check_frames(ev, partial, log)
    area = area_direct_of(ev, {n.direct_samples for n in nets} - {1})
    exposure = ev.exposure
    exposures = FrameExposures(mode, exposure)
    info = ev.info
    ladder_spp = [int(n) for n in info["ladder_spp"]]
    ladder = ladder_methods(ev)
    images = {"direct": "direct", "noise_floor": info["second_seed_channel"],
              **(ladder if ev.ladder_images() else {})}
    result = {"evalset": str(evalset_dir), "compact": ev.compact, "frames": ev.subset, "scene": ev.manifest["scene"],
              "reference_spp": ev.manifest["spp"], "tonemap_exposure": exposure,
              "tonemap_from": "the evaluation set's manifest (one per scene)", "ladder_spp": ladder_spp,
              "flip": {"flip_hdr": "HDR-FLIP on linear radiance (negative values clamped to 0)",
                       "flip_ldr": "LDR-FLIP on the tone-mapped images"},
              "equivalent_spp_by": EQUIVALENT_BY[0], "left_out": ev.left_out(), "not_scored": {},
              "regions_left_out": info.get("regions_left_out"), "exposure": exposures.record(), "splits": {}}
    if not ev.ladder_images() and mode != "scene":  # its stored ladder scores are at the scene's exposure
        result["ladder_left_out"] = COMPACT_LADDER
    for split, why in result["left_out"].items():
        log(f"split {split} left out: {why}")
    splits = ev.splits()
    present = {s: ev.present(s, problems) for s in splits}
    if partial:  # what was scored and what was not, never "every frame"
        result.update(partial_record(ev, problems, present))
    progress = progress_bar(sum(len(present[s]) * len(sh) for s, sh in splits.items()), "eval", "frame")
    with Scorer(jobs) as scorer:
        _score_splits(ev, splits, present, result, models, images, exposures, ladder_spp, progress, partial, area,
                      scorer, log)
    progress.close()
    for line in format_tables(result):
        log(line)
    if out is not None:
        write_json(out, result)
    return result


def partial_record(ev: EvalFrames, problems: list, present: dict[str, list[int]]) -> dict:
    """An ``eval --partial`` result's account of its frames: ``frames`` in words, the indices scored and those not
    (each with why)."""
    scored = sorted(i for idx in present.values() for i in idx)
    return {"frames": f"{'a partial set: ' if problems else ''}{len(scored)} of the set's {len(ev.frames)} frames "
                      f"scored (--partial)" + (f", {len(problems)} absent" if problems else ""),
            "frames_scored": scored,
            "frames_not_scored": [{"index": p.index, "split": ev.entry(p.index)["split"], "problem": p.problem}
                                  for p in problems]}


def _score_splits(ev, splits, present, result, models, images, exposures, ladder_spp, progress, partial, area, scorer,
                  log) -> None:
    for split, shapes in splits.items():
        idx = present[split]
        if not idx:
            result["not_scored"][split] = "no frame of this split is present"
            log(f"split {split}: no frame present, not scored")
            continue
        for shape in shapes:
            key = split_key(split, shape, shapes)
            result["splits"][key] = _score_split(ev, key, split, shape, idx, models, images, exposures, ladder_spp,
                                                 progress, partial, area, scorer)


def area_direct_of(ev: EvalFrames, samples: set[int], ctx=None, settings=None) -> dict[int, dict[int, np.ndarray]]:
    """The GL direct light over each pixel's area (`diviewer.gl.area`) of every frame of ``ev``, per sample count
    asked for: what a model trained on it takes in place of the set's stored (pixel-centre) light. The set's truth,
    tone map and regions stay as stored. ``ctx``: the caller's current GL context, rendered in (a context of its
    own would be current after this returns, its creation having replaced the caller's); None: a headless one.
    ``settings``: the renderer's (`RenderSettings`; None: the defaults, with the scene's shadow map size)."""
    if not samples:
        return {}
    from contextlib import nullcontext

    from diviewer.gl.area import AreaDirect
    from diviewer.gl.context import headless_context
    from diviewer.scene.loader import config_from_dict, load_recorded_scene

    scene = load_recorded_scene(ev.manifest, ev.root, "the evaluation set's area direct light cannot be rendered")
    w, h = (int(x) for x in ev.manifest["resolution"])
    out = {}
    with nullcontext(ctx) if ctx is not None else headless_context() as gl:
        for n in sorted(samples):
            area = AreaDirect(gl, scene, w, h, n, settings)
            try:
                out[n] = {f["index"]: area(config_from_dict(scene, f["config"])) for f in ev.frames}
            finally:
                area.release()
    return out


def model_input(net, f: dict, frame: dict, area: dict, index: int, width: int) -> dict:
    """What ``net`` takes of a stored frame: ``f`` (``frame`` cropped to ``width``) as stored, or, for a model of the
    area's direct light, ``frame`` with that light (``area``: `area_direct_of`'s) in place, cropped alike."""
    if net.direct_samples == 1:
        return f
    return crop_frame({**frame, "direct": area[net.direct_samples][index]}, width)


def _score_split(ev, key, split, shape, idx, models, images, exposures: FrameExposures, ladder_spp, progress,
                 partial, area, scorer: Scorer) -> dict:
    rows = {k: [] for k in (*models, *images)}
    # A compact set's stored ladder scores are at the scene's exposure: used only there.
    stored_ladder = not ev.ladder_images() and exposures.mode == "scene"
    regions_at = None if exposures.mode == "scene" else ev.exposure  # the same pixels in every mode
    if stored_ladder:
        rows.update({m: [] for m in ev.ladder_rows(idx[0], key)})
    times, refused, flat = {k: [] for k in models}, {}, 0
    scene = stored_scene(ev, models.values())  # what each frame's conditioning needs
    pending = []  # per frame, the futures of its rows (scored in ``scorer``'s workers while the models run)
    for i in idx:
        frame = ev.load(i)
        f = crop_frame(frame, shape[0])
        mask = flat_mask(f["depth"], f["normal"], f["albedo"], f["direct"])  # flat and no shadow edge
        flat += int(mask.sum())
        exposure = exposures.factor(f["pt"])  # the frame's one exposure, for its every row
        mine = []
        for name, net in models.items():
            if name in refused:
                continue
            x = model_input(net, f, frame, area, i, shape[0])  # the area's direct light for a model of it
            t0 = time.perf_counter()
            try:
                y = run_model(net, x, **stored_inputs(net, scene, ev.entry(i), x))
            except DiviewerError as exc:  # the runtime refuses this shape: say so, score the rest
                refused[name] = str(exc)
                continue
            times[name].append((time.perf_counter() - t0) * 1e3)
            mine.append((name, scorer.submit(y, f, exposure, mask, regions_at)))
        for name, ch in images.items():
            mine.append((name, scorer.submit(f[ch], f, exposure, mask, regions_at)))
        if stored_ladder:
            mine.extend((name, done(row)) for name, row in ev.ladder_rows(i, key).items())
        pending.append(mine)
    for mine in pending:
        for name, future in mine:
            rows[name].append(future.result())
        progress.update()
    methods = {k: aggregate(r) for k, r in rows.items() if r}
    ladder = [methods[f"pt_spp{n}"] for n in ladder_spp if f"pt_spp{n}" in methods]
    for name, m in methods.items():
        m["equivalent_spp"] = equivalent(m, ladder_spp, ladder) if ladder else dict.fromkeys(EQUIVALENT_BY)
        if name in models or name == "direct":
            m["per_frame"] = per_frame(list(idx), rows[name])
        if name in models:
            net = models[name]
            m.update(kind=net.meta.get("kind", "neural"), label=_model_label(net.meta, net.path),
                     model=str(net.path), checkpoint_sha256=net.meta.get("checkpoint_sha256"),
                     provider=net.provider, edge_guard=net.edge_guard,
                     below_direct=below_direct(rows[name], rows["direct"]),
                     inference_ms={"median": float(np.median(times[name]))})
            spp = model_truth_spp(net.meta)
            if spp and ladder and len(rows[name]) == len(idx) and rows["noise_floor"]:  # its training truth over it
                m["truth_margin"] = truth_margin(rows[name], rows["noise_floor"],
                                                 {n: rows[f"pt_spp{n}"] for n in ladder_spp}, spp)
            elif filt := ((net.meta.get("recipe") or {}).get("capture") or {}).get("truth_filter"):
                m["truth_margin"] = {"truth_filter": filt, "from": FILTERED_MARGIN}
        elif name == "direct":
            m.update(kind="direct", label="direct light only (GL)")
        elif name == "noise_floor":
            m.update(kind="noise_floor", label=f"noise floor ({ev.manifest['spp']} spp, 2nd seed)")
        else:
            m.update(kind="path_tracer", label=f"path traced {name[6:]} spp")
    out = {"split": split, "shape": list(shape), "frames": len(idx), "flat_pixels_per_frame": flat / len(idx),
           "methods": methods, "refused": {name: {"label": _model_label(models[name].meta, models[name].path),
                                                  "reason": why} for name, why in refused.items()}}
    if (used := exposures.split_record()) is not None:
        out["exposure"] = used
    if partial:
        out["frames_scored"] = list(idx)
    return out


def _cell(m: dict, key: str, fmt: str) -> str:
    v = m.get(key)
    return "-" if v is None else (format(v["mean"], fmt) if math.isfinite(v["mean"]) else "inf")


def format_tables(result: dict) -> list[str]:
    """The per-split tables for people."""
    eq = "none (no ladder: see ladder_left_out)" if "ladder_left_out" in result else \
        "the path tracer's samples that score as well"
    lines = [f"{result['scene']}: against path tracing at {result['reference_spp']} spp; {legend(result)}; eq. spp: {eq}",
             "object / unlit / lit / shade: PSNR tm / SSIM tm over those pixels; < direct: share of frames below direct "
             "light alone; every column: docs/evaluation.md (\"Reading diviewer eval's table\")"]
    if "frames_scored" in result:  # eval --partial: which frames the figures below are of
        missing = result.get("frames_not_scored") or []
        lines.append(f"frames: {result['frames']}" + (f"; not scored: {', '.join(str(r['index']) for r in missing)}"
                                                      if missing else ""))
    for split, why in result.get("left_out", {}).items():
        lines.append(f"{split}: left out ({why})")
    for split, why in result.get("not_scored", {}).items():
        lines.append(f"{split}: not scored ({why})")
    if result.get("regions_left_out"):
        lines.append(f"object regions: left out ({result['regions_left_out']})")
    for split, r in result["splits"].items():
        lines.append("")
        lines.append(f"{split} ({r['frames']} frames at {r['shape'][0]}x{r['shape'][1]})" + split_legend(r)
                     + (f"; frames scored: {', '.join(map(str, r['frames_scored']))}" if "frames_scored" in r else ""))
        lines.append(f"{'method':<34} {'PSNR':>6} {'SSIM':>6} {'PSNR tm':>7} {'SSIM tm':>7} {'FLIP-HDR':>8} "
                     f"{'FLIP-LDR':>8} {'eq. spp':>8} {'checker':>7} {'stride':>6} {'bias':>7} {'indirect':>8} "
                     f"{'object':>13} {'unlit':>13} {'lit':>13} {'shade':>13} {'< direct':>19}")
        for m in r["methods"].values():
            eq = m["equivalent_spp"][EQUIVALENT_BY[0]]
            obj = f"{_cell(m, 'psnr_tm_object', '.2f')}/{_cell(m, 'ssim_tm_object', '.3f')}"
            unlit, lit, shade = (f"{_cell(m, f'psnr_tm_{r}', '.2f')}/{_cell(m, f'ssim_tm_{r}', '.3f')}"
                                 for r in ("object_unlit", "lit", "shade"))
            below = m.get("below_direct")
            below = "/".join(f"{100 * below[k]['share']:.0f}%" if k in below else "-" for k in ("frame", *REGIONS)) \
                if below is not None else ""
            lines.append(f"{m['label']:<34} {m['psnr']['mean']:6.2f} {m['ssim']['mean']:6.4f} "
                         f"{m['psnr_tm']['mean']:7.2f} {m['ssim_tm']['mean']:7.4f} {m['flip_hdr']['mean']:8.4f} "
                         f"{m['flip_ldr']['mean']:8.4f} {eq['text'] if eq else '-':>8} {_num(m['checkerboard']):>7} "
                         f"{_stride(m.get('stride_shade')):>6} {_pct(m.get('bias')):>7} "
                         f"{_pct(m.get('bias_indirect')):>8} {obj:>13} {unlit:>13} {lit:>13} {shade:>13} {below:>19}")
        for name, why in r.get("refused", {}).items():
            lines.append(f"{why['label']:<34} refused by the runtime at this shape: {why['reason']}")
        for m in r["methods"].values():
            if (t := m.get("truth_margin")) and t.get("frames"):
                lines.append(f"{m['label']}: its {t['truth_spp']}-spp training truth stands {t['median_db']:+.1f} dB "
                             f"above its error (median frame; lowest {t['lowest_db']:+.1f}; {t['share_at_least_6db']:.0%}"
                             f" of frames >= {MARGIN_DB:g} dB; {t['unresolved']} unresolved; from {t['from']})")
            elif t and "truth_filter" in t:
                lines.append(f"{m['label']}: its training truth was filtered; {t['from']}")
    return lines


def _pct(v: float | None) -> str:
    return f"{100 * v:+.1f}%" if v is not None and math.isfinite(v) else "-"


def _stride(v: dict | None) -> str:
    return f"{100 * v['mean']:.1f}%" if v else "-"


def _num(v: float) -> str:
    return f"{v:.3g}" if math.isfinite(v) else "inf"
