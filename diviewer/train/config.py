"""Settings of one training run (`TrainConfig`), and which of them a resumed run may change."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from diviewer.errors import DiviewerError
from diviewer.fieldspec import Bool, Choice, Float, Floats, Int, Maybe, Text, check_fields
from diviewer.provenance import check_known_keys


@dataclass(frozen=True)
class TrainConfig:
    """Settings of one training run; recorded in every checkpoint (`to_dict`)."""

    data: Path
    """Dataset folder (`diviewer capture` output) with train and val frames."""

    out: Path
    """Run folder: checkpoints, metrics.csv, curves.png."""

    K: int = 32
    """Generator base width (pix2pix's ngf); the paper trains K = 32, 64, 128."""

    epochs: int = 50
    """Passes over the train split (the paper: 50)."""

    batch_size: int = 4
    """Frames per step (per process under torchrun); the paper: 4."""

    lr: float = 2e-4
    """Adam learning rate of both networks (pix2pix)."""

    lr_decay: str = "none"
    """Learning-rate schedule: "none" (constant, pix2pix) or "cosine" (from lr down to lr / 100 over
    epochs x steps per epoch, a pure function of the step, so a resumed run follows the same curve)."""

    lr_decay_start: int = 0
    """With "cosine": the step the decay begins at; the rate is constant before it (a constant phase,
    then an anneal). A run trained at a constant rate can be resumed into an anneal that starts at or
    after its step: every step it took ran at the rate the new schedule gives it."""

    beta1: float = 0.5
    """Adam beta1 (pix2pix: 0.5, which keeps GAN training stable)."""

    beta2: float = 0.999
    """Adam beta2."""

    lambda_L1: float = 100.0
    """Weight of the L1 term against the adversarial term (pix2pix)."""

    target: str = "full"
    """What netG predicts: "full" (the path-traced image), "indirect" (pt - pt_direct, added to the GL direct light
    when composed) or "residual" (pt - the GL direct light itself, added back to it: the network also corrects
    where the rasterizer's shadow map and point-sampled pixels differ from the path tracer's direct light)."""

    divide_albedo: bool = False
    """With target "indirect" or "residual": predict it / max(albedo, ALBEDO_FLOOR) (texture-free, closer
    to irradiance) and multiply back when composing."""

    seed: int = 0
    """Seeds the weights, the data order and dropout; the same seed gives the same run."""

    recipe: dict[str, Any] | None = None
    """Where these settings came from (`diviewer.train.recipe.Recipe.record`: name, file, sha256, the fields the
    command line changed); None for a run configured in code. The model card keeps it in ``recipe.train``."""

    dropout: float = 0.5
    """Dropout in the innermost generator decoders (pix2pix: 0.5)."""

    ndf: int = 64
    """Discriminator base width (the paper: 64)."""

    precision: str = "auto"
    """Autocast: "auto" (bfloat16 on CUDA, float32 on the CPU), "fp32", "bf16" (no loss scaling
    needed: float32's range), or "fp16" (float16 with gradient scaling; CUDA only)."""

    num_workers: int = 0
    """DataLoader workers. The train split lives in RAM, so workers only overlap the host-to-GPU
    copy with compute; 0 loads in the training process."""

    val_every: int = 1
    """Validate every this many epochs (and always after the last one and when a run stops)."""

    save_every: int = 0
    """Also write last.ckpt every this many steps inside an epoch (0: at epoch ends and stops only)."""

    max_steps: int | None = None
    """Stop after this many steps in total (smoke runs, tests); None trains all epochs."""

    device: str = "auto"
    """"auto" (CUDA if available, else CPU), "cpu", "cuda" or "cuda:N"."""

    gan_weight: float = 1.0
    """Weight of netG's adversarial term (1: pix2pix and the paper; 0: reconstruction only, netD
    is then neither trained nor run)."""

    gan_mode: str = "vanilla"
    """Adversarial objective: "vanilla" (BCE on logits, the paper) or "lsgan" (least squares)."""

    recon_loss: str = "l1"
    """Reconstruction norm, weighted by lambda_L1: "l1" (the paper) or "l2"."""

    recon_space: str = "encoded"
    """Where the reconstruction loss is taken: "encoded" (the network's values, the paper),
    "linear" (radiance times the dataset exposure; with l2 the one unbiased choice under
    Monte-Carlo noise), "log" (relative errors: dark regions count), "relative" or "levels" (4x4 block means and
    the detail around them: L1 sets a block's level near its noisy target's mean); see `diviewer.train.losses`."""

    ssim_weight: float = 0.0
    """Weight of the structure term, 1 - SSIM of the tone-mapped displayed frame (`diviewer.train.losses.
    structure_loss`), beside the reconstruction term, both times lambda_L1; 0: none."""

    ssim_exposure: str = "scene"
    """Where the structure term tone-maps: "scene" (the scene's exposure, as `diviewer eval` scores), "metered" (each
    frame at the exposure the viewer's meter reads off its target) or "both" (the mean of the two terms)."""

    n_layers_D: int = 3
    """Discriminator stride layers (3: the paper's 70x70 PatchGAN; 4 sees 142x142 patches)."""

    norm_D: str = "batch"
    """Discriminator normalisation: "batch" (the paper), "instance" or "none"."""

    d_lr: float | None = None
    """netD's Adam learning rate (None: the same as lr); a higher one rebalances a netD at chance."""

    upsample: str = "transpose"
    """Generator decoder upsampling: "transpose" (the paper), "resize" or "shuffle"."""

    norm: str = "batch"
    """Generator normalisation: "batch" (the paper), "instance" or "none"."""

    train_frames: int | None = None
    """Train on only the first N train frames by index (None: all present), so runs can share a
    dataset whose capture is still adding frames."""

    patience: int = 0
    """Early stopping: stop when validation tone-mapped SSIM has not improved for this many
    validations in a row (0: never; train all epochs)."""

    val_every_steps: int = 0
    """Also validate (and write a row, and save) every this many steps (0: at epoch ends only)."""

    init_from: str | None = None
    """A checkpoint (RUN/best.ckpt) whose networks and encoding this run starts from instead of random
    weights: a warm start, e.g. onto more frames of the same scene. The networks must be the same
    (K, levels, decoder, normalisation, target); optimizers, step and schedule start afresh. The
    checkpoint's own recipe is recorded (model card: ``recipe.init``) so the model can be rebuilt."""

    light_scale: bool = True
    """Encoding version 2: divide each frame's direct light and target by its light scale (from its lights
    and emitters, `diviewer.scene.lights.light_scale`) and multiply the output back, so the model is linear
    in the light by construction (no light: exactly black). False: version 1, radiance as is."""

    world_inputs: bool = False
    """Encoding version 3 (needs ``light_scale``): the network also takes each pixel's world-space position and
    normal, computed from its depth, normal and the frame's camera (`diviewer.train.world`)."""

    light_inputs: bool = False
    """Encoding version 4 (needs ``world_inputs``): the network also takes where each of the scene's lights is (a
    sun's direction, a point light's position: `diviewer.scene.lights.light_params`), as constant planes."""

    world_frequencies: int = 0
    """Octaves L of Fourier features of the world position (needs ``world_inputs``): sin and cos of pi 2^l p, l < L,
    6 L more planes into netG's first encoder (`diviewer.train.networks.UnetGenerator`), so a small network can
    key its light on fine detail of where a surface is. 0: the position as is."""

    output_gain: bool = False
    """Encode the target at its own exposure: the dataset's exposure times a gain that maps the 99th percentile of
    the train split's exposed target to 1 (`diviewer.train.targets.fit_output_gain`; recorded as the encoding's
    ``output_gain``). False: the direct light's exposure for both, as before."""

    aspect_crops: tuple[float, float] | None = None
    """Random-width crops of the (wider) dataset frames, one width per batch, width / height drawn in this
    range at full height (e.g. (0.5625, 1.7778): 9:16 to 16:9), edge-padded to the network's stride as the
    runtime pads them, the loss over the frame's pixels only. None: whole frames."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "data", Path(self.data))
        object.__setattr__(self, "out", Path(self.out))

        def fail(name: str, message: str) -> None:
            raise DiviewerError(message, field=f"train.{name}")

        # Each field as TRAIN_FIELDS declares it (type, range, names); then the rules between fields.
        values = {name: getattr(self, name) for name in TRAIN_FIELDS}
        for name, value in check_fields(values, TRAIN_FIELDS, "train").items():
            object.__setattr__(self, name, value)
        if self.ssim_exposure != "scene" and not self.ssim_weight:
            fail("ssim_exposure", f"{self.ssim_exposure!r} needs the structure term (ssim_weight > 0)")
        if self.divide_albedo and self.target == "full":
            fail("divide_albedo", "only applies to targets 'indirect' and 'residual' (use --target indirect)")
        if self.recipe is not None and not (isinstance(self.recipe, dict)
                                            and all(isinstance(k, str) for k in self.recipe)):
            fail("recipe", f"must be a recipe record (a table of name, file, sha256, overrides), got {self.recipe!r}")
        if self.world_inputs and not self.light_scale:
            fail("world_inputs", "needs light_scale (encoding 3 extends encoding 2)")
        if self.light_inputs and not self.world_inputs:
            fail("light_inputs", "needs world_inputs (encoding 4 extends encoding 3)")
        f = self.world_frequencies
        if f and not self.world_inputs:
            fail("world_frequencies", "needs world_inputs (the features are of the world position)")
        a = self.aspect_crops
        if a is not None and not a[0] <= a[1]:
            fail("aspect_crops", f"must be two positive numbers lo <= hi (width / height), got {a!r}")
        cuda_n = self.device.startswith("cuda:") and self.device[5:].isdigit()
        if not (self.device in ("auto", "cpu", "cuda") or cuda_n):
            fail("device", f"must be auto, cpu, cuda or cuda:N, got {self.device!r}")

    def check_schedule(self, steps_per_epoch: int) -> str | None:
        """Refuse a decay that would start at or after the run's last step (it would never decay), where the
        decay start was asked for; where it came from the recipe (a run the user shortened with --epochs),
        return the note to print instead: the rate stays constant."""
        horizon = self.epochs * steps_per_epoch
        if self.lr_decay == "none" or self.lr_decay_start < horizon:
            return None
        text = (f"is {self.lr_decay_start}, but the run ends at step {horizon} ({self.epochs} epochs of "
                f"{steps_per_epoch} steps): the decay would never start")
        from_recipe = self.recipe is not None and "lr_decay_start" not in self.recipe.get("overrides", {})
        if from_recipe:
            return f"recipe {self.recipe.get('name')}: lr_decay_start {text}; the learning rate stays constant"
        raise DiviewerError(f"{text}; give a smaller step or more epochs", field="train.lr_decay_start")

    def to_dict(self) -> dict[str, Any]:
        """Plain dict (paths as strings) for checkpoints."""
        d = dataclasses.asdict(self)
        d["data"], d["out"] = str(self.data), str(self.out)
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainConfig:
        """Rebuild from `to_dict()` output; unknown keys are an error (checkpoints written before
        `precision` recorded `amp`: True meant float16 autocast)."""
        data = dict(data)
        data = {**LEGACY_DEFAULTS, **data}
        if "amp" in data and "precision" not in data:
            data["precision"] = "fp16" if data.pop("amp") else "auto"
        check_known_keys(cls, data, "train")
        return cls(**data)


MAX_FREQUENCIES: int = 12
"""The most octaves of `world_frequencies`: at pi 2^11 the wavelength is 1/1024 of the encoding's box (5 cm across
Sponza's 51 m), finer than the pixels of a capture see."""

CHOICES: dict[str, tuple[str, ...]] = {
    "precision": ("auto", "fp32", "bf16", "fp16"), "gan_mode": ("vanilla", "lsgan"), "recon_loss": ("l1", "l2"),
    "recon_space": ("encoded", "linear", "log", "relative", "levels"), "norm_D": ("batch", "instance", "none"),
    "upsample": ("transpose", "resize", "shuffle"), "norm": ("batch", "instance", "none"),
    "lr_decay": ("none", "cosine"), "ssim_exposure": ("scene", "metered", "both"),
}
"""The settings that take one of a few names (the network ones are `networks.UPSAMPLES`/`NORMS`)."""

_STEPS = Int(0, 10**9)
TRAIN_FIELDS: dict[str, Any] = {
    "K": Int(1, 1024), "epochs": Int(1, 100_000), "batch_size": Int(1, 4096),
    "lr": Float(0.0, 1.0, lo_open=True), "lr_decay": Choice(CHOICES["lr_decay"]), "lr_decay_start": _STEPS,
    "beta1": Float(0.0, 1.0, hi_open=True), "beta2": Float(0.0, 1.0, hi_open=True), "lambda_L1": Float(0.0, 1e6),
    "target": Choice(("full", "indirect", "residual")), "divide_albedo": Bool(), "seed": Int(0, 2**32 - 1),
    "dropout": Float(0.0, 1.0, hi_open=True), "ndf": Int(1, 1024), "precision": Choice(CHOICES["precision"]),
    "num_workers": Int(0, 256), "val_every": Int(1, 100_000), "save_every": _STEPS,
    "max_steps": Maybe(Int(1, 10**9)), "device": Text(64), "gan_weight": Float(0.0, 1e6),
    "gan_mode": Choice(CHOICES["gan_mode"]), "recon_loss": Choice(CHOICES["recon_loss"]),
    "recon_space": Choice(CHOICES["recon_space"]), "ssim_weight": Float(0.0, 1e6),
    "ssim_exposure": Choice(CHOICES["ssim_exposure"]), "n_layers_D": Int(1, 8), "norm_D": Choice(CHOICES["norm_D"]),
    "d_lr": Maybe(Float(0.0, 1.0, lo_open=True)), "upsample": Choice(CHOICES["upsample"]),
    "norm": Choice(CHOICES["norm"]), "train_frames": Maybe(Int(1, 10**8)), "patience": Int(0, 10**6),
    "val_every_steps": _STEPS, "init_from": Maybe(Text()), "light_scale": Bool(), "world_inputs": Bool(),
    "light_inputs": Bool(), "world_frequencies": Int(0, MAX_FREQUENCIES), "output_gain": Bool(),
    "aspect_crops": Maybe(Floats(2, Float(0.0, 100.0, lo_open=True))),
}
"""What each setting accepts (`diviewer.fieldspec`): every field but ``data``, ``out`` and ``recipe``, checked when a
TrainConfig is made (from a recipe, the command line or a checkpoint); the rules between fields follow in
``__post_init__``. The bounds keep a run within memory and time: K and ndf up to 1024 (a U-Net's widest layer is 8 K
channels), batches up to 4096 frames."""

RESUME_FIXED: tuple[str, ...] = ("K", "batch_size", "lr", "lr_decay", "lr_decay_start", "beta1", "beta2",
                                 "lambda_L1", "target", "divide_albedo", "seed", "dropout", "ndf", "gan_weight",
                                 "gan_mode", "recon_loss", "recon_space", "ssim_weight", "ssim_exposure",
                                 "n_layers_D", "norm_D", "d_lr", "upsample",
                                 "norm", "train_frames", "init_from", "light_scale", "aspect_crops",
                                 "world_inputs", "light_inputs", "world_frequencies", "output_gain")
"""Settings a resumed run must share with its checkpoint (the others, e.g. epochs, may change); the schedule
(lr_decay, lr_decay_start) may change while both the old and the new one are constant up to the
checkpoint's step (train.checkpoint.check_resume)."""

RESUME_INHERITED: tuple[str, ...] = (*RESUME_FIXED, "epochs", "val_every", "save_every", "patience", "val_every_steps")
"""Settings `diviewer train --resume` takes from the checkpoint unless given again (max_steps, precision,
device and num_workers describe this invocation and this machine, so they are not inherited)."""

LEGACY_DEFAULTS: dict[str, Any] = {"light_scale": False, "aspect_crops": None, "world_inputs": False,
                                   "light_inputs": False, "output_gain": False, "world_frequencies": 0,
                                   "ssim_exposure": "scene"}
"""What a checkpoint from before these settings existed trained with (radiance as is, whole frames), where
it does not record them; a new run's defaults differ."""
