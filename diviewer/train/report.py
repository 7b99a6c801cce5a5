"""Validation and what a person reads of a run: per-frame metrics of the composed image against the
path tracer, metrics.csv (one row per validation or stop), curves.png and a ladder's curves side by side."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from diviewer import imageio
from diviewer.metrics import tonemap
from diviewer.train.config import TrainConfig
from diviewer.train.targets import compose_radiance, split_batch

if TYPE_CHECKING:
    from diviewer.contract.encoding import Encoding

METRIC_KEYS: tuple[str, ...] = ("mse", "psnr", "ssim", "mse_tm", "psnr_tm", "ssim_tm")
"""Validation metrics: on linear radiance, then on tone-mapped images (suffix _tm)."""

CSV_COLUMNS: tuple[str, ...] = ("epoch", "step", "loss_D", "loss_G_GAN", "loss_G_L1", "loss_G_SSIM", "D_acc_real",
                                "D_acc_fake",
                                *(f"val_{k}" for k in METRIC_KEYS), "seconds")
"""metrics.csv columns: fractional epoch, global step, mean train losses over the epoch so far
(loss_G_L1: the reconstruction term, L1 or L2, already times lambda_L1, as pix2pix reports it; loss_G_SSIM: the
structure term times lambda_L1 and ssim_weight, empty without it;
loss_G_GAN unweighted), netD's accuracy on real and on generated pairs over the same steps (0.5:
at chance; the adversarial columns are empty when gan_weight is 0), validation metrics (empty when
not validated) and wall-clock seconds since the run began (summed over resumed parts)."""


def validate(netG, val: np.ndarray, slices: Mapping[str, slice], enc: Encoding, cfg: TrainConfig, device,
             dtype=None, scales: np.ndarray | None = None, multiple: int = 1,
             tonemap_exposure: float | None = None, cams: np.ndarray | None = None,
             lights: np.ndarray | None = None) -> dict[str, float]:
    """Mean per-frame metrics of the composed image against the path-traced `pt`, netG in eval mode.

    Linear: MSE, PSNR (peak 1) and SSIM (data_range 1) on radiance as stored, as `diviewer.metrics`
    defines them. Tone-mapped (_tm): the same on `tonemap(x, enc.exposure)`. With target
    "indirect" the image is GL direct + predicted indirect, as the viewer composes it. dtype: the
    autocast dtype netG runs in (None: float32). scales: each val frame's light scale (encoding version
    2: the decoded output is multiplied by it). Frames are padded to ``multiple`` as the runtime pads them,
    and the metrics taken on the frame's own pixels. tonemap_exposure: the tone map's (default
    ``enc.exposure``; with encoding 2 the trainer passes the one fitted on the raw direct light, as eval fits it).
    cams: each val frame's camera (encoding version 3, `diviewer.train.targets.run_conditioning`); lights: its lights
    (encoding version 4, `diviewer.train.targets.run_conditioning`).
    """
    import torch

    from diviewer import metrics
    from diviewer.train.encoding_torch import decode_radiance

    was_training = netG.training
    netG.eval()
    sums = dict.fromkeys(METRIC_KEYS, 0.0)
    with torch.no_grad():
        for start in range(0, len(val), cfg.batch_size):
            x16 = torch.from_numpy(val[start:start + cfg.batch_size]).to(device)
            scale = None if scales is None else torch.from_numpy(scales[start:start + cfg.batch_size])
            cam = None if cams is None else torch.from_numpy(cams[start:start + cfg.batch_size])
            lit = None if lights is None else torch.from_numpy(lights[start:start + cfg.batch_size])
            b = split_batch(x16, slices, enc, cfg, scale=scale, multiple=multiple, cams=cam, lights=lit)
            with torch.autocast(device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
                fake_B = netG(b["real_A"])
            radiance = decode_radiance(fake_B.float(), enc.output())
            if "scale" in b:
                radiance = radiance * b["scale"]
            pred = compose_radiance(radiance, b["direct"], b["albedo"], cfg.target, cfg.divide_albedo)
            rows, cols = b["crop"]
            pred = pred[:, :, rows, cols].permute(0, 2, 3, 1).cpu().numpy()
            truth = b["pt"][:, :, rows, cols].permute(0, 2, 3, 1).cpu().numpy()
            for p, t in zip(pred, truth):
                tm = enc.exposure if tonemap_exposure is None else tonemap_exposure
                p_tm, t_tm = tonemap(p, tm), tonemap(t, tm)
                sums["mse"] += metrics.mse(p, t)
                sums["psnr"] += metrics.psnr(p, t)
                sums["ssim"] += metrics.ssim(p, t)
                sums["mse_tm"] += metrics.mse(p_tm, t_tm)
                sums["psnr_tm"] += metrics.psnr(p_tm, t_tm)
                sums["ssim_tm"] += metrics.ssim(p_tm, t_tm)
    netG.train(was_training)
    return {k: float(v / len(val)) for k, v in sums.items()}


def read_metrics(path: Path) -> list[dict[str, float | None]]:
    """metrics.csv rows as dicts of floats (None where a row has no value)."""
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return [{k: (float(v) if v not in ("", None) else None) for k, v in row.items()} for row in csv.DictReader(f)]


def write_metrics(path: Path, rows: list[dict[str, Any]]) -> None:
    def cell(v: Any) -> str:
        return "" if v is None else (f"{v:.8g}" if isinstance(v, float) else str(v))

    lines = [",".join(CSV_COLUMNS)] + [",".join(cell(r.get(c)) for c in CSV_COLUMNS) for r in rows]
    imageio.write_text(path, "\n".join(lines) + "\n")


def draw_curves(rows: list[Mapping[str, Any]], path: Path, best_epoch: float | None = None,
                stop_epoch: float | None = None) -> None:
    """curves.png: validation MSE and SSIM per epoch (linear and tone-mapped), the train losses and
    netD's accuracy; a grey line marks the best validation, a red one where early stopping stopped."""
    panels = [
        ("validation MSE (log)", [("linear", "val_mse"), ("tone-mapped", "val_mse_tm")], True),
        ("validation SSIM", [("linear", "val_ssim"), ("tone-mapped", "val_ssim_tm")], False),
        ("train losses (log)", [("D", "loss_D"), ("G GAN", "loss_G_GAN"), ("G rec", "loss_G_L1"),
                                ("G SSIM", "loss_G_SSIM")], True),
        ("netD accuracy (0.5: chance)", [("real", "D_acc_real"), ("fake", "D_acc_fake")], False),
    ]
    no_netD = "no discriminator (--gan-weight 0)" if any(r.get("loss_G_L1") is not None for r in rows) else None
    _draw_panels([(title, [(label, _series(rows, "epoch", key, log_y)) for label, key in series], log_y,
                   no_netD if title.startswith("netD") else None) for title, series, log_y in panels],
                 path, "epoch", [(best_epoch, (150, 150, 150), "best"), (stop_epoch, (214, 39, 40), "stop")])


def draw_ladder_curves(runs: Mapping[str, list[Mapping[str, Any]]], path: Path) -> None:
    """SCENE_ladder_curves.png: each K of a ladder (``runs``: its label -> its metrics.csv rows) on one budget,
    per training step: validation PSNR and SSIM on tone-mapped frames and the train reconstruction loss, so the
    widths read side by side where each run's curves.png shows one."""
    panels = [("validation PSNR, tone-mapped (dB)", "val_psnr_tm", False),
              ("validation SSIM, tone-mapped", "val_ssim_tm", False),
              ("train reconstruction loss (log)", "loss_G_L1", True)]
    _draw_panels([(title, [(label, _series(rows, "step", key, log_y)) for label, rows in runs.items()], log_y, None)
                  for title, key, log_y in panels], path, "step", [])


def _series(rows: list[Mapping[str, Any]], x_key: str, key: str, log_y: bool) -> list[tuple[float, float]]:
    """The finite (x, y) points of column ``key`` against ``x_key`` (y as log10 on a log panel)."""
    p = [(float(r[x_key]), float(r[key])) for r in rows
         if r.get(key) is not None and math.isfinite(float(r[key])) and (not log_y or float(r[key]) > 0)]
    return [(x, math.log10(y) if log_y else y) for x, y in p]


def _draw_panels(panels: list[tuple[str, list[tuple[str, list[tuple[float, float]]]], bool, str | None]],
                 path: Path, x_label: str, marks: list[tuple[float | None, tuple[int, int, int], str]]) -> None:
    """Panels side by side, each (title, [(legend label, points)], log y, what to say when it has no points: a
    panel that does not apply, or None for "no data yet"), with vertical ``marks`` (x, colour, label) on each;
    written atomically as a PNG."""
    from PIL import Image, ImageDraw, ImageFont

    colors = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (148, 103, 189)]
    pw, ph, ml, mr, mt, mb = 420, 330, 64, 14, 42, 38
    img = Image.new("RGB", (pw * len(panels), ph), "white")
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default()
    for k, (title, series, log_y, empty) in enumerate(panels):
        x0, x1, y0, y1 = k * pw + ml, (k + 1) * pw - mr, mt, ph - mb
        draw.text((k * pw + ml, 6), title, fill="black", font=font)
        draw.rectangle([x0, y0, x1, y1], outline="black")
        allp = [q for _, p in series for q in p]
        if not allp and empty:  # a panel that does not apply to the run: a sentence, no legend
            draw.text((x0 + 10, (y0 + y1) // 2), empty, fill="gray", font=font)
            continue
        lx = x0  # the legend: one row between the title and the plot, every series named, with points or not
        for j, (label, _) in enumerate(series):
            draw.line([lx, 28, lx + 16, 28], fill=colors[j % len(colors)], width=2)
            draw.text((lx + 20, 22), label, fill="black", font=font)
            lx += 20 + int(draw.textlength(label, font=font)) + 18
        if not allp:
            draw.text((x0 + 10, (y0 + y1) // 2), "no data yet", fill="gray", font=font)
            continue
        xlo, xhi = min(q[0] for q in allp), max(q[0] for q in allp)
        ylo, yhi = min(q[1] for q in allp), max(q[1] for q in allp)
        if xhi - xlo < 1e-9:
            xlo, xhi = xlo - 0.5, xhi + 0.5
        pad = (yhi - ylo) * 0.05 or (0.5 if log_y else max(abs(ylo) * 0.05, 1e-3))
        ylo, yhi = ylo - pad, yhi + pad

        def to_px(x: float, y: float) -> tuple[float, float]:
            return (x0 + (x - xlo) / (xhi - xlo) * (x1 - x0), y1 - (y - ylo) / (yhi - ylo) * (y1 - y0))

        for i in range(5):
            fx = xlo + (xhi - xlo) * i / 4
            fy = ylo + (yhi - ylo) * i / 4
            px, _ = to_px(fx, ylo)
            _, py = to_px(xlo, fy)
            draw.line([px, y1, px, y1 + 4], fill="black")
            draw.text((px - 10, y1 + 6), f"{fx:,.0f}" if abs(fx) >= 1000 else f"{fx:.3g}", fill="black", font=font)
            draw.line([x0 - 4, py, x0, py], fill="black")
            draw.text((k * pw + 4, py - 6), f"{10 ** fy if log_y else fy:.3g}", fill="black", font=font)
        draw.text(((x0 + x1) // 2 - 14, ph - 14), x_label, fill="black", font=font)
        for mark, color, label in marks:
            if mark is not None and xlo <= mark <= xhi:
                px, _ = to_px(mark, ylo)
                draw.line([px, y0, px, y1], fill=color, width=1)
                draw.text((px + 3, y0 + 3), label, fill=color, font=font)
        for j, (_, p) in enumerate(series):
            color = colors[j % len(colors)]
            xy = [to_px(x, y) for x, y in p]
            if len(xy) > 1:
                draw.line(xy, fill=color, width=2)
            for px, py in xy:
                draw.ellipse([px - 2, py - 2, px + 2, py + 2], fill=color)
    with imageio.atomic_path(path) as tmp:
        img.save(tmp, format="PNG")
