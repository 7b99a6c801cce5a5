"""The benchmark's outputs: the machine it ran on, the rows joined with their accuracy, the table, the plot."""

from __future__ import annotations

import dataclasses
import math
import os
import platform
from pathlib import Path

from diviewer.bench.frontier import equal_error, equal_time, smallest_sufficient_k
from diviewer.evaluation.evaluate import EVAL_KEYS, EQUIVALENT_BY
from diviewer.metrics import psnr_error

PAPER_CLAIMS = {"VXGI": 10.0, "path tracing": 100.0}
"""Deep Illumination's claims, as ratios of frame time at similar quality: the network ~10x faster than VXGI
and ~100x faster than path tracing."""
ACCURACY_KEYS = EVAL_KEYS + ("checkerboard",)


def environment(ctx, gl_timing: str) -> dict:
    """CPU, GPU (GL renderer), onnxruntime providers, versions, and the load while it ran."""
    import onnxruntime as ort

    from diviewer.provenance import cpu_model, versions

    return {"cpu": cpu_model(), "cpu_count": os.cpu_count(), "platform": platform.platform(),
            "load_average_at_start": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
            "gl_renderer": ctx.info["GL_RENDERER"], "gl_vendor": ctx.info["GL_VENDOR"],
            "gl_version": ctx.info["GL_VERSION"],
            "gl_timing": {"query": "GL timer queries (GPU clock) per GL stage",
                          "sync": "wall clock around glFinish per GL stage"}[gl_timing],
            "cpu_timing": "wall clock (readback, inference, upload, path_trace, the frame)",
            "onnxruntime_available_providers": ort.get_available_providers(), "versions": versions()}


def _psnr_from_error(e):
    return None if e is None else -10.0 * math.log10(e)


def assemble(settings, scene, rows, accuracy, temporal, pt, env, notes, seconds: float) -> dict:
    """Join rows with accuracy, equivalent spp, equal-time and equal-error figures, temporal stability, FLOP/s."""
    methods = accuracy["methods"] if accuracy else {}
    by = EQUIVALENT_BY[0]
    ladder = pt.get("ladder") or []
    ladder_err = [psnr_error(methods[f"pt_spp{n}"][by]["mean"]) for n in ladder] if methods else None
    t_methods = temporal["methods"] if temporal else {}
    for row in rows:
        if row["kind"] == "direct":
            row["accuracy_key"] = "direct"
        key = row.get("accuracy_key")
        acc = None if row.get("untrained") else methods.get(key)
        row["accuracy"] = {k: (acc[k]["mean"] if k != "checkerboard" else acc[k]) for k in ACCURACY_KEYS} if acc else None
        row["equivalent_spp"] = acc["equivalent_spp"] if acc else None
        ms = row["timing"]["frame"]["median"]
        pt_ms = pt.get("ms_by_resolution", {}).get(row["resolution"][0])
        row["equal_time"] = row["equal_error"] = None
        if ladder_err and pt_ms and row["kind"] != "path_tracer":
            et = equal_time(ladder, [pt_ms[n] for n in ladder], ladder_err, ms)
            row["equal_time"] = {"spp": et["spp"], "bound": et["bound"], by: _psnr_from_error(et["error"])}
            if acc and acc[by]["mean"] is not None and math.isfinite(acc[by]["mean"]):
                row["equal_error"] = equal_error(ladder, [pt_ms[n] for n in ladder], ladder_err,
                                                 psnr_error(acc[by]["mean"]), ms)
        t_key = "direct" if row["kind"] == "direct" else key if row.get("step", 1) == 1 else None
        row["temporal"] = t_methods.get(t_key) if t_key else None
        inf = row["timing"]["stages"].get("inference")
        row["achieved_flops_per_s"] = row["flops"] / (inf["median"] / 1e3) if row.get("flops") and inf else None
    _int8(rows, settings.int8_max_drop_db, notes)
    trained = {}
    for r in rows:
        if r["kind"] == "neural" and r.get("step") == 1 and r["accuracy"] and r.get("K"):
            trained[int(r["K"])] = max(trained.get(int(r["K"]), -math.inf), r["accuracy"][by])
    cost = {"flops": "2 x multiply-adds of the generator's convolutions per frame (elementwise layers not counted)",
            "by_K": [{"K": r["K"], "resolution": r["gi_resolution"], "label": r["label"], "flops": r["flops"],
                      "inference_ms": r["timing"]["stages"]["inference"]["median"],
                      "achieved_flops_per_s": r["achieved_flops_per_s"], "untrained": bool(r.get("untrained"))}
                     for r in rows if r.get("flops")],
            "smallest_sufficient_K": smallest_sufficient_k(trained) if trained else None}
    if not trained:
        notes.append("smallest sufficient K: needs trained models of several K with accuracy")
    for r in rows:
        r.pop("accuracy_key", None)
    return {"benchmark": "diviewer bench", "scene": scene.name, "scene_hash": scene.file_hash,
            "settings": dataclasses.asdict(settings), "environment": env, "stages": list(_stage_names(rows)),
            "accuracy": None if not accuracy else {
                "evalset": accuracy["path"], "resolution": accuracy["resolution"], "frames": accuracy["frames"],
                "reference_spp": accuracy["reference_spp"], "tonemap_exposure": accuracy["exposure"],
                "ladder": {f"pt_spp{n}": {k: methods[f"pt_spp{n}"][k]["mean"] for k in EVAL_KEYS} for n in ladder},
                "noise_floor": {k: methods["noise_floor"][k]["mean"] for k in EVAL_KEYS} if "noise_floor" in methods else None,
                "equivalent_spp_by": by, "pooled": "mean over the frames of both splits"},
            "path_tracer_ms": pt.get("ms_by_resolution"), "temporal": None if not temporal else
            {k: v for k, v in temporal.items() if k != "methods"},
            "cost_model": cost, "paper_claims": PAPER_CLAIMS, "rows": rows, "notes": notes,
            "seconds": seconds}


def _stage_names(rows):
    seen = {}
    for r in rows:
        for k in r["timing"]["stages"]:
            seen[k] = None
    return seen


def _int8(rows, max_drop, notes):
    """Each int8 row's accuracy drop against its fp32 source; kept when within ``max_drop`` dB."""
    for r in rows:
        if r.get("precision") != "int8":
            continue
        src = next((s for s in rows if s.get("model") == r.get("model") and s.get("precision") == "fp32"
                    and s["resolution"] == r["resolution"] and s.get("step") == r.get("step")), None)
        if r["accuracy"] is None or src is None or src["accuracy"] is None:
            r["int8"] = {"drop_db": None, "kept": None, "why": "no accuracy to compare (no evaluation set)"}
            continue
        drop = src["accuracy"][EQUIVALENT_BY[0]] - r["accuracy"][EQUIVALENT_BY[0]]
        r["int8"] = {"drop_db": drop, "kept": drop <= max_drop, "max_drop_db": max_drop}
        note = f"{r['label']}: int8 loses {drop:.2f} dB (PSNR tm) > {max_drop} dB: not kept"
        if drop > max_drop and note not in notes:  # once a model: every resolution's row carries the same accuracy
            notes.append(note)


def _f(v, fmt):
    return "-" if v is None else format(v, fmt)


def table(result: dict) -> list[str]:
    """The table for people: one line per row, then each row's stages, then the notes."""
    env = result["environment"]
    lines = [f"diviewer bench: {result['scene']} on {env['cpu']} ({env['cpu_count']} cores), {env['gl_renderer']}; "
             f"GL stages: {env['gl_timing']}"]
    if result["accuracy"]:
        a = result["accuracy"]
        lines.append(f"accuracy: {a['frames']} frames of {a['evalset']} at {a['resolution'][0]}x{a['resolution'][1]} "
                     f"against {a['reference_spp']} spp; PSNR/SSIM tone-mapped; eq. spp from PSNR tm")
    lines.append("")
    head = (f"{'method':<36} {'res':>5} {'GI':>4} {'ms':>8} {'p95':>8} {'fps':>7} {'infer':>7} {'ovh%':>5} "
            f"{'PSNRtm':>6} {'SSIMtm':>6} {'FLIP':>6} {'eq.spp':>7} {'PT@time':>8} {'x PT':>7} {'flick':>6}")
    lines += [head, "-" * len(head)]
    for r in result["rows"]:
        t, a = r["timing"], r["accuracy"]
        inf = t["stages"].get("inference", {}).get("median")
        eq = (r["equivalent_spp"] or {}).get(EQUIVALENT_BY[0])
        et = r["equal_time"]
        ee = r["equal_error"]
        label = r["label"] + (" [untrained]" if r.get("untrained") else "") + \
            (" [not kept]" if (r.get("int8") or {}).get("kept") is False else "")
        lines.append(
            f"{label[:36]:<36} {r['resolution'][0]:>5} {r['gi_resolution'][0]:>4} {t['frame']['median']:8.2f} "
            f"{t['frame']['p95']:8.2f} {t['fps']:7.1f} {_f(inf, '7.2f'):>7} {100 * t['overhead_fraction']:5.1f} "
            f"{_f(a and a['psnr_tm'], '6.2f'):>6} {_f(a and a['ssim_tm'], '6.3f'):>6} {_f(a and a['flip_ldr'], '6.3f'):>6} "
            f"{eq['text'] if eq else '-':>7} "
            f"{(('<' if et['bound'] == '<' else '>=' if et['bound'] == '>=' else '') + format(et['spp'], '.3g')) if et else '-':>8} "
            f"{_f(ee and ee['speedup'], '7.1f'):>7} {_f(r['temporal'] and r['temporal']['ratio'], '6.2f'):>6}")
    lines += ["", "columns: ms/p95 = frame time (median, 95th percentile); infer = inference ms; ovh% = frame time outside "
              "inference; eq.spp = path-tracer samples with the same error; PT@time = samples the path tracer renders in "
              "this row's frame time; x PT = path tracer's time at equal error / this row's; flick = frame-to-frame "
              "change / the reference's", "", "stages (median ms):"]
    for r in result["rows"]:
        st = r["timing"]["stages"]
        lines.append(f"  {r['label'][:36]:<36} {r['resolution'][0]:>4}: " +
                     "  ".join(f"{k} {v['median']:.2f}" for k, v in st.items()))
    cost = result["cost_model"]
    if cost["by_K"]:
        lines += ["", "cost model (FLOPs per frame, achieved FLOP/s in inference):"]
        for c in cost["by_K"]:
            lines.append(f"  {c['label'][:36]:<36} {c['resolution'][0]:>4}: {c['flops'] / 1e6:10.1f} MFLOP  "
                         f"{_f(c['achieved_flops_per_s'] and c['achieved_flops_per_s'] / 1e9, '8.2f')} GFLOP/s")
    if cost["smallest_sufficient_K"]:
        s = cost["smallest_sufficient_K"]
        lines.append(f"  smallest K within {s['tolerance_db']} dB of the best (K={s['best_K']}, {s['best_psnr']:.2f} dB): "
                     f"K={s['K']}")
    if result["notes"]:
        lines += ["", "notes:"] + [f"  - {n}" for n in result["notes"]]
    return lines


def plot(result: dict, out: Path) -> Path:
    """Error (tone-mapped PSNR) against frame time, log time axis, with the paper's claims as ratios."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = EQUIVALENT_BY[0]
    fig, ax = plt.subplots(figsize=(8, 5.5), dpi=120)
    markers = {"direct": "s", "baseline": "D", "neural": "o", "path_tracer": "^", "vxgi": "v"}
    # one colour per method at every resolution; the first resolution filled, the others open
    colours, cycle = {}, plt.rcParams["axes.prop_cycle"].by_key()["color"]
    resolutions = sorted({r["resolution"][0] for r in result["rows"]})
    for i, res in enumerate(resolutions):
        rows = [r for r in result["rows"] if r["resolution"][0] == res and r["accuracy"]]
        face = {} if i == 0 else {"markerfacecolor": "none"}
        pt = sorted((r for r in rows if r["kind"] == "path_tracer"), key=lambda r: r["spp"])
        if pt:
            c = colours.setdefault("path tracer", cycle[len(colours) % len(cycle)])
            ax.plot([r["timing"]["frame"]["median"] for r in pt], [r["accuracy"][by] for r in pt], marker="^",
                    color=c, ls="-" if i == 0 else "--", label=f"path tracer {res}px (1..{pt[-1]['spp']} spp)", **face)
        claimed = False
        for r in rows:
            if r["kind"] == "path_tracer":
                continue
            x, y = r["timing"]["frame"]["median"], r["accuracy"][by]
            c = colours.setdefault(r["label"], cycle[len(colours) % len(cycle)])
            ax.plot([x], [y], markers.get(r["kind"], "o"), color=c, label=f"{r['label']} {res}px", **face)
            if (r["kind"] == "neural" and r.get("step") == 1 and r.get("precision") in ("fp16", "fp32")
                    and not claimed):  # the paper's ratios once per resolution, from the first network row
                claimed = True
                for j, (name, ratio) in enumerate(PAPER_CLAIMS.items()):
                    ax.plot([x * ratio], [y], "x", color="grey")
                    ax.annotate(f"paper: {name} ~{ratio:.0f}x ({res}px)", (x * ratio, y), fontsize=6, color="grey",
                                xytext=(3, 4 + 9 * (2 * i + j)), textcoords="offset points")
                if r["equal_error"]:
                    ax.plot([r["equal_error"]["pt_ms"]], [y], "*", color="black", ms=8)
    ax.set_xscale("log")
    ax.set_xlabel("frame time (ms, median, log scale)")
    ax.set_ylabel(f"PSNR tone-mapped (dB) vs {result['accuracy']['reference_spp'] if result['accuracy'] else '?'} spp")
    env = result["environment"]
    ax.set_title(f"{result['scene']}: speed/accuracy ({env['cpu'][:40]}, {env['gl_renderer'][:30]})", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=6, loc="lower right")
    fig.text(0.01, 0.01, "x: where the paper's ratios would put VXGI / path tracing at the network's quality; "
             "*: this path tracer's time at the network's error", fontsize=6)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    from diviewer import imageio

    try:
        with imageio.atomic_path(out) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
    return Path(out)
