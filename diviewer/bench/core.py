"""`diviewer bench`: settings, and the run that turns measurements (diviewer.bench.runner) into rows."""

from __future__ import annotations

import dataclasses
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path


from diviewer.errors import DiviewerError


@dataclass(frozen=True)
class BenchSettings:
    """What the benchmark measures; recorded in its JSON."""

    scene: str = "cornell"
    """Shipped scene name or a .toml path."""
    models: tuple[str, ...] = ()
    """ONNX models (diviewer export or baseline); empty: the scene's shipped assets/models/<scene>*.onnx."""
    resolutions: tuple[int, ...] = (128, 256)
    """Square frame resolutions."""
    frames: int = 30
    """Timed frames per row (test configurations along the scene's camera path)."""
    warmup: int = 5
    """Untimed frames before them."""
    untrained_k: tuple[int, ...] = (8, 16, 32, 64, 128)
    """Base widths of the untrained generators (cost curve only: no accuracy)."""
    pt_spp: tuple[int, ...] = (1, 4, 16, 64, 256)
    """Path tracer sample counts when there is no evaluation set (else the set's ladder)."""
    pt_frames: int = 2
    """Frames the path tracer is timed on, per sample count."""
    vxgi_grids: tuple[int, ...] = (32, 64, 128)
    """VXGI grid resolutions (voxels per side), one row each; empty: no VXGI rows."""
    vxgi_trace_scale: int = 2
    """VXGI traces one pixel per block of this side, then upsamples (the pass's default; 1: full resolution)."""
    gi_steps: tuple[int, ...] = (2,)
    """GI below frame resolution: frame / step, for each step the model's size multiple allows."""
    render_scales: tuple[float, ...] = ()
    """The viewer's render scales (dynamic resolution) to time and score at each resolution as a window
    (diviewer.bench.scales); empty: none."""
    evalset: str | None = None
    """The scene's evaluation set (diviewer evalset); default its compact set, assets/evalsets/<scene>."""
    eval_frames: int | None = None
    """Frames per split of the evaluation set scored (None: all)."""
    calib_data: str | None = None
    """A capture whose train split calibrates int8 quantisation (default: GL renders of training configurations)."""
    calib_frames: int = 16
    int8_max_drop_db: float = 0.5
    """int8 is kept when its tone-mapped PSNR is within this of the fp32 model's."""
    temporal_frames: int = 8
    temporal_spp: int = 64
    """Samples per pixel of the temporal sequence's reference."""
    temporal_max_spp: int | None = None
    """The path tracer's ladder rungs above this get no temporal row (None: every rung). --quick sets its
    reference's 4: the ladder's 16 to 256 spp at the evaluation set's size would be most of its time."""
    provider: str | None = None
    """onnxruntime provider (cpu, cuda, tensorrt); default the best available."""
    timing: str = "auto"
    """GL stage timing: auto (timer queries where supported), query, or sync (wall clock around glFinish)."""
    paths: tuple[str, ...] = ("lean", "graph")
    """Inference paths each model is timed on: ``lean`` (the generator alone, its encoding and decoding in shaders,
    `diviewer.contract.lean`; where a model has none, a note says why) and ``graph`` (the self-contained graph)."""

    def check(self) -> None:
        if self.frames < 1 or self.warmup < 0 or self.pt_frames < 1 or self.temporal_frames < 2:
            raise DiviewerError("--frames and pt frames must be >= 1, warm-up >= 0, temporal frames >= 2",
                                field="--frames")
        if any(r < 16 or r % 2 for r in self.resolutions):
            raise DiviewerError(f"resolutions must be even and >= 16, got {self.resolutions}", field="--res")
        from diviewer.bench.scales import check_render_scales

        check_render_scales(self.render_scales, self.resolutions)
        if self.vxgi_trace_scale < 1:
            raise DiviewerError(f"must be >= 1, got {self.vxgi_trace_scale}", field="--vxgi-trace-scale")
        if self.temporal_max_spp is not None and self.temporal_max_spp < 1:
            raise DiviewerError(f"must be >= 1 samples per pixel, got {self.temporal_max_spp}",
                                field="temporal_max_spp")
        for g in self.vxgi_grids:
            self.vxgi(g).validate()
        if not self.paths or set(self.paths) - {"lean", "graph"}:
            raise DiviewerError(f"paths must be lean and/or graph, got {self.paths}", field="paths")
        if self.timing not in ("auto", "query", "sync"):
            raise DiviewerError(f"--timing must be auto, query or sync, got {self.timing}", field="--timing")

    def vxgi(self, grid: int):
        """The VXGISettings of the row for ``grid`` voxels per side."""
        from diviewer.gl.vxgi import VXGISettings

        return VXGISettings(resolution=grid, trace_scale=self.vxgi_trace_scale)


QUICK = {"resolutions": (32,), "frames": 3, "warmup": 1, "untrained_k": (8, 16), "pt_frames": 1, "eval_frames": 1,
         "calib_frames": 2, "temporal_frames": 3, "temporal_spp": 4, "temporal_max_spp": 4, "vxgi_grids": (16,)}
"""--quick: a few frames at a small size, seconds; every kind of row, stage and metric is still there."""


def quick(settings: BenchSettings) -> BenchSettings:
    return dataclasses.replace(settings, **QUICK)


def model_paths(settings: BenchSettings, scene) -> list[Path]:
    if settings.models:
        return [Path(m) for m in settings.models]
    from diviewer.paths import models_dir

    try:
        return sorted(models_dir().glob(f"{scene.name}*.onnx"))
    except FileNotFoundError:
        return []


def _variants(paths: list[Path], tmp: Path, notes: list[str], log) -> list[dict]:
    """Each given model as fp32 and fp16 files (converted without torch where needed); baselines as given."""
    import onnx
    import onnxruntime as ort

    from diviewer.bench.onnx_tools import to_fp16, to_fp32
    from diviewer.contract.runtime import read_metadata

    out = []
    for n, path in enumerate(paths):  # n: two models of one name (a/cornell.onnx, b/cornell.onnx) convert apart
        meta = read_metadata(path)
        base = {"source": str(path), "name": path.stem, "meta": meta, "n": n}
        if meta.get("kind") == "linear_baseline":
            out.append({**base, "kind": "baseline", "precision": meta["precision"], "path": path})
            continue
        given = meta["precision"]
        out.append({**base, "kind": "neural", "precision": given, "path": path})
        other = "fp32" if given == "fp16" else "fp16"
        try:
            converted = (to_fp32 if other == "fp32" else to_fp16)(onnx.load(str(path)))
            ort.InferenceSession(converted.SerializeToString(), providers=["CPUExecutionProvider"])
            dst = tmp / f"{n}_{path.stem}_{other}.onnx"
            onnx.save(converted, str(dst))
            out.append({**base, "kind": "neural", "precision": other, "path": dst, "converted_from": given})
        except Exception as exc:  # a graph the converter does not handle (or onnxruntime then refuses): said so
            notes.append(f"{path.name}: no {other} variant ({type(exc).__name__}: {exc})")
    names = ", ".join(f"{v['name']} {v['precision']}" for v in out)
    log(f"models: {names or 'none'}")
    return out


def _check_extras(plot_out: Path | None) -> None:
    """The optional packages the benchmark needs, before any work: onnx always, matplotlib for --plot."""
    import importlib.util

    from diviewer.errors import missing_extra

    for module, needed in (("onnx", True), ("matplotlib", plot_out is not None)):
        if needed and importlib.util.find_spec(module) is None:
            raise missing_extra(module, "bench")


def _check_calib_data(settings, scene) -> None:
    """A --calib-data capture of the benchmark's scene (the same scene file), before any work."""
    if not settings.calib_data:
        return
    from diviewer.data.dataset import Dataset

    ds = Dataset(settings.calib_data)
    if ds.manifest.get("scene_hash") != scene.file_hash:
        raise DiviewerError(f"is a capture of scene '{ds.manifest.get('scene')}' (another scene file than the "
                            f"benchmark's '{scene.name}'); give a capture of this scene", path=settings.calib_data,
                            field="--calib-data")


def _int8_twins(settings, scene, ctx, mode, variants: list[dict], tmp: Path, notes: list[str]) -> list[dict]:
    """int8 twins of each trained model's fp32 variant, quantised with inputs of training frames (what failed to
    quantise goes to ``notes``)."""
    from diviewer.bench.onnx_tools import quantize_int8
    from diviewer.bench.runner import calibration

    out = []
    for v in [v for v in variants if v["kind"] == "neural" and v["precision"] == "fp32"]:
        w, h = (int(x) for x in v["meta"]["resolution"])
        calib, calib_note = calibration(settings, scene, ctx, w, h, mode, v["meta"]["encoding"])
        dst = tmp / f"{v['n']}_{v['name']}_int8.onnx"
        try:
            quantize_int8(Path(v["path"]), dst, calib)
            out.append({**v, "precision": "int8", "path": dst, "calibration": calib_note, "converted_from": "fp32"})
        except Exception as exc:
            notes.append(f"{v['name']}: int8 quantisation failed ({type(exc).__name__}: {exc})")
    return out


def run_bench(settings: BenchSettings, json_out: Path | None = None, plot_out: Path | None = None,
              log=print) -> dict:
    """Measure every row; print the table; write the JSON and the plot when asked. Returns the result."""
    _check_extras(plot_out)
    from diviewer.bench import report
    from diviewer.bench.runner import GlBench, gl_timing_mode, temporal_rows, time_path_tracer
    from diviewer.bench.scales import scale_rows, table as scale_table
    from diviewer.gl.context import headless_context
    from diviewer.contract.runtime import NeuralGI
    from diviewer.scene import load_scene, sample_config

    settings.check()
    t_start = time.perf_counter()
    scene = load_scene(settings.scene)
    _check_calib_data(settings, scene)
    notes: list[str] = []
    ds = _open_evalset(settings, scene, notes)
    tmp_dir = tempfile.TemporaryDirectory(prefix="diviewer-bench-")
    tmp = Path(tmp_dir.name)
    variants = _variants(model_paths(settings, scene), tmp, notes, log)
    nets = {}

    def net_of(v):
        key = str(v["path"])
        if key not in nets:
            nets[key] = NeuralGI(v["path"], scene=scene, provider=settings.provider)
        return nets[key]

    configs = [sample_config(scene, 7000 + i, "test") for i in range(settings.frames)]
    rows: list[dict] = []
    with headless_context() as ctx:
        mode = gl_timing_mode(ctx, settings.timing)
        env = report.environment(ctx, mode)
        variants += _int8_twins(settings, scene, ctx, mode, variants, tmp, notes)
        for res in settings.resolutions:
            log(f"timing at {res}x{res} ({settings.warmup} warm-up + {settings.frames} frames per row, GL: {mode})")
            gb = GlBench(ctx, scene, res, res, mode)
            try:
                rows += _rows_at(res, gb, settings, scene, configs, variants, net_of, tmp, notes)
            finally:
                gb.release()
        accuracy = _accuracy(ctx, mode, settings, scene, ds, variants, net_of, notes, log)
        temporal = temporal_rows(ctx, settings, scene, ds, variants, net_of, mode, notes, log)
        scales = scale_rows(ctx, mode, settings, scene, ds, variants, net_of, configs, notes, log) \
            if settings.render_scales else None
    pt = _path_tracer_timing(settings, scene, ds, configs, notes, log, time_path_tracer)
    rows.extend(pt["rows"])
    result = report.assemble(settings, scene, rows, accuracy, temporal, pt, env, notes,
                             seconds=time.perf_counter() - t_start)
    if scales is not None:
        result["render_scales"] = scales
    for line in report.table(result) + bare_ratio_lines(result["rows"]) + (scale_table(scales) if scales else []):
        log(line)
    if json_out is not None:
        from diviewer.outputs import write_json

        write_json(json_out, result)
    if plot_out is not None:
        report.plot(result, plot_out)
    tmp_dir.cleanup()
    return result


def _rows_at(res: int, gb, settings: BenchSettings, scene, configs: list, variants: list[dict], net_of,
             tmp: Path, notes: list[str]) -> list[dict]:
    """The timed rows at one square resolution: direct light, VXGI per grid, each model variant at each GI step
    it allows on each inference path (`BenchSettings.paths`), and the untrained generators of the cost curve."""
    import onnx

    from diviewer.bench.onnx_tools import generator_flops, network_inputs, untrained_generator
    from diviewer.contract.lean import lean_model
    from diviewer.contract.padding import padded_size
    from diviewer.contract.runtime import NeuralGI

    rows = [_row("direct", "direct light only", res, res, gb.time_direct(configs, settings.warmup))]
    for g in settings.vxgi_grids:
        vs = settings.vxgi(g)
        row = _row("vxgi", _vxgi_label(vs), res, -(-res // vs.trace_scale),
                   gb.time_vxgi(vs, configs, settings.warmup))
        row.update(grid=g, vxgi=dataclasses.asdict(vs), accuracy_key=f"vxgi{g}")
        rows.append(row)
    for v in variants:
        net = net_of(v)
        steps = [1] + ([s for s in settings.gi_steps if v["precision"] == v["meta"]["precision"]]
                       if v["kind"] == "neural" else [])
        paths = [p for p in settings.paths if p == "graph" or v["kind"] == "neural"]
        if "lean" in paths and lean_model(net)[0] is None:
            paths.remove("lean")
            note = lean_model(net)[1]
            notes.extend([note] if note not in notes else [])
        for step, path in [(s, p) for s in steps for p in paths]:
            if res % step:  # the runtime pads any GI size to the model's stride
                continue
            label = _label(v, step) + (f" {path}" if v["kind"] == "neural" else "")
            row = _row(v["kind"], label, res, res // step,
                       gb.time_model(net, configs, settings.warmup, step, lean=path == "lean"))
            row.update(model=v["source"], precision=v["precision"], provider=net.provider, edge_guard=net.edge_guard,
                       K=v["meta"].get("K"), levels=v["meta"].get("levels"), step=step, inference_path=path,
                       accuracy_key=f"{v['path']}|{step}", converted_from=v.get("converted_from"),
                       calibration=v.get("calibration"))
            if v["kind"] == "neural":
                lv = int(v["meta"]["levels"])
                side = res // step  # padded as the runtime pads it: to the stride, its columns with net's guard
                row["flops"] = generator_flops(int(v["meta"]["K"]), lv, padded_size(side, 2 ** lv, net.edge_guard),
                                               padded_size(side, 2 ** lv),
                                               in_channels=network_inputs(v["meta"]),
                                               upsample=v["meta"].get("upsample", "transpose"))["flops"]
            rows.append(row)
    levels = _levels(res)
    for K in settings.untrained_k:
        path = tmp / f"untrained_K{K}_{res}.onnx"
        onnx.save(untrained_generator(K, levels, scene, res), str(path))
        net = NeuralGI(path, scene=scene, provider=settings.provider)
        row = _row("untrained", f"untrained K={K} fp32", res, res,
                   gb.time_model(net, configs, settings.warmup, lean=False))
        row.update(K=K, levels=levels, precision="fp32", provider=net.provider, untrained=True, step=1,
                   flops=generator_flops(K, levels, res, res)["flops"])
        rows.append(row)
        del net
        path.unlink()
    return rows


def bare_ratio_lines(rows: list[dict]) -> list[str]:
    """Each model's inference time over a bare (untrained) generator's of the same K at the same size, in
    the same run, on each inference path: what the model's graph (or its lean path's generator) costs beyond
    the bare convolutions. Also recorded in the rows (``bare_ratio``)."""
    def inference(r):
        return r["timing"]["stages"].get("inference", {}).get("median")

    bare = {(r["K"], r["resolution"][0]): r for r in rows if r.get("untrained")}
    lines = []
    for r in rows:
        b = bare.get((r.get("K"), r["gi_resolution"][0]))
        if r["kind"] != "neural" or r.get("untrained") or b is None or not inference(r) or not inference(b):
            continue
        if r.get("levels") is not None and b.get("levels") is not None and r["levels"] != b["levels"]:
            continue  # the model pads this size to its own stride: another graph than the bare one's
        r["bare_ratio"] = inference(r) / inference(b)
        lines.append(f"  {r['label'][:36]:<36} {r['gi_resolution'][0]:>4}: inference {inference(r):.2f} ms = "
                     f"{r['bare_ratio']:.2f} x the bare K={r['K']} fp32 generator's {inference(b):.2f} ms")
    return ["", "model / bare generator of the same K and size (inference, median):"] + lines if lines else []


def _levels(res: int) -> int:
    """U-Net levels for a square side: the times it halves exactly (train.networks.levels_for_resolution, which
    imports torch)."""
    levels, r = 0, res
    while r % 2 == 0 and r > 1:
        r //= 2
        levels += 1
    return levels


def _label(v: dict, step: int) -> str:
    if v["kind"] == "baseline":
        return f"linear baseline ({v['name']})"
    gi = f" GI 1/{step}" if step > 1 else ""
    return f"{v['name']} K={v['meta']['K']} {v['precision']}{gi}"


def _vxgi_label(vs) -> str:
    return f"VXGI {vs.resolution}^3" + (f" trace 1/{vs.trace_scale}" if vs.trace_scale > 1 else "")


def _row(kind: str, label: str, res: int, gi_res: int, timing: dict) -> dict:
    return {"kind": kind, "label": label, "resolution": [res, res], "gi_resolution": [gi_res, gi_res],
            "timing": timing}


def _open_evalset(settings, scene, notes):
    from diviewer.evaluation.frames import EvalFrames, default_evalset
    from diviewer.evaluation.evaluate import check_frames

    path = Path(settings.evalset) if settings.evalset else default_evalset(scene.name)
    if not (path / "manifest.json").is_file():
        notes.append(f"no evaluation set at {path}: accuracy columns are empty (make one with "
                     f"`diviewer evalset --scene {scene.name} --out DIR` and pass --evalset DIR)")
        return None
    ds = EvalFrames(path)
    if ds.manifest["scene_hash"] != scene.file_hash:
        notes.append(f"the evaluation set {path} was made from another version of the scene file: accuracy left out")
        return None
    check_frames(ds, partial=False)  # a corrupt or incomplete set is refused, as by `diviewer eval`
    return ds


def _accuracy(ctx, mode, settings, scene, ds, variants, net_of, notes, log) -> dict | None:
    """Scores at the evaluation set's resolution, keyed like rows' ``accuracy_key``."""
    if ds is None:
        return None
    from diviewer.bench.runner import GlBench, score_evalset

    idx, (E, H) = ds.bench_frames()
    models = {}
    for v in variants:
        net = net_of(v)
        steps = [1] + (list(settings.gi_steps) if v["kind"] == "neural" and v["precision"] == v["meta"]["precision"]
                       else [])
        for step in steps:
            if E % step or H % step:  # the runtime pads any GI size to the model's stride
                notes.append(f"{v['name']} {v['precision']}" + (f" GI 1/{step}" if step > 1 else "") +
                             f": no accuracy (the evaluation set's {E}x{H} px is not divisible by {step})")
                continue
            models[f"{v['path']}|{step}"] = (net, step)
    vxgi = {f"vxgi{g}": settings.vxgi(g) for g in settings.vxgi_grids}
    log(f"scoring {len(models)} model variants and {len(vxgi)} VXGI grids on {ds.root} ({E}x{H})")
    gl = GlBench(ctx, scene, E, H, mode) if vxgi or models else None  # models take the frame's GL scene, camera
    try:
        scored = score_evalset(ds, idx, (E, H), models, settings.eval_frames, gl, log, vxgi=vxgi)
    finally:
        if gl is not None:
            gl.release()
    scored["path"] = str(ds.root)
    scored["resolution"] = [E, H]
    scored["compact"] = ds.compact
    scored["frames"] = ds.subset
    scored["reference_spp"] = ds.manifest["spp"]
    return scored


def _path_tracer_timing(settings, scene, ds, configs, notes, log, time_path_tracer) -> dict:
    try:
        from diviewer.reference.mitsuba import effective_spp, import_mitsuba as _import_mitsuba

        _import_mitsuba()
    except DiviewerError as exc:
        notes.append(f"no path tracer rows: {exc}")
        return {"rows": [], "ladder": {}}
    ladder = [int(n) for n in ds.manifest["evalset"]["ladder_spp"]] if ds is not None else \
        sorted({effective_spp(n) for n in settings.pt_spp})
    rows, by_res = [], {}
    for res in settings.resolutions:
        log(f"path tracer at {res}x{res}: {'/'.join(map(str, ladder))} spp on {settings.pt_frames} frame(s)")
        timings = time_path_tracer(scene, configs[: settings.pt_frames], res, res, ladder)
        by_res[res] = {n: t["frame"]["median"] for n, t in timings.items()}
        for n, t in timings.items():
            row = _row("path_tracer", f"path traced {n} spp", res, res, t)
            row.update(spp=n, accuracy_key=f"pt_spp{n}")
            rows.append(row)
    return {"rows": rows, "ladder": ladder, "ms_by_resolution": by_res}


__all__ = ["BenchSettings", "QUICK", "quick", "run_bench"]
