"""Where a build's cost estimates come from, for the user's own scene: one GL frame and one low-spp path-traced
frame of it timed on this machine at the recipe's resolution (cached in the work folder, keyed by the scene's
identity and the machine), or a previous build's actual stage times in the same folder, else the constants of
`diviewer.builder.costs` (measured on Sponza and cornell).

The constants are scaled, not replaced: a stage's estimate is its constant cost times the factor its source gives
(`CostBasis`), so the recipe's proportions (spp, ladder, frames) still come from the cost model.
"""

from __future__ import annotations

import json
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

from diviewer import imageio
from diviewer.builder import costs

CALIBRATION_FILE = "calibration.json"
"""The timed frames of the scene on this machine, in the work folder."""
ACTUALS_FILE = "costs_actual.json"
"""A build's actual stage times against its plan, in the work folder (`diviewer.builder.actuals`)."""
SPP_LOW, SPP_HIGH = 2, 8
"""The two sample counts the path tracer is timed at, each after a first frame that compiles its kernels: the slope is
the seconds a sample, the rest a frame's fixed cost."""


@dataclass(frozen=True)
class CostBasis:
    """Per stage (a name such as ``train_k8``, or a kind such as ``capture``), the factor on the constant cost and
    where it comes from; a stage not named keeps the constants (``default``)."""

    factors: dict[str, float] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    default: str = "the constants in diviewer/builder/costs.py"

    def of(self, stage: str) -> tuple[float, str]:
        for key in (stage, stage.partition("_k")[0]):
            if key in self.factors:
                return self.factors[key], self.sources[key]
        if stage.partition("_k")[0] == "train":
            return 1.0, TRAIN_SOURCE
        if stage.partition("_k")[0] == "export":
            return 1.0, EXPORT_SOURCE
        return 1.0, self.default


TRAIN_SOURCE = "the training constants in diviewer/builder/costs.py (Sponza's ladder on a 2-core CPU, an H100)"
"""Where a training's cost comes from without a previous build's actuals: it depends on the resolution and K, not
on the scene."""
EXPORT_SOURCE = "an allowance, not a measurement (EXPORT_EVAL_ALLOWANCE in diviewer/builder/costs.py)"


def machine_key() -> dict:
    """This machine as a calibration's key: its kind, cores and CPU model."""
    model = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    m = costs.detect_machine()
    return {"kind": m.kind, "cpus": m.cpus, "cpu": model}


def constants_source(scene_name: str) -> str:
    """The constants a scene's path tracing is costed with when nothing of it was measured, in words."""
    if ("cpu", scene_name) in costs.PT_SECONDS_PER_SAMPLE:
        return f"{scene_name}'s constants (diviewer/builder/costs.py)"
    return "Sponza's constants: this scene's own cost is unmeasured (diviewer/builder/costs.py)"


def time_scene(scene, width: int, height: int, spp: int, max_depth: int) -> dict:
    """One GL frame and the path tracer's frame of ``scene`` at ``width`` x ``height`` timed here: the GL frame's
    seconds (the second of two: the first compiles the shaders), and the path tracing's fixed and per-sample
    seconds (`SPP_LOW`, `SPP_HIGH`), from which a frame at ``spp`` is predicted."""
    from diviewer.gl.context import headless_context
    from diviewer.gl.renderer import Renderer
    from diviewer.reference import mitsuba as ref
    from diviewer.scene.sampler import sample_config

    config = sample_config(scene, 0, "train")
    with headless_context() as ctx:
        renderer = Renderer(ctx, scene, width, height)
        try:
            renderer.frame(config)
            t0 = time.perf_counter()
            renderer.frame(config)
            ctx.finish()
            gl = time.perf_counter() - t0
        finally:
            renderer.release()
    variant = ref.select_variant()
    t0 = time.perf_counter()
    frame = ref.load_frame(scene, config, width, height)
    load = time.perf_counter() - t0
    for n in (SPP_LOW, SPP_HIGH):  # compiles the kernels (one each: the sample count is compiled in)
        frame.full_and_direct(n, 1, max_depth)
    seconds = {}
    for n in (SPP_LOW, SPP_HIGH):
        t0 = time.perf_counter()
        frame.full_and_direct(n, 2, max_depth)
        seconds[n] = time.perf_counter() - t0
    per_sample = max(seconds[SPP_HIGH] - seconds[SPP_LOW], 0.0) / (SPP_HIGH - SPP_LOW)
    fixed = max(seconds[SPP_LOW] - per_sample * SPP_LOW, 0.0) + load
    return {"gl_seconds": round(gl, 4), "pt_fixed_seconds": round(fixed, 4),
            "pt_seconds_per_sample": per_sample, "variant": variant, "pt_frame_seconds": round(fixed + per_sample
                                                                                                * spp, 3)}


def calibrate(scene_path: Path, scene_name: str, capture, work: Path, log=print, keep: bool = True) -> dict | None:
    """This scene's frame timed on this machine at the capture's resolution (`time_scene`), from the work folder's
    cache where its key (scene identity, machine, resolution, spp) matches, else measured now and kept there
    (atomically; ``keep`` False: not kept, `keep_calibration` keeps it once the command is accepted; a fresh
    record then has ``unkept`` set). None, with a line saying why, where the scene cannot be timed here (no Mitsuba, no GL)."""
    from diviewer.scene.loader import load_scene

    scene = load_scene(scene_path)
    key = {"scene_hash": scene.file_hash, "machine": machine_key(), "width": capture.width,
           "height": capture.height, "spp": capture.spp, "max_depth": capture.max_depth}
    cache = Path(work) / CALIBRATION_FILE
    try:
        kept = json.loads(cache.read_text())
        if kept.get("key") == key:
            return kept
    except (OSError, ValueError):
        pass
    try:
        t0 = time.perf_counter()
        measured = time_scene(scene, capture.width, capture.height, capture.spp, capture.max_depth)
    except Exception as exc:  # noqa: BLE001 - the plan then says the constants stand, and why
        log(f"costs: {scene_name} could not be timed here ({type(exc).__name__}: {exc}); the plan uses "
            f"{constants_source(scene_name)}")
        return None
    record = {"key": key, **measured, "seconds": round(time.perf_counter() - t0, 2)}
    log(f"costs: timed {scene_name} here at {capture.width}x{capture.height} in {record['seconds']:.1f} s: "
        f"GL {measured['gl_seconds']:.3f} s a frame, path tracing {measured['pt_frame_seconds']:.2f} s a frame "
        f"at {capture.spp} spp")
    record["unkept"] = True
    if keep:
        keep_calibration(work, record)
    return record


def keep_calibration(work: Path, record: dict | None) -> None:
    """Keep a fresh calibration ``record`` in ``work`` (`CALIBRATION_FILE`, atomically), creating the folder."""
    if record is None or not record.pop("unkept", False):
        return
    Path(work).mkdir(parents=True, exist_ok=True)
    imageio.write_text(Path(work) / CALIBRATION_FILE, json.dumps(record, indent=1, sort_keys=True) + "\n")


def basis(scene_name: str, capture, calibration: dict | None, actuals: dict | None) -> CostBasis:
    """The cost basis of a plan: a previous build's actuals where they are of this scene on this machine, else the
    calibration, else the constants (`constants_source`)."""
    factors, sources = {}, {}
    if calibration is not None:
        kind = calibration["key"]["machine"]["kind"]
        w, h, spp = capture.width, capture.height, capture.spp
        const_pt = costs.refine_seconds(kind, scene_name, 1, w, h, spp)
        const_frame = costs.capture_seconds(kind, scene_name, 1, w, h, spp)
        measured_pt = calibration["pt_frame_seconds"]
        measured_frame = measured_pt + calibration["gl_seconds"]
        where = f"measured on this scene ({w}x{h}, {calibration['variant']}, {calibration['key']['machine']['cpu']})"
        for stage, factor in (("capture", measured_frame / const_frame), ("refine", measured_pt / const_pt),
                              ("evalset", measured_pt / const_pt)):
            factors[stage], sources[stage] = factor, where
    for stage, rec in (actuals or {}).items():
        if rec.get("factor") and rec["factor"] > 0:
            factors[stage] = rec["factor"]
            sources[stage] = f"a previous build's actuals in this work folder ({rec['actual_seconds']:.0f} s)"
    return CostBasis(factors, sources, constants_source(scene_name))


def actuals_key(scene_hash: str, capture) -> dict:
    """What a build's actual costs are of: the scene, this machine, and the capture's resolution and spp (a stage's
    fixed costs weigh otherwise at another)."""
    return {"scene_hash": scene_hash, "machine": machine_key(), "width": capture.width, "height": capture.height,
            "spp": capture.spp}


def previous_actuals(work: Path, scene_hash: str, capture) -> dict | None:
    """The actual costs a build of this scene on this machine at this capture's resolution and spp kept in ``work``
    (`ACTUALS_FILE`), per stage; None where there are none or they are of another (`actuals_key`)."""
    try:
        data = json.loads((Path(work) / ACTUALS_FILE).read_text())
    except (OSError, ValueError):
        return None
    if data.get("key") != actuals_key(scene_hash, capture):
        return None
    return data.get("stages") or None


def plan_basis(scene: str, recipe, work: Path, log=print, keep: bool = True) -> tuple[CostBasis, dict | None]:
    """The cost basis of a build of ``scene`` with ``recipe`` in ``work``, before it is planned: this scene timed
    here at the recipe's capture resolution (`calibrate`), and a previous build's actuals in ``work``; and the
    calibration record (for `keep_calibration` where ``keep`` is False)."""
    from diviewer.scene.loader import load_scene, resolve_scene_path
    from diviewer.train.recipe import capture_settings

    path = resolve_scene_path(scene)
    loaded = load_scene(path)
    capture = capture_settings(recipe)
    record = calibrate(path, loaded.name, capture, work, log, keep)
    return basis(loaded.name, capture, record, previous_actuals(work, loaded.file_hash, capture)), record
