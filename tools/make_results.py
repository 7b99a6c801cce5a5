"""docs/results.md and README.md's headline table, written from the shipped data and nothing else.

Usage: python tools/make_results.py [--check]

Every figure of the page is read from a file of the tree: the model cards (assets/models/<scene>.json), the ladder
records they name (assets/models/<scene>_ladder.json), each shipped model's evaluation on its scene's full
evaluation set and the benchmark of its scene (JSON under docs/data/, listed in SOURCES). The page names each
file, the machine its own environment record gives and the date its folder carries. Run it after any of these
files changes; ``--check`` exits 1 when the page or the README's table is not what the data gives
(tests/test_results_page.py runs the same comparison).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = "docs/results.md"
README = "README.md"
BEGIN, END = "<!-- results: headline (python tools/make_results.py) -->", "<!-- /results -->"
RECORD_COMMIT = "c48f1bc"
"""The commit whose tree still holds the long records (ablations, the Sponza chain's log, superseded models)."""

SOURCES = {
    "cornell": {"eval": "docs/data/cornell_v3/eval_full_k16half_96frames.json", "method": "cornell_k16",
                "bench": "docs/data/timings_2026-11-29d/bench_cornell.json",
                "shown": ("docs/data/eval_exposure/cornell_shown.json", "--exposure=0", "its fixed exposure, 0 EV")},
    "sponza": {"eval": "docs/data/sponza256_ladder/eval_full_ladder.json", "method": "sponza_k16",
               "bench": "docs/data/timings_2026-12-02/bench_sponza.json",
               "shown": ("docs/data/eval_exposure/sponza_metered.json", "--exposure metered",
                         "each frame's metered exposure")},
}
"""Per shipped scene: its model's full-set evaluation (and the method's key in it), its benchmark, and its compact
set scored at the exposure the viewer shows it at (the JSON, eval's option, how the viewer exposes the scene)."""

SPLITS = {"unseen_configs": "new configurations (scene camera)", "unseen_objects": "unseen objects",
          "moved_camera": "moved camera (held-out regions / path)", "window_shapes_170x128": "4:3 window",
          "window_shapes_228x128": "16:9 window"}
RECORDS = [("ablations of the network (decoder, loss, GAN, demodulation, K) and Experiment 4", "docs/training.md"),
           ("the cornell models shipped before, scored on the same sets", "docs/accuracy.md"),
           ("training where the user flies: camera ranges, window shapes, the shade", "docs/generalisation.md"),
           ("every timing run of the viewer and the benchmark, per machine", "docs/speed.md"),
           ("the viewer's frame against the path tracer at window size, supersampling, window shapes", "docs/viewer.md"),
           ("how each cost constant of the build's estimate was measured", "docs/build.md"),
           ("the Sponza asset, the chain of captures, refinements, ladders and filtered truths behind its model, and the "
            "models shipped before it", "docs/sponza.md")]


def wrap(text: str) -> list[str]:
    return textwrap.wrap(text, 116, break_long_words=False, break_on_hyphens=False)


def load(rel: str) -> dict:
    return json.loads((ROOT / rel).read_text(encoding="utf-8"))


def date_of(rel: str) -> str:
    """The measurement's date, as the folder that holds its JSON carries it ('not recorded' where none does)."""
    m = re.search(r"\d{4}-\d{2}-\d{2}", rel)
    return m.group(0) if m else "not recorded"


def machine_of(env: dict) -> str:
    return (f"{env['cpu']}, {env['cpu_count']} cores, {env['gl_renderer']}, onnxruntime "
            f"{env['versions']['onnxruntime']}")


def db(x: float) -> str:
    return f"{x:.1f}"


def mean(split: dict, method: str, metric: str) -> float:
    return split["methods"][method][metric]["mean"]


def shipped(scene: str) -> dict:
    """The scene's card, its evaluation, its bench and the figures the headline takes from them."""
    src = SOURCES[scene]
    card, ev, bench = load(f"assets/models/{scene}.json"), load(src["eval"]), load(src["bench"])
    model = f"assets/models/{scene}.onnx"
    row = next(r for r in bench["rows"] if r["kind"] == "neural" and r["label"] == f"{scene} K={card['K']} fp32"
               and r["resolution"] == [128, 128] and r["gi_resolution"] == [128, 128])
    first = ev["splits"]["unseen_configs"]
    shown = load(src["shown"][0])
    return {"card": card, "eval": ev, "bench": bench, "row": row, "src": src, "shown": shown,
            "mb": (ROOT / model).stat().st_size / 1e6,
            "psnr": mean(first, src["method"], "psnr_tm"), "direct": mean(first, "direct", "psnr_tm")}


def headline(scenes: dict) -> list[str]:
    names = list(scenes)
    out = ["| | " + " | ".join(f"`{n}`" for n in names) + " |", "| --- |" + " --- |" * len(names)]
    out.append("| tone-mapped PSNR against the path tracer (1024 spp), new configurations | "
               + " | ".join(f"**{db(s['psnr'])} dB**" for s in scenes.values()) + " |")
    out.append("| direct light alone, the same frames | "
               + " | ".join(f"{db(s['direct'])} dB" for s in scenes.values()) + " |")
    out.append("| the model at the exposure the viewer shows each frame at (compact set; in brackets, the path tracer's noise "
               "there) | " + " | ".join(
                   f"{db(mean(sp, s['card']['scene'], 'psnr_tm'))} dB ({db(mean(sp, 'noise_floor', 'psnr_tm'))} dB)"
                   for s in scenes.values() for sp in [s["shown"]["splits"]["unseen_configs"]]) + " |")
    envs = [s["bench"]["environment"] for s in scenes.values()]
    cores = "/".join(sorted({str(e["cpu_count"]) for e in envs}))
    gl = "software GL" if all(e["gl_renderer"].startswith("llvmpipe") for e in envs) else "GL: " + ", ".join(
        sorted({e["gl_renderer"] for e in envs}))
    out.append(f"| frame rate at 128x128 on a {cores}-core CPU, {gl} | "
               + " | ".join(f"{s['row']['timing']['fps']:.0f} fps" for s in scenes.values()) + " |")
    out.append("| model: width K, weights, size | "
               + " | ".join(f"K = {s['card']['K']}, {s['card']['weights']}, {s['mb']:.1f} MB" for s in scenes.values())
               + " |")
    return out


def split_table(s: dict) -> list[str]:
    ev, method = s["eval"], s["src"]["method"]
    out = ["| split | frames | PSNR tm (dB) | SSIM tm | FLIP-LDR | equivalent spp | direct light: PSNR tm |",
           "| --- | --- | --- | --- | --- | --- | --- |"]
    for key, name in SPLITS.items():
        split = ev["splits"].get(key)
        if split is None:
            continue
        m = split["methods"][method]
        spp = m["equivalent_spp"]
        spp = spp["psnr_tm"]["text"]
        out.append(f"| {name} | {split['frames']} | **{m['psnr_tm']['mean']:.2f}** | {m['ssim_tm']['mean']:.3f} | "
                   f"{m['flip_ldr']['mean']:.3f} | {spp} | {mean(split, 'direct', 'psnr_tm'):.2f} |")
    return out


def ladder_table(card: dict) -> list[str]:
    rec = load(f"assets/models/{card['ladder']['file']}")
    out = ["| K | steps | size (MB) | PSNR tm over the set (dB) | picked |", "| --- | --- | --- | --- | --- |"]
    for r in rec["rows"]:
        pick = "**yes**" if r["K"] == rec["chosen_K"] else ""
        out.append(f"| {r['K']} | {r['steps']:,} | {r['bytes'] / 1e6:.1f} | {r['evalset_psnr_tm']:.2f} | {pick} |")
    m = rec["machine"]
    out += [""] + wrap(f"Sizes are the ladder's float32 exports. Rule: {rec['rule']}. Machine: {m['kind']}, "
                       f"{m['cpus']} cores. Record: [assets/models/{card['ladder']['file']}]"
                       f"(../assets/models/{card['ladder']['file']}).")
    return out


def fmt_spp(row: dict) -> str:
    e = row.get("equivalent_spp") or {}
    return e.get("psnr_tm", {}).get("text", "-")


def speed_table(bench: dict) -> list[str]:
    out = ["| method | res | ms median (p95) | fps | inference ms | PSNR tm | equivalent spp | x path tracer |",
           "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in bench["rows"]:
        if r["kind"] in ("path_tracer", "untrained"):
            continue
        t, acc = r["timing"], r.get("accuracy") or {}
        inf = t["stages"].get("inference", {}).get("median")
        speed = (r.get("equal_error") or {}).get("speedup")
        psnr = acc.get("psnr_tm")
        cells = [r["label"], str(r["resolution"][0]), f"{t['frame']['median']:.1f} ({t['frame']['p95']:.1f})",
                 f"{t['fps']:.0f}", "-" if inf is None else f"{inf:.1f}", "-" if psnr is None else f"{psnr:.2f}",
                 fmt_spp(r), "-" if speed is None else f"{speed:.1f}"]
        out.append("| " + " | ".join(cells) + " |")
    pt = bench["path_tracer_ms"]
    for res, by_spp in pt.items():
        cells = ", ".join(f"{spp} spp {ms:,.0f} ms" for spp, ms in by_spp.items())
        out.append(f"| path tracer | {res} | {cells} | | | | | |")
    return out


def page(scenes: dict) -> str:
    out = ["# Results", "",
           "Written by `python tools/make_results.py` from the files it names; do not edit by hand. How to read each",
           "column: [evaluation.md](evaluation.md).", "", "## Headline", ""]
    out += headline(scenes)
    out += ["", "## The shipped models per split", ""]
    for name, s in scenes.items():
        card, ev = s["card"], s["eval"]
        out += [f"### {name}", ""] + wrap(
                f"`assets/models/{name}.onnx`: K = {card['K']}, {card['precision']} arithmetic on weights stored as "
                f"{card['weights']}, {s['mb']:.1f} MB, trained at {card['resolution'][0]}x{card['resolution'][1]} "
                f"(the weights of step {card['steps']:,}; rebuild: `{card['rebuild']}`). Scored on the scene's full evaluation "
                f"set at {ev['reference_spp']} spp ({s['src']['eval']}; `diviewer eval` records no machine in it).") + [""]
        out += split_table(s)
        out += ["", f"#### The K ladder of {name}", ""]
        out += ladder_table(card)
        out.append("")
    evs = [e for s in scenes.values() for sp in s["shown"]["splits"].values() if "ev_min" in sp.get("exposure", {})
           for e in (sp["exposure"]["ev_min"], sp["exposure"]["ev_max"])]
    out += ["## At the exposure the viewer shows", ""] + wrap(
        "The tone-mapped figures above are at each evaluation set's one exposure, fitted to its lit direct light. The "
        "viewer shows cornell at its scene's fixed exposure, about that one, but meters each frame of Sponza (auto "
        f"exposure): its frames are shown {min(evs):+.1f} to {max(evs):+.1f} stops bright, and their shade, dark at "
        "the set's exposure, fills the screen. The shipped compact sets scored so (`diviewer eval --model "
        "assets/models/SCENE.onnx --exposure ...`; the noise floor is a second 1024-spp render of the truth, the best "
        "any model can score there):") + ["", "| scene | exposure | split | model | direct light | noise floor |",
                                          "| --- | --- | --- | --- | --- | --- |"]
    for name, s in scenes.items():
        rel, option, how = s["src"]["shown"]
        where = f"{how}: `{option}` ([JSON]({Path(rel).relative_to('docs').as_posix()}))"
        for key, split in s["shown"]["splits"].items():
            cells = [db(mean(split, m, "psnr_tm")) for m in (s["card"]["scene"], "direct", "noise_floor")]
            out.append(f"| {name} | {where} | {SPLITS.get(key, key)} | " + " | ".join(f"{c} dB" for c in cells) + " |")
            name = where = ""
    out += [""]
    out += ["## Speed", "",
            "`diviewer bench --scene S --res 128 256` per shipped scene: every method timed on the same frames,",
            "scored at the scene camera on the compact evaluation set. \"x path tracer\" is the path tracer's time at",
            "the same error divided by the row's.", ""]
    for name, s in scenes.items():
        b, rel = s["bench"], s["src"]["bench"]
        out += [f"### {name}", ""] + wrap(
            f"Machine: {machine_of(b['environment'])}. Measured {date_of(rel)}, {b['settings']['frames']} frames a "
            f"row. Data: [{rel}]({Path(rel).relative_to('docs').as_posix()}).") + [""]
        out += speed_table(b)
        out.append("")
    out += ["![error against frame time, cornell](../assets/figures/cornell_frontier.png)", "",
            "*Error against frame time (`diviewer bench --scene cornell --plot`).*", "",
            "## The records", "",
            f"The long records left the tree; git keeps them. Each is at commit {RECORD_COMMIT}:", ""]
    out += [f"- {what}: the record at commit {RECORD_COMMIT}, {path}" for what, path in RECORDS]
    return "\n".join(out) + "\n"


def readme_with(text: str, table: list[str]) -> str:
    """The README with the lines between its markers replaced by the headline table."""
    i, j = text.index(BEGIN), text.index(END)
    return text[:i + len(BEGIN)] + "\n" + "\n".join(table) + "\n" + text[j:]


def build() -> dict[str, str]:
    """{relative path: the text it must hold}."""
    scenes = {name: shipped(name) for name in SOURCES}
    readme = (ROOT / README).read_text(encoding="utf-8")
    return {PAGE: page(scenes), README: readme_with(readme, headline(scenes))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = ap.parse_args(argv)
    stale = []
    for rel, text in build().items():
        path = ROOT / rel
        if path.exists() and path.read_text(encoding="utf-8") == text:
            continue
        stale.append(rel)
        if not args.check:
            tmp = path.with_suffix(path.suffix + ".tmp")
            tmp.write_text(text, encoding="utf-8")
            tmp.replace(path)
    if args.check and stale:
        print("not what the data gives (run python tools/make_results.py): " + ", ".join(stale))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
