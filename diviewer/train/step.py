"""The pix2pix training step: the two networks, their optimizers and losses (`Nets`), and one update
of netD then netG (`train_step`), with the numbers a reader needs to see whether netD is at chance."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch

from diviewer.contract.encoding import Encoding
from diviewer.train.config import TrainConfig
from diviewer.train.distributed import Dist, seed_all
from diviewer.train.losses import LossConfig, structure_loss
from diviewer.train.networks import NetConfig, init_weights

STEP_KEYS: tuple[str, ...] = ("loss_D", "loss_G_GAN", "loss_G_L1", "loss_G_SSIM", "D_acc_real", "D_acc_fake")
"""What one step reports (the adversarial ones are absent when gan_weight is 0: netD does not run)."""


@dataclass
class Nets:
    """netG and netD (DDP-wrapped under torchrun; the bare modules are netG_m/netD_m), their Adam
    optimizers, the losses, and the autocast dtype (None: float32) with its gradient scaler."""

    netG: Any
    netD: Any
    netG_m: Any
    netD_m: Any
    optG: Any
    optD: Any
    scaler: Any
    dtype: Any
    loss: LossConfig
    criterionGAN: Any
    gan_weight: float
    lambda_L1: float
    encoding: Encoding
    target: str = "full"
    """What netG predicts (TrainConfig.target) and whether divided by the albedo: the structure term composes the
    displayed frame as validation does."""
    divide_albedo: bool = False

    @property
    def adversarial(self) -> bool:
        """Whether netD is trained and netG's loss has an adversarial term."""
        return self.gan_weight > 0


def autocast_dtype(cfg: TrainConfig, dev: Dist, say) -> torch.dtype | None:
    """The autocast dtype for cfg.precision on this device (None: float32)."""
    want = cfg.precision
    if want == "auto":
        want = "bf16" if dev.device.type == "cuda" else "fp32"
    if want == "fp16" and dev.device.type != "cuda":
        say("note: fp16 autocast applies to CUDA only; training in float32 on the CPU")
        want = "fp32"
    return {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}[want]


def build_nets(cfg: TrainConfig, net_cfg: NetConfig, enc: Encoding, dev: Dist, say) -> Nets:
    """netG, netD and their optimizers (pix2pix: normal init, Adam(2e-4, (0.5, 0.999)) for each;
    netD may get its own learning rate)."""
    seed_all(cfg.seed)
    channels = enc.input_planes
    netG = init_weights(net_cfg.build_generator(channels)).to(dev.device)
    netD = init_weights(net_cfg.build_discriminator(channels)).to(dev.device)
    optG = torch.optim.Adam(netG.parameters(), lr=cfg.lr, betas=(cfg.beta1, cfg.beta2))
    optD = torch.optim.Adam(netD.parameters(), lr=cfg.d_lr or cfg.lr, betas=(cfg.beta1, cfg.beta2))
    dtype = autocast_dtype(cfg, dev, say)
    loss = LossConfig(reconstruction=cfg.recon_loss, space=cfg.recon_space, gan_mode=cfg.gan_mode,
                      ssim_weight=float(cfg.ssim_weight), ssim_exposure=cfg.ssim_exposure)
    nets = Nets(netG=netG, netD=netD, netG_m=netG, netD_m=netD, optG=optG, optD=optD,
                scaler=torch.amp.GradScaler("cuda", enabled=dtype == torch.float16), dtype=dtype, loss=loss,
                criterionGAN=loss.gan_loss().to(dev.device), gan_weight=float(cfg.gan_weight),
                lambda_L1=float(cfg.lambda_L1), encoding=enc, target=cfg.target, divide_albedo=cfg.divide_albedo)
    # Dropout draws differ per rank (after identical weights); ranks' states are all saved.
    seed_all(cfg.seed + 1_000_003 * (dev.rank + 1))
    return nets


LR_FLOOR = 0.01
"""The cosine schedule ends at this fraction of the learning rate."""


def lr_factor(cfg: TrainConfig, step: int, horizon: int) -> float:
    """The learning rate at ``step`` (0-based, the step about to run) as a fraction of ``cfg.lr``.

    "none": 1. "cosine": 1 up to ``cfg.lr_decay_start`` (0: from the first step), then a half cosine
    down to LR_FLOOR at ``horizon`` (epochs x steps per epoch), LR_FLOOR after it.
    """
    start = cfg.lr_decay_start
    if cfg.lr_decay == "none" or step <= start:
        return 1.0
    if horizon <= start:
        return LR_FLOOR if horizon > 0 else 1.0
    t = min((step - start) / (horizon - start), 1.0)
    return LR_FLOOR + (1.0 - LR_FLOOR) * 0.5 * (1.0 + math.cos(math.pi * t))


def constant_until(cfg: Any, step: int) -> bool:
    """Whether the schedule of ``cfg`` (a TrainConfig or a checkpoint's config dict) runs every step
    before ``step`` at the full rate, whatever the horizon."""
    get = cfg.get if isinstance(cfg, dict) else (lambda k, d=None: getattr(cfg, k, d))
    return get("lr_decay", "none") == "none" or (get("lr_decay_start", 0) or 0) >= step


def set_learning_rate(nets: Nets, cfg: TrainConfig, step: int, horizon: int) -> None:
    """Apply the schedule to both optimizers (netD keeps its own base rate)."""
    f = lr_factor(cfg, step, horizon)
    for opt, base in ((nets.optG, cfg.lr), (nets.optD, cfg.d_lr or cfg.lr)):
        for group in opt.param_groups:
            group["lr"] = base * f


def _accuracy(pred: torch.Tensor, real: bool, gan_mode: str) -> torch.Tensor:
    """Share of netD's patches classified right: logits above 0 (vanilla) or outputs above 0.5 (lsgan)."""
    threshold = 0.0 if gan_mode == "vanilla" else 0.5
    return ((pred.float() > threshold) == real).float().mean()


def train_step(nets: Nets, b: dict[str, Any]) -> dict[str, float]:
    """One pix2pix step: netD on real and generated pairs, then netG against the updated netD.

    Returns the step's numbers (`STEP_KEYS`): netD's loss, netG's adversarial loss (unweighted),
    the reconstruction term times lambda_L1 (pix2pix's "G_L1", whatever the norm), the structure term times
    lambda_L1 and ssim_weight (where that is above 0; ``b`` then holds ``tonemap_exposure``), and netD's
    accuracy on the real and the generated pairs before its update (0.5 each: at chance).
    """
    real_A, real_B = b["real_A"], b["real_B"]
    device_type = real_A.device.type
    autocast = {"device_type": device_type, "dtype": nets.dtype or torch.float32, "enabled": nets.dtype is not None}
    out: dict[str, torch.Tensor] = {}
    with torch.autocast(**autocast):
        fake_B = nets.netG(real_A)
    if nets.adversarial:
        with torch.autocast(**autocast):
            # netD: real pairs vs generated pairs (fake_B detached: no gradient into netG)
            for p in nets.netD.parameters():
                p.requires_grad_(True)
            pred_fake = nets.netD(torch.cat([real_A, fake_B.detach()], 1))
            pred_real = nets.netD(torch.cat([real_A, real_B], 1))
            loss_D = 0.5 * (nets.criterionGAN(pred_fake, False) + nets.criterionGAN(pred_real, True))
        nets.optD.zero_grad(set_to_none=True)
        nets.scaler.scale(loss_D).backward()
        nets.scaler.step(nets.optD)
        out.update(loss_D=loss_D.detach(), D_acc_real=_accuracy(pred_real.detach(), True, nets.loss.gan_mode),
                   D_acc_fake=_accuracy(pred_fake.detach(), False, nets.loss.gan_mode))
    with torch.autocast(**autocast):
        loss_G = loss_G_L1 = nets.loss.reconstruction_loss(fake_B, real_B, nets.encoding, b.get("mask")) * nets.lambda_L1
        if nets.adversarial:
            # netG: fool the updated netD. The bare module: under DDP no gradient of netD is
            # reduced in this pass.
            for p in nets.netD.parameters():
                p.requires_grad_(False)
            loss_G_GAN = nets.criterionGAN(nets.netD_m(torch.cat([real_A, fake_B], 1)), True)
            loss_G = loss_G + nets.gan_weight * loss_G_GAN
            out["loss_G_GAN"] = loss_G_GAN.detach()
    if nets.loss.ssim_weight > 0:  # outside the autocast: SSIM's window sums in bfloat16 would lose the structure
        out["loss_G_SSIM"] = structure_loss(fake_B, b, nets.encoding, nets.target, nets.divide_albedo,
                                              nets.loss.ssim_exposure) * (
            nets.lambda_L1 * nets.loss.ssim_weight)
        loss_G = loss_G + out["loss_G_SSIM"]
    nets.optG.zero_grad(set_to_none=True)
    nets.scaler.scale(loss_G).backward()
    nets.scaler.step(nets.optG)
    nets.scaler.update()
    out["loss_G_L1"] = loss_G_L1.detach()
    if "loss_G_SSIM" in out:
        out["loss_G_SSIM"] = out["loss_G_SSIM"].detach()
    keys = [k for k in STEP_KEYS if k in out]
    values = torch.stack([out[k].float() for k in keys]).tolist()  # one device sync per step
    return dict(zip(keys, values))
