"""What each stage of `diviewer build` costs, from figures measured on this project's machines.

Every constant says where it was measured. They size `--budget` plans and the `--dry-run` estimate; they are
estimates (a loaded machine is slower; an accelerator shared with other jobs was slower than one alone), and
the progress bars report the real rate as the build runs.
"""

from __future__ import annotations

import ctypes.util
import math
import os
import shutil
from dataclasses import dataclass

PIXELS_REF = 128 * 128
"""The resolution every figure below was measured at."""

PT_SECONDS_PER_SAMPLE = {
    # 2-core CPU, Mitsuba llvm_ad_rgb (DESIGN.md, "Facts measured", 2026-11-24): cornell 128x128 at 256 spp 1.2 s.
    ("cpu", "cornell"): 1.2 / (PIXELS_REF * 256),
    # The same machine: Sponza 128x128 at 256 spp ~12 s (at 64 spp ~4 s). Linear in the samples: on the Intel
    # Xeon of 2026-12-03, 228x128 in one pass, 1.2-1.8 / 4.1-4.5 / 12.4-13.5 s at 16 / 64 / 192 spp (frames 0, 700
    # and 1,400 of the capture, the chain paused), 0.2 s at 1 spp. That machine traced ~1.45x slower a sample than the
    # Intel VMs of 2026-11-28 to 12-02, whose capture, refinement and evaluation set matched this figure.
    ("cpu", "sponza"): 12.0 / (PIXELS_REF * 256),
    # H100, cuda_ad_rgb (README, "The same recipes at full budget on an H100", 2026-11-23): 4,600 cornell frames
    # at 256 spp in 3 minutes with 4 shards.
    ("cuda", "cornell"): 180.0 / 4600 / (PIXELS_REF * 256),
    # The same lease (README, "The Sponza model"): Sponza at 512 spp (528 effective), about 3.5 frames/s, 8 shards.
    ("cuda", "sponza"): 1 / 3.5 / (PIXELS_REF * 528),
}
"""Seconds of path tracing per pixel per sample, by machine kind and scene; a scene not listed is costed as
Sponza (262k triangles, textured, alpha-masked: the heaviest measured)."""

ONE_PASS_SHARE = 0.55
"""The one-pass truth (`diviewer.reference.split_path`, 2026-11-28) takes 54-55 % of the time of the two passes the
figures above were measured with (Sponza 228x128 at 64 spp on the Intel 2-core: 3.1-4.2 s against 5.7-7.7 s;
docs/architecture.md). Frames with area lights still take two passes: their scenes are costed low by this share."""

FILTER_FRAME_SECONDS = 0.06
"""`diviewer data filter-truth` of one 228x128 frame, one level, its read and write included: 407 of Sponza's 64-spp
frames in 21 s on the Intel 2-core beside a capture (2026-12-02, runs/ab/filt64); a level more costs as much again
(`filter_levels`)."""


def filter_levels(filt) -> int:
    """A truth filter's cost in levels of `FILTER_FRAME_SECONDS`: its levels, and one more for a range term's guide
    (one level of geometry alone). The filter alone on a 228x128 frame, the AMD EPYC 2-core (2026-12-04): 0.061 s at
    one level, 0.116 at two, 0.190 at two with the range term (its per-tap weights add ~0.01 s a level)."""
    return filt.levels + (1 if filt.range_sigma else 0)

GL_SECONDS_PER_FRAME = {"cpu": 0.05, "cuda": 0.0}
"""The GL inputs of one 128x128 frame: +0.05 s on the 2-core CPU's llvmpipe (README, "Training on VXGI instead
of path tracing"); on the H100 the capture figures above include them."""

GL_AREA_SECONDS_PER_PASS = {"cpu": (0.4775 - 0.05 * 228 * 128 / PIXELS_REF) / 16 / (228 * 128 / PIXELS_REF),
                            "cuda": 0.0}
"""The direct light over each pixel's area (`diviewer.gl.area`), per 128x128 pass of its s x s: Sponza's 2026-12-03
capture read 0.4775 s of GL a 228x128 frame with s = 4 (the median of its first 1,819 frames' sidecars,
`seconds.gl`), the G-buffer's share above taken out: 0.014 s a pass. Costed at the G-buffer's 0.05 s a pass before,
that capture planned 1.5 s of GL a frame."""

EVALSET_MEASURED = {
    # Cornell's evaluation set (24 + 24 frames, 1024 spp twice, ladder 1..256) took about 70 minutes on the 2-core
    # CPU, in two passes: several times what the capture figures predict (float32 frames, the
    # direct-only render at 1024 spp of its area light, the exposure fit).
    "cornell": {"kind": "cpu", "frames": 48, "spp": 1024, "ladder": (1, 4, 16, 64, 256), "width": 128,
                "height": 128, "seconds": 70 * 60, "one_pass": False},
    # Sponza's full set (2026-11-28, the Intel 2-core, one pass): 113.2 s a frame at 228x128, the median of the 11
    # frames rendered with nothing else running (06:11-06:30 UTC; the frames' sidecars, `seconds.gt`), within
    # 3 % of what the capture figures predict. Cornell's ratio, applied to it, had planned 851 s a frame.
    "sponza": {"kind": "cpu", "frames": 1, "spp": 1024, "ladder": (1, 4, 16, 64, 256), "width": 228, "height": 128,
               "seconds": 113.2, "one_pass": True},
}
"""Evaluation sets as measured, per scene: each scene's sets are costed with the ratio of its measured time to what
its samples predict (`EVALSET_FACTOR`); a scene not listed with Sponza's, as its path tracing is."""

SPONZA_LADDER_PIXELS = (72 + 227) / 2 * 128
"""The mean pixels of a training frame of Sponza's ladder: 228x128 frames cut to aspect crops 0.5625-1.78 wide
(`train_pixels`), 72 to 227 columns drawn uniformly."""

TRAIN_SECONDS_PER_STEP = {
    # 2-core Intel Xeon, one torch thread, float32, batch 4, no discriminator: Sponza's ladder on its 256-spp truth,
    # 45,900 steps each, its training time alone (docs/sponza.md at commit c48f1bc, "The ladder's first two rungs", 2026-12-02):
    # K = 8 4,043 s and K = 16 5,186 s, brought to 128x128 from the crops' mean pixels. Planned before from the
    # cornell ladder's 3,544 and 5,911 s as if at 128x128, its 228x128 frames' crops counted whole: the plan read
    # K = 8 1 h 36 and K = 16 2 h 41 for Sponza's 1.1 and 1.4 h.
    ("cpu", 8): 4043.0 / 45900 * PIXELS_REF / SPONZA_LADDER_PIXELS,
    ("cpu", 16): 5186.0 / 45900 * PIXELS_REF / SPONZA_LADDER_PIXELS,
}
"""Seconds per training step at batch 4, 128x128, without a discriminator, by machine kind and K."""

CPU_WIDE_K_STEP_RATIO = 9774.0 / 5186.0
"""On the CPU, a training step's time per doubling of K above 16: Sponza's ladder (above) took 9,774 s for K = 32
against K = 16's 5,186 (1.88x); `tools/experiments/train_speed.py --data runs/sponza/data --recipe
assets/recipes/sponza.toml --k K` had measured 2.0-2.2x (1.6x from 8 to 16; 2-core Intel Xeon, 2026-11-29;
docs/data/train_speed_k/), not the 4x of the convolutions' work: the wider layers keep the cores busier. Planned at
4x before that, Sponza's K = 32 read ~11 h where it takes ~3."""

CUDA_STEPS_PER_SECOND = {8: 17.0, 128: 7.0}
"""H100, batch 16, 128x128, bf16, seven trainings sharing the GPU beside a capture (README, device lease of
2026-11-23: "7-17 steps/s each"): the fastest rate for the smallest K, the slowest for the largest."""

GAN_STEP_FACTOR = 2.0
"""A step with the discriminator costs twice one without (README, "The neural GI model": `--gan-weight 0`
halves the CPU step time)."""

EXPORT_EVAL_ALLOWANCE = 60.0
"""Seconds allowed per K for export (with its verification) and the test-split evaluation: not measured as a
stage; an allowance so the plan's total is not short of them."""


@dataclass(frozen=True)
class Machine:
    """What this machine trains and renders on, as the cost model sees it."""

    kind: str
    """"cuda" where a CUDA driver is present (Mitsuba cuda_ad_rgb, torch CUDA), else "cpu"."""
    cpus: int
    """CPU cores."""
    why: str
    """How it was told (one line for the plan)."""


def detect_machine() -> Machine:
    """The machine kind without importing torch or Mitsuba: a CUDA driver library or nvidia-smi means CUDA."""
    cpus = os.cpu_count() or 1
    if ctypes.util.find_library("cuda") or shutil.which("nvidia-smi"):
        return Machine("cuda", cpus, "a CUDA driver is present: Mitsuba cuda_ad_rgb and torch CUDA where they run")
    return Machine("cpu", cpus, f"no CUDA driver: Mitsuba llvm_ad_rgb (or scalar_rgb) and torch on {cpus} CPU cores")


def pt_seconds_per_sample(kind: str, scene: str) -> tuple[float, str]:
    """Path-tracing seconds per pixel-sample, and which measurement it is."""
    key = (kind, scene) if (kind, scene) in PT_SECONDS_PER_SAMPLE else (kind, "sponza")
    return PT_SECONDS_PER_SAMPLE[key], f"{key[1]} on {kind}"


def capture_seconds(kind: str, scene: str, frames: int, width: int, height: int, spp: int,
                    direct_samples: int = 1) -> float:
    """A capture of ``frames`` frames: path tracing (full and direct-only, counted in the measurements, in one pass
    now: ``ONE_PASS_SHARE``) + GL, and with ``direct_samples`` s > 1 the direct light rendered again at s x s the
    pixels (`diviewer.gl.area`)."""
    scale = width * height / PIXELS_REF
    area = GL_AREA_SECONDS_PER_PASS[kind] * direct_samples ** 2 if direct_samples > 1 else 0.0
    gl = scale * (GL_SECONDS_PER_FRAME[kind] + area)
    return refine_seconds(kind, scene, frames, width, height, spp) + frames * gl


def refine_seconds(kind: str, scene: str, frames: int, width: int, height: int, extra_spp: int) -> float:
    """Path tracing ``frames`` frames at ``extra_spp`` samples a pixel in one pass: `diviewer data refine`, and a
    capture's truth."""
    per_sample, _ = pt_seconds_per_sample(kind, scene)
    return frames * per_sample * ONE_PASS_SHARE * width * height * extra_spp


def _evalset_predicted(kind: str, scene: str, frames: int, width: int, height: int, spp: int,
                       ladder: tuple[int, ...]) -> float:
    return capture_seconds(kind, scene, frames, width, height, 2 * spp + sum(ladder))


def _evalset_factor(m: dict, scene: str) -> float:
    predicted = _evalset_predicted(m["kind"], scene, m["frames"], m["width"], m["height"], m["spp"], m["ladder"])
    # a set measured in two passes, against the one-pass prediction (its GL share left in the one-pass share)
    return (1.0 if m["one_pass"] else ONE_PASS_SHARE) * m["seconds"] / predicted


EVALSET_FACTOR = {scene: _evalset_factor(m, scene) for scene, m in EVALSET_MEASURED.items()}
"""Per scene, how much longer an evaluation set took than its samples predict (see `EVALSET_MEASURED`)."""


def evalset_seconds(kind: str, scene: str, frames: int, width: int, height: int, spp: int,
                    ladder: tuple[int, ...]) -> float:
    """An evaluation set of ``frames`` frames (both splits): two renders at ``spp``, the ladder, the direct light."""
    factor = EVALSET_FACTOR.get(scene, EVALSET_FACTOR["sponza"])
    return factor * _evalset_predicted(kind, scene, frames, width, height, spp, ladder)


def train_pixels(width: int, height: int, aspect_crops: tuple[float, float] | None = None) -> float:
    """The mean pixels a training step sees of each frame: the whole frame, or with ``aspect_crops`` the mean of
    the crop widths the trainer draws uniformly (`diviewer.train.targets.crop_widths`) times the height."""
    if not aspect_crops:
        return float(width * height)
    from diviewer.train.targets import crop_widths

    return sum(crop_widths(aspect_crops, height, width)) / 2 * height


def train_step_seconds(kind: str, K: int, batch_size: int, width: int, height: int, gan: bool,
                       aspect_crops: tuple[float, float] | None = None) -> float:
    """One training step on frames of ``width`` x ``height`` (cut to ``aspect_crops``: `train_pixels`). On the CPU:
    the two measured widths, a power law between and below them, and `CPU_WIDE_K_STEP_RATIO` a doubling above
    K = 16; on CUDA: the shared H100 rates, log-interpolated in K."""
    scale = train_pixels(width, height, aspect_crops) / PIXELS_REF * (GAN_STEP_FACTOR if gan else 1.0)
    if kind == "cuda":
        (k0, r0), (k1, r1) = sorted(CUDA_STEPS_PER_SECOND.items())
        t = min(max(math.log(K / k0) / math.log(k1 / k0), 0.0), 1.0)
        rate = r0 * (r1 / r0) ** t
        return scale * batch_size / 16 / rate * (K / k1) ** 2 if K > k1 else scale * batch_size / 16 / rate
    s8, s16 = TRAIN_SECONDS_PER_STEP[("cpu", 8)], TRAIN_SECONDS_PER_STEP[("cpu", 16)]
    per = s16 * (K / 16) ** math.log2(CPU_WIDE_K_STEP_RATIO) if K > 16 else s8 * (K / 8) ** math.log2(s16 / s8)
    return scale * batch_size / 4 * per
