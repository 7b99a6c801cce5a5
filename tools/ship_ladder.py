"""Pick a scene's default K from a K ladder trained by tools/device_build.py, and record the ladder.

Usage: python tools/ship_ladder.py SCENE --results RESULTS [--ship] [--tolerance 0.5]

RESULTS is the unpacked results.tar.gz of tools/device_pack.sh (record.json, SCENE/models/*_test.json,
SCENE/train_*/metrics.csv and curves.png, SCENE/evalset_eval.json) with the models that came back beside
it (RESULTS/SCENE_k*.onnx). The rule (issue 18): among the resize-decoder runs k8, k16, ... the smallest K
whose tone-mapped PSNR on the capture's test split is within --tolerance dB of the best K's.

Writes assets/models/SCENE_ladder.json: per K the parameters, steps, test-split and (where rendered)
evaluation-set metrics, and the choice with its reason. With --ship it also copies the chosen model
(which must have come back) to assets/models/SCENE.onnx with its card (the ladder added), curves and
metrics.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from diviewer.bench.frontier import smallest_sufficient_k  # noqa: E402  (the bench's rule, the same K)

MODELS = ROOT / "assets" / "models"
QUALITY = ("psnr", "ssim", "psnr_tm", "ssim_tm")


def generator_parameters(k: int) -> int:
    """netG's parameter count at width K (the 128x128 U-Net every shipped model uses)."""
    from diviewer.train.networks import NetConfig

    return sum(p.numel() for p in NetConfig(K=k, resolution=128, upsample="resize").build_generator().parameters())


def evalset_rows(results: Path, scene: str) -> dict[str, dict]:
    """Per model stem and split: the evaluation set's tone-mapped figures (absent where none was rendered)."""
    path = results / scene / "evalset_eval.json"
    if not path.is_file():
        return {}
    d = json.loads(path.read_text())
    rows: dict[str, dict] = {"_meta": {"reference_spp": d["reference_spp"], "ladder_spp": d["ladder_spp"],
                                       "tonemap_exposure": d["tonemap_exposure"]}}
    for split, r in d["splits"].items():
        for key, m in r["methods"].items():
            row = {q: m[q]["mean"] for q in QUALITY if q in m}
            row.update(flip_ldr=m["flip_ldr"]["mean"], checkerboard=m.get("checkerboard"),
                       equivalent_spp=m["equivalent_spp"]["psnr_tm"]["text"])
            rows.setdefault(key, {})[split] = row
    return rows


def ladder(results: Path, scene: str, ablations: bool = False) -> list[dict]:
    """The runs kN (the ladder, resize decoder) or, with ``ablations``, the others (kN_transpose, ...)."""
    record = json.loads((results / "record.json").read_text())
    ev = evalset_rows(results, scene)
    out = []
    for name, run in sorted(record["runs"].items()):
        s, _, tag = name.partition("/")
        m = re.fullmatch(r"k(\d+)(_\w+)?", tag)
        if s != scene or not m or not run.get("test") or bool(m.group(2)) != ablations:
            continue
        k, test = int(m.group(1)), run["test"]
        row = {"run": tag, "K": k, "parameters": generator_parameters(k), "steps": int(run["last_row"]["step"]),
               "test_split": {"frames": test["frames"], "reference_spp": test["reference_spp"],
                              **{meth: {q: test["methods"][meth][q]["mean"] for q in QUALITY}
                                 for meth in ("neural", "direct")}},
               "model_came_back": (results / f"{scene}_{tag}.onnx").is_file()}
        if f"{scene}_{tag}" in ev:
            row["evalset"] = ev[f"{scene}_{tag}"]
        out.append(row)
    return sorted(out, key=lambda r: r["K"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("--results", type=Path, required=True)
    ap.add_argument("--tolerance", type=float, default=0.5)
    ap.add_argument("--ship", action="store_true")
    ap.add_argument("--note", default=None, help="how the ladder was run, where it differs from device_build's plan")
    a = ap.parse_args()
    rows = ladder(a.results, a.scene)
    if not rows:
        sys.exit(f"{a.results}: no ladder runs of {a.scene} with test results")
    pick = smallest_sufficient_k({r["K"]: r["test_split"]["neural"]["psnr_tm"] for r in rows}, a.tolerance)
    best, chosen = pick["best_psnr"], next(r for r in rows if r["K"] == pick["K"])
    record = json.loads((a.results / "record.json").read_text())
    ev = evalset_rows(a.results, a.scene)
    out = {"scene": a.scene, "rule": f"smallest K whose tone-mapped test-split PSNR is within {a.tolerance} dB of the "
                                     f"best K's ({best:.2f} dB)",
           "chosen_K": chosen["K"], "machine": record["machine"], "capture": record["scenes"][a.scene],
           "evalset": ev.get("_meta"), "reference_rows": {k: v for k, v in ev.items() if not k.startswith(f"{a.scene}_")
                                                          and k != "_meta"},
           "rows": rows, "ablations": ladder(a.results, a.scene, ablations=True), **({"note": a.note} if a.note else {})}
    dst = MODELS / f"{a.scene}_ladder.json"
    dst.write_text(json.dumps(out, indent=1) + "\n")
    print(f"{dst}: K={chosen['K']} ({out['rule']})")
    for r in rows:
        t = r["test_split"]["neural"]
        print(f"  K={r['K']:<4} {r['parameters'] / 1e6:6.2f} M params  {r['steps']:>6} steps  test PSNR tm {t['psnr_tm']:.2f}"
              f"  SSIM tm {t['ssim_tm']:.3f}")
    if a.ship:
        src = a.results / f"{a.scene}_k{chosen['K']}.onnx"
        if not src.is_file():
            sys.exit(f"{src}: the chosen model did not come back from the device; nothing shipped")
        shutil.copyfile(src, MODELS / f"{a.scene}.onnx")
        card = json.loads((a.results / a.scene / "models" / f"{a.scene}_k{chosen['K']}.json").read_text())
        card["ladder"] = {"chosen_K": chosen["K"], "why": out["rule"], "file": dst.name}
        (MODELS / f"{a.scene}.json").write_text(json.dumps(card, indent=1) + "\n")
        run = a.results / a.scene / f"train_k{chosen['K']}"
        shutil.copyfile(run / "curves.png", MODELS / f"{a.scene}_curves.png")
        shutil.copyfile(run / "metrics.csv", MODELS / f"{a.scene}_metrics.csv")
        print(f"shipped {MODELS / f'{a.scene}.onnx'}")


if __name__ == "__main__":
    main()
