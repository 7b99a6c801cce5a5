"""Build both scenes' models in one accelerator lease: captures, Sponza's evaluation set, K ladders, export, eval.

Usage (on a CUDA machine, after tools/device_lease.sh has installed Mitsuba and the GL loader):
  python tools/device_build.py --work /tmp/dv [--minutes 20] [--smoke]

One lease of the device tool is at most 30 minutes, so every stage has a deadline (minutes after the
start) and the work runs side by side: capture shards of both scenes at once (Mitsuba cuda_ad_rgb, GL on
the GPU through EGL), then the trainings of all ladders at once on the one GPU. A stage that reaches
its deadline is interrupted the way a user would (SIGINT): a capture keeps every finished frame and a
training saves last.ckpt, its best.ckpt being the best validation so far; the record says which runs
stopped there and at what step. Every stage resumes (run the same command again): captures skip
finished frames, trainings continue from last.ckpt.

The runs (one recipe for all, the winner of the README's ablations, with a cosine learning-rate decay):
  cornell: K = 8, 16, 32, 64, 128 (resize decoder), plus K=16 with the paper's transposed decoder and
           K=16 transposed + GAN (the paper's loss), the ablations at the full budget;
  sponza:  K = 8, 16, 32, 64, 128 (resize decoder).
Each is exported (fp16) and scored on its capture's test split; Sponza's K are also scored on its own
evaluation set (``diviewer evalset``, 2048 spp, with a ladder that includes the capture's spp, so the
training data's own error shows beside the models'). ``work/record.json`` gathers it all; the shipped
choice (smallest K within 0.5 dB of the best, tone-mapped test PSNR) is made from it by
tools/ship_ladder.py on the developer's machine.
--smoke runs the same stages at toy size on a CPU (llvm_ad_rgb, Mesa) into --work, in a few minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

RECIPE = ["--target", "indirect", "--divide-albedo", "--norm", "batch", "--gan-weight", "0", "--lr", "2e-4",
          "--lr-decay", "cosine", "--patience", "0", "--seed", "0", "--precision", "fp32"]
"""Every run's training settings (a run adds --k, --upsample and, for the paper's loss, --gan-weight 1).
float32: the lease of 2026-11-23 trained with bf16 autocast (the default on CUDA), and every cornell model of
it came out below the float32 CPU model on the evaluation set; bf16 is one of the suspects."""


@dataclass
class Scene:
    name: str
    frames: int
    spp: int
    splits: str
    shards: int
    steps: int
    """Training steps of every run of the ladder (the horizon of the cosine decay)."""
    runs: dict[str, list[str]]
    evalset_spp: int = 0
    """0: no evaluation set rendered here (cornell's is made on the CPU: `diviewer evalset`)."""


@dataclass
class Job:
    name: str
    argv: list[str]
    log: Path
    proc: subprocess.Popen | None = None
    started: float = 0.0
    ended: float | None = None
    interrupted: bool = False
    env: dict = field(default_factory=dict)

    def start(self) -> None:
        self.log.parent.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "2", **self.env}
        f = self.log.open("a")
        f.write(f"\n+ {' '.join(self.argv)}\n")
        f.flush()
        # A process group of its own: SIGINT at a deadline reaches the job and nothing else.
        self.proc = subprocess.Popen(self.argv, stdout=f, stderr=subprocess.STDOUT, env=env, cwd=ROOT,
                                     start_new_session=True)
        self.started = time.time()

    @property
    def running(self) -> bool:
        if self.proc is None or self.ended is not None:
            return False
        if self.proc.poll() is not None:
            self.ended = time.time()
            return False
        return True

    @property
    def rc(self) -> int | None:
        return None if self.proc is None else self.proc.poll()

    def interrupt(self) -> None:
        if self.running:
            self.interrupted = True
            os.killpg(self.proc.pid, signal.SIGINT)

    def record(self) -> dict:
        return {"argv": self.argv[2:], "rc": self.rc, "seconds": round((self.ended or time.time()) - self.started, 1)
                if self.started else None, "interrupted_at_deadline": self.interrupted}


def diviewer(*args: str) -> list[str]:
    return [sys.executable, "-m", "diviewer", *args]


class Build:
    def __init__(self, work: Path, scenes: list[Scene], deadlines: dict[str, float], res: int, smoke: bool):
        self.work, self.scenes, self.deadlines, self.res, self.smoke = work, scenes, deadlines, res, smoke
        self.t0 = time.time()
        self.jobs: dict[str, Job] = {}
        self.record: dict = {"started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime()),
                             "machine": machine(), "deadlines_min": deadlines, "res": res, "recipe": RECIPE,
                             "scenes": {s.name: {k: v for k, v in vars(s).items() if k != "runs"} for s in scenes}}

    def minutes(self) -> float:
        return (time.time() - self.t0) / 60

    def say(self, text: str) -> None:
        print(f"[{self.minutes():5.1f} min] {text}", flush=True)

    def job(self, name: str, argv: list[str], **env) -> Job:
        j = Job(name, argv, self.work / "logs" / f"{name}.log", env={k: str(v) for k, v in env.items()})
        self.jobs[name] = j
        j.start()
        self.say(f"start {name}")
        return j

    def wait(self, names: list[str], deadline: str | None) -> None:
        """Until every named job has ended; at the deadline, interrupt those still running (then wait)."""
        limit = self.deadlines.get(deadline) if deadline else None
        warned = False
        last = 0.0
        while any(self.jobs[n].running for n in names):
            if limit is not None and self.minutes() >= limit and not warned:
                warned = True
                for n in names:
                    if self.jobs[n].running:
                        self.say(f"deadline {deadline} ({limit} min): interrupting {n}")
                        self.jobs[n].interrupt()
            if time.time() - last > 60:
                last = time.time()
                self.status()
            time.sleep(2)
        for n in names:
            j = self.jobs[n]
            if j.rc not in (0, 130) and not j.interrupted:
                self.say(f"{n} failed (rc {j.rc}); see {j.log}")

    def status(self) -> None:
        parts = []
        for s in self.scenes:
            frames = self.work / s.name / "data" / "frames"
            if frames.is_dir():
                parts.append(f"{s.name} {sum(1 for _ in frames.glob('*.json'))}/{s.frames} frames")
            for r in s.runs:
                last = _last_row(self.work / s.name / f"train_{r}" / "metrics.csv")
                if last:
                    parts.append(f"{s.name}/{r} step {last['step']:.0f} val_psnr_tm {last.get('val_psnr_tm') or 0:.2f}")
        self.say("; ".join(parts) or "starting")
        self.save()

    def save(self) -> None:
        self.record["jobs"] = {n: j.record() for n, j in self.jobs.items()}
        self.record["minutes"] = round(self.minutes(), 2)
        (self.work / "record.json").write_text(json.dumps(self.record, indent=1))

    # -- stages ---------------------------------------------------------------------------------------

    def capture(self, s: Scene) -> list[str]:
        names = []
        for k in range(1, s.shards + 1):
            names.append(f"capture_{s.name}_{k}")
            self.job(names[-1], diviewer("capture", "--scene", s.name, "--frames", str(s.frames), "--res", str(self.res),
                                         "--spp", str(s.spp), "--splits", s.splits, "--seed", "0",
                                         "--shard", f"{k}/{s.shards}", "--out", str(self.work / s.name / "data")))
        return names

    def present(self, s: Scene, split: str) -> int:
        from diviewer.data.dataset import Dataset

        return len(Dataset(self.work / s.name / "data").indices(split))

    def train(self, s: Scene) -> list[str]:
        n_train = self.present(s, "train")
        batch = 4 if self.smoke else 16
        epochs = max(1, round(s.steps * batch / max(n_train, 1)))  # epochs x steps per epoch ~ s.steps
        val_every = max(1, s.steps // 10)
        self.record["scenes"][s.name].update(train_frames=n_train, val_frames=self.present(s, "val"),
                                             test_frames=self.present(s, "test"), epochs=epochs, batch_size=batch,
                                             val_every_steps=val_every)
        names = []
        for run, extra in s.runs.items():
            out = self.work / s.name / f"train_{run}"
            names.append(f"train_{s.name}_{run}")
            self.job(names[-1], diviewer("train", "--data", str(self.work / s.name / "data"), "--out", str(out),
                                         *RECIPE, "--batch-size", str(batch), "--epochs", str(epochs),
                                         "--val-every-steps", str(val_every),
                                         "--train-frames", str(n_train), *extra,
                                         *(["--resume"] if (out / "last.ckpt").is_file() else []),
                                         *(["--device", "cpu"] if self.smoke else [])))
        return names

    def export_and_eval(self, s: Scene) -> list[str]:
        names = []
        for run in s.runs:
            ckpt = self.work / s.name / f"train_{run}" / "best.ckpt"
            if not ckpt.is_file():
                self.say(f"{s.name}/{run}: no best.ckpt, nothing to export")
                continue
            model = self.work / s.name / "models" / f"{s.name}_{run}.onnx"
            model.parent.mkdir(parents=True, exist_ok=True)
            cmd = (f"{sys.executable} -m diviewer export {ckpt} --out {model} --fp16 && "
                   f"{sys.executable} -m diviewer eval --model {model} --data {self.work / s.name / 'data'} "
                   f"--split test --out {model.with_name(model.stem + '_test.json')}")
            names.append(f"export_{s.name}_{run}")
            self.job(names[-1], ["bash", "-c", cmd])
        return names

    def evalset(self, s: Scene) -> str:
        name = f"evalset_{s.name}"
        # The capture's own spp joins the ladder: the training data's error against the evaluation truth.
        ladder = ",".join(str(x) for x in sorted({x for x in (1, 4, 16, 64, 256) if x < s.evalset_spp} | {s.spp}))
        self.job(name, diviewer("evalset", "--scene", s.name, "--out", str(self.work / s.name / "evalset"),
                                "--res", str(self.res), "--spp", str(s.evalset_spp), "--ladder", ladder,
                                *(["--frames-per-split", "2"] if self.smoke else [])))
        return name

    def eval_on_evalset(self, s: Scene) -> str | None:
        models = sorted((self.work / s.name / "models").glob("*.onnx"))
        evalset = self.work / s.name / "evalset"
        if not models or not (evalset / "manifest.json").is_file():
            return None
        name = f"evaleval_{s.name}"
        argv = diviewer("eval", "--evalset", str(evalset), "--out", str(self.work / s.name / "evalset_eval.json"))
        for m in models:
            argv += ["--model", str(m)]
        self.job(name, argv)
        return name


def machine() -> dict:
    out = {"node": platform.node(), "cpus": os.cpu_count(), "python": platform.python_version()}
    try:
        out["gpu"] = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"],
                                    capture_output=True, text=True, timeout=20).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        out["gpu"] = None
    return out


def plan(smoke: bool) -> tuple[list[Scene], dict[str, float], int]:
    ladder = {f"k{k}": ["--k", str(k), "--upsample", "resize"] for k in (8, 16, 32, 64, 128)}
    paper = {"k16_transpose": ["--k", "16", "--upsample", "transpose"],
             "k16_paper": ["--k", "16", "--upsample", "transpose", "--gan-weight", "1"]}
    if smoke:
        small = {f"k{k}": ["--k", str(k), "--upsample", "resize"] for k in (4, 8)}
        return ([Scene("cornell", 12, 4, "0.5,0.25,0.25", 2, 4, {**small, "k4_transpose": ["--k", "4", "--upsample", "transpose"]}),
                 Scene("sponza", 8, 4, "0.5,0.25,0.25", 2, 4, small, evalset_spp=8)],
                {"capture_cornell": 4, "capture_sponza": 6, "train": 9}, 64)
    # Sized on the H100 lease of 2026-11-23: cornell's 4,600 frames took 3 min with 4 shards; Sponza at 512 spp
    # ran at ~3.5 frames/s with 8 shards (~2.3 s a frame each, the GPU full); seven trainings beside the Sponza
    # capture ran 7-17 steps/s each, so the step budgets are what fits, and a run's cosine decay completes.
    return ([Scene("cornell", 4600, 256, "0.87,0.065,0.065", 4, 5000, {**ladder, **paper}),
             Scene("sponza", 3450, 512, "0.88,0.06,0.06", 8, 3200, ladder, evalset_spp=2048)],
            {"capture_cornell": 5.0, "capture_sponza": 14.5, "train": 22.5}, 128)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--smoke", action="store_true")
    ap.add_argument("--stretch", type=float, default=1.0, help="multiply every deadline (a faster or slower lease)")
    ap.add_argument("--post-only", action="store_true",
                    help="only export and evaluate the runs there (after trainings run by hand or interrupted)")
    a = ap.parse_args()
    scenes, deadlines, res = plan(a.smoke)
    deadlines = {k: v * a.stretch for k, v in deadlines.items()}
    a.work.mkdir(parents=True, exist_ok=True)
    b = Build(a.work, scenes, deadlines, res, a.smoke)
    cornell, sponza = scenes
    if not a.post_only:
        b.say(f"plan: {json.dumps(b.record['scenes'])}; deadlines {deadlines}")
        cap_c, cap_s = b.capture(cornell), b.capture(sponza)
        b.wait(cap_c, "capture_cornell")
        train_c = b.train(cornell)
        ev = b.evalset(sponza)  # on the GPU beside cornell's trainings; its 2048 spp truth scores the Sponza ladder
        b.wait(cap_s, "capture_sponza")
        train_s = b.train(sponza)
        b.wait([ev], "train")
        b.wait(train_c + train_s, "train")
        b.say("trainings ended; export and evaluation")
    else:
        old = a.work / "record.json"
        if old.is_file():  # keep what the interrupted build recorded (its jobs, the plan)
            prev = json.loads(old.read_text())
            b.record["earlier"] = {k: prev.get(k) for k in ("started", "jobs", "scenes", "deadlines_min")}
        for s in scenes:
            b.record["scenes"][s.name]["present"] = {sp: b.present(s, sp) for sp in ("train", "val", "test")}
    b.wait(b.export_and_eval(cornell) + b.export_and_eval(sponza), None)
    last = b.eval_on_evalset(sponza)
    if last:
        b.wait([last], None)
    b.record["runs"] = {}
    for s in scenes:
        for run in s.runs:
            d = a.work / s.name / f"train_{run}"
            ckpt = d / "best.ckpt"
            res_json = a.work / s.name / "models" / f"{s.name}_{run}_test.json"
            b.record["runs"][f"{s.name}/{run}"] = {
                "last_row": _last_row(d / "metrics.csv"),
                "test": json.loads(res_json.read_text()) if res_json.is_file() else None,
                "best_ckpt": ckpt.is_file()}
    b.save()
    b.say(f"done in {b.minutes():.1f} min: {a.work / 'record.json'}")


def _last_row(path: Path) -> dict | None:
    from diviewer.train.report import read_metrics

    rows = read_metrics(path)
    return rows[-1] if rows else None


if __name__ == "__main__":
    main()
