"""Tests for diviewer.train.networks: shapes, pix2pix structure, determinism, a tiny overfit."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from torch import nn  # noqa: E402

from diviewer.contract.encoding import INPUT_CHANNEL_COUNT, OUTPUT_CHANNELS, Encoding  # noqa: E402
from diviewer.train.encoding_torch import encode_inputs, encode_radiance  # noqa: E402
from diviewer.errors import DiviewerError  # noqa: E402
from diviewer.train.losses import reconstruction_loss  # noqa: E402
from diviewer.train.networks import (  # noqa: E402
    LAMBDA_L1,
    NORMS,
    UPSAMPLES,
    GANLoss,
    NetConfig,
    NLayerDiscriminator,
    PixelShuffleUpsample,
    UnetGenerator,
    init_weights,
    levels_for_resolution,
)


@pytest.fixture(autouse=True)
def _seed() -> None:
    torch.manual_seed(0)


def test_levels_for_resolution() -> None:
    assert [levels_for_resolution(r) for r in (32, 64, 128, 256, 512)] == [5, 6, 7, 8, 9]
    assert levels_for_resolution(384) == 7  # 3x3 bottleneck
    with pytest.raises(ValueError):
        levels_for_resolution(33)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("K", "resolution"),
    [(K, r) for K in (8, 16, 32) for r in (32, 64, 128)] + [(8, 256)],
)
def test_generator_output_shape(K: int, resolution: int) -> None:
    netG = UnetGenerator(K=K, resolution=resolution).eval()
    assert netG.levels == levels_for_resolution(resolution)
    with torch.no_grad():
        y = netG(torch.randn(2, INPUT_CHANNEL_COUNT, resolution, resolution))
    assert y.shape == (2, OUTPUT_CHANNELS, resolution, resolution)
    assert y.abs().max() <= 1.0  # tanh


def test_generator_widths_are_capped_at_8K() -> None:
    netG = UnetGenerator(K=8, levels=7)
    widths = [block[0].out_channels for block in netG.down]
    assert widths == [8, 16, 32, 64, 64, 64, 64]


def test_generator_non_square_and_refusal() -> None:
    netG = UnetGenerator(K=8, levels=4).eval()  # multiple of 16
    with torch.no_grad():
        assert netG(torch.randn(1, INPUT_CHANNEL_COUNT, 48, 80)).shape == (1, OUTPUT_CHANNELS, 48, 80)
    with pytest.raises(ValueError, match="multiples of 16; got 48x40"):
        netG(torch.randn(1, INPUT_CHANNEL_COUNT, 48, 40))
    with pytest.raises(ValueError, match="multiples of 16"):
        netG(torch.randn(1, INPUT_CHANNEL_COUNT, 50, 64))


@pytest.mark.parametrize("levels", [5, 8])
def test_generator_norms_and_dropout_follow_pix2pix(levels: int) -> None:
    netG = UnetGenerator(K=4, levels=levels)
    all_modules = [m for _, m in netG.named_modules(remove_duplicate=False)]
    assert len({id(m) for m in all_modules}) == len(all_modules), "a module is shared between layers"
    norms = [m for m in all_modules if isinstance(m, nn.BatchNorm2d)]
    # Every conv but the first encoder, the innermost encoder and the last decoder has its own norm.
    assert len(norms) == (levels - 2) + (levels - 1)
    assert not any(isinstance(m, nn.BatchNorm2d) for m in netG.down[0])
    assert not any(isinstance(m, nn.BatchNorm2d) for m in netG.down[-1])
    assert not any(isinstance(m, nn.BatchNorm2d) for m in netG.up[-1])
    assert isinstance(netG.up[-1][-1], nn.Tanh)
    dropout_decoders = [k for k, block in enumerate(netG.up) if any(isinstance(m, nn.Dropout) for m in block)]
    assert dropout_decoders == list(range(min(3, levels - 4)))  # the innermost decoders: 3 at 256


@pytest.mark.slow
def test_generator_batch_size_one_trains() -> None:
    # The 1x1 bottleneck has no norm, so batch-norm statistics exist even for a single image.
    netG = init_weights(UnetGenerator(K=8, resolution=32)).train()
    y = netG(torch.randn(1, INPUT_CHANNEL_COUNT, 32, 32))
    y.abs().mean().backward()
    grads = [p.grad for p in netG.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert netG.down[0][0].weight.grad.abs().sum() > 0  # gradients reach the first layer


@pytest.mark.slow
def test_generator_eval_is_deterministic() -> None:
    netG = init_weights(UnetGenerator(K=8, resolution=32))
    x = torch.randn(2, INPUT_CHANNEL_COUNT, 32, 32)
    netG.train()
    netG(x)  # move the batch-norm running statistics off their initial values
    netG.eval()
    with torch.no_grad():
        assert torch.equal(netG(x), netG(x))


def test_model_args_rebuild() -> None:
    netG = init_weights(UnetGenerator(K=8, levels=5, dropout=0.25))
    rebuilt = UnetGenerator(**netG.model_args())
    rebuilt.load_state_dict(netG.state_dict())  # strict: same structure and shapes
    netG.eval()
    rebuilt.eval()
    x = torch.randn(1, INPUT_CHANNEL_COUNT, 32, 32)
    with torch.no_grad():
        assert torch.equal(netG(x), rebuilt(x))
    netD = NLayerDiscriminator(ndf=8)
    NLayerDiscriminator(**netD.model_args()).load_state_dict(netD.state_dict())


def _tiny_batch() -> tuple[torch.Tensor, torch.Tensor]:
    """Two smooth 32x32 frames and a GI-like target: direct light plus an albedo-tinted blurred bounce."""
    g = torch.Generator().manual_seed(0)
    n, h, w = 2, 32, 32

    def smooth(c: int) -> torch.Tensor:
        coarse = torch.rand(n, c, 8, 8, generator=g)
        return nn.functional.interpolate(coarse, size=(h, w), mode="bilinear", align_corners=False)

    depth = smooth(1) * 5.0
    depth[:, :, :4] = 0.0  # a strip of background
    normal = nn.functional.normalize(torch.randn(n, 3, h, w, generator=g), dim=1)
    albedo = smooth(3)
    direct = 10 ** (4 * smooth(3) - 2)  # 1e-2 .. 1e2: uses a good part of the curve
    enc = Encoding(depth_scale=5.0)
    real_A = encode_inputs(depth, normal, albedo, direct, enc, channel_axis=1)
    bounce = nn.functional.avg_pool2d(direct, 9, 1, 4) * albedo * 0.5
    real_B = encode_radiance(direct + bounce, enc)
    return real_A, real_B


@pytest.fixture
def one_thread():
    """One torch thread: on a loaded 2-core machine two threads run these tiny convolutions far slower."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.mark.slow
def test_tiny_generator_overfits(one_thread) -> None:
    """K=8 at 32x32 fits a fixed batch: L1 falls >= 5x from the start and >= 4x below the best constant.

    lr 1e-3 (5x the paper's 2e-4) and no dropout, so 300 steps suffice on two CPU cores (measured:
    0.142 -> 0.0072, 20x; the best constant, the target's median, scores 0.067).
    """
    real_A, real_B = _tiny_batch()
    netG = init_weights(UnetGenerator(K=8, resolution=32, dropout=0.0))
    optimizer = torch.optim.Adam(netG.parameters(), lr=1e-3, betas=(0.5, 0.999))
    baseline = (real_B - real_B.median()).abs().mean().item()
    losses = []
    for _ in range(300):
        loss = nn.functional.l1_loss(netG(real_A), real_B)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] <= losses[0] / 5, f"L1 {losses[0]:.4f} -> {losses[-1]:.4f}"
    assert losses[-1] <= baseline / 4, f"L1 {losses[-1]:.4f} vs best constant {baseline:.4f}"


@pytest.mark.parametrize(("size", "patches"), [(32, 2), (64, 6), (256, 30)])
def test_discriminator_patch_map(size: int, patches: int) -> None:
    netD = NLayerDiscriminator(INPUT_CHANNEL_COUNT + OUTPUT_CHANNELS, ndf=8).eval()
    convs = [m for m in netD.modules() if isinstance(m, nn.Conv2d)]
    assert len(convs) == 5
    real_AB = torch.randn(2, INPUT_CHANNEL_COUNT + OUTPUT_CHANNELS, size, size)
    with torch.no_grad():
        assert netD(real_AB).shape == (2, 1, patches, patches)  # 30x30 patches at 256: pix2pix's 70x70 PatchGAN


def test_gan_loss_is_stable_and_right() -> None:
    criterion = GANLoss()
    huge = torch.tensor([[1e4, -1e4]], requires_grad=True)
    for target_is_real in (True, False):
        loss = criterion(huge, target_is_real)
        loss.backward()
        assert torch.isfinite(loss) and torch.isfinite(huge.grad).all()
        huge.grad = None
    # A confident right answer costs ~0, a confident wrong one ~|logit|; zero logits cost log 2.
    assert criterion(torch.full((1, 1, 3, 3), 1e4), True).item() == pytest.approx(0.0, abs=1e-6)
    assert criterion(torch.full((1, 1, 3, 3), 1e4), False).item() == pytest.approx(1e4, rel=1e-6)
    assert criterion(torch.zeros(1, 1, 3, 3), False).item() == pytest.approx(0.6931472, rel=1e-6)
    assert LAMBDA_L1 == 100.0


def test_init_weights() -> None:
    netD = init_weights(NLayerDiscriminator(ndf=16), gain=0.02)
    conv = netD.model[0]
    assert conv.weight.std().item() == pytest.approx(0.02, rel=0.1)
    assert torch.all(conv.bias == 0)
    norm = next(m for m in netD.modules() if isinstance(m, nn.BatchNorm2d))
    assert norm.weight.mean().item() == pytest.approx(1.0, abs=0.01)


def test_net_config() -> None:
    config = NetConfig(K=8, resolution=64, target="indirect")
    assert NetConfig.from_dict(config.to_dict()) == config
    assert config.resolved_levels() == 6
    netG = config.build_generator()
    assert netG.levels == 6 and netG.K == 8 and netG.in_channels == INPUT_CHANNEL_COUNT
    assert config.build_discriminator().in_channels == INPUT_CHANNEL_COUNT + OUTPUT_CHANNELS
    with pytest.raises(DiviewerError, match="unknown key"):
        NetConfig.from_dict({**config.to_dict(), "ngf": 64})
    with pytest.raises(DiviewerError, match="target"):
        NetConfig(target="direct")
    with pytest.raises(DiviewerError, match="multiple"):
        NetConfig(resolution=96, levels=6)


# ---------------------------------------------------------------------------------------------
# Ablation options: decoder upsampling and normalisation


def _norm_modules(net: nn.Module) -> list[nn.Module]:
    return [m for m in net.modules() if isinstance(m, (nn.BatchNorm2d, nn.InstanceNorm2d))]


@pytest.mark.slow
@pytest.mark.parametrize("upsample", UPSAMPLES)
@pytest.mark.parametrize("norm", NORMS)
def test_each_option_builds_and_trains_one_step(upsample: str, norm: str) -> None:
    config = NetConfig(K=4, resolution=32, ndf=8, upsample=upsample, norm=norm, norm_D=norm, target="indirect")
    netG, netD = init_weights(config.build_generator()), init_weights(config.build_discriminator())
    assert netG.model_args()["upsample"] == upsample and netG.model_args()["norm"] == norm
    levels = netG.levels
    expected_norms = 0 if norm == "none" else (levels - 2) + (levels - 1)
    assert len(_norm_modules(netG)) == expected_norms
    assert all(isinstance(m, nn.InstanceNorm2d) == (norm == "instance") for m in _norm_modules(netG))
    assert len(_norm_modules(netD)) == (0 if norm == "none" else 3)
    # a conv followed by a norm needs no bias (the norm's shift replaces it); without a norm it has one
    for block in netG.down[1:-1]:
        assert (block[0].bias is None) == (norm != "none")
    # one pix2pix step: netD on real/fake pairs, then netG on GAN + reconstruction
    real_A, real_B = _tiny_batch()
    optG = torch.optim.Adam(netG.parameters(), lr=2e-4, betas=(0.5, 0.999))
    optD = torch.optim.Adam(netD.parameters(), lr=2e-4, betas=(0.5, 0.999))
    before = {k: v.clone() for k, v in netG.state_dict().items()}
    criterion = GANLoss()
    fake_B = netG(real_A)
    assert fake_B.shape == real_B.shape
    loss_D = 0.5 * (criterion(netD(torch.cat([real_A, fake_B.detach()], 1)), False)
                    + criterion(netD(torch.cat([real_A, real_B], 1)), True))
    optD.zero_grad()
    loss_D.backward()
    optD.step()
    loss_G = criterion(netD(torch.cat([real_A, fake_B], 1)), True) + LAMBDA_L1 * reconstruction_loss(fake_B, real_B)
    optG.zero_grad()
    loss_G.backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in netG.parameters())
    optG.step()
    changed = [k for k, v in netG.state_dict().items() if v.is_floating_point() and not torch.equal(v, before[k])]
    assert any(k.startswith("down.0.") for k in changed) and any(k.startswith(f"up.{levels - 1}.") for k in changed)
    # non-square sizes work with every option
    netG.eval()
    with torch.no_grad():
        assert netG(torch.randn(1, INPUT_CHANNEL_COUNT, 32, 64)).shape == (1, OUTPUT_CHANNELS, 32, 64)


@pytest.mark.slow
def test_instance_norm_has_no_running_statistics() -> None:
    """Instance norm normalises each image by itself: train and eval give the same output."""
    netG = init_weights(UnetGenerator(K=4, resolution=32, norm="instance", dropout=0.0))
    assert not any(b.numel() for b in netG.buffers())
    x = torch.randn(2, INPUT_CHANNEL_COUNT, 32, 32)
    with torch.no_grad():
        y_train = netG.train()(x)
        y_eval = netG.eval()(x)
        assert torch.allclose(y_train, y_eval, atol=1e-6)
        # and one image's output does not depend on the others in the batch (BatchNorm's does in training)
        assert torch.allclose(netG(x[:1]), y_eval[:1], atol=1e-6)


@pytest.mark.parametrize("initialise", [False, True])
def test_pixel_shuffle_starts_as_nearest_upsampling(initialise: bool) -> None:
    """ICNR: the four sub-pixels of each 2x2 output block start equal (no checkerboard at init)."""
    up = PixelShuffleUpsample(6, 5)
    if initialise:
        init_weights(up, gain=0.02)
        assert up[0].weight.std().item() == pytest.approx(0.02, rel=0.2)
    else:
        torch.nn.init.uniform_(up[0].bias)  # a non-zero bias must be grouped too
        up.reset_icnr()
    with torch.no_grad():
        y = up(torch.randn(2, 6, 8, 8))
    assert y.shape == (2, 5, 16, 16)
    corner = y[..., 0::2, 0::2]
    for dy, dx in ((0, 1), (1, 0), (1, 1)):
        assert torch.equal(y[..., dy::2, dx::2], corner)
    assert corner.std() > 0


def test_resize_decoder_uses_no_transposed_convolution() -> None:
    netG = UnetGenerator(K=4, resolution=32, upsample="resize")
    assert not any(isinstance(m, nn.ConvTranspose2d) for m in netG.modules())
    assert sum(isinstance(m, nn.Upsample) for m in netG.modules()) == netG.levels
    assert all(m.mode == "nearest" for m in netG.modules() if isinstance(m, nn.Upsample))
    shuffle = UnetGenerator(K=4, resolution=32, upsample="shuffle")
    assert sum(isinstance(m, nn.PixelShuffle) for m in shuffle.modules()) == shuffle.levels


def test_checkpoints_without_the_options_rebuild_the_paper_network() -> None:
    """model_args and net_config written before upsample/norm existed rebuild transpose/batch, strictly."""
    netG = init_weights(UnetGenerator(K=8, levels=5))
    old_args = {k: v for k, v in netG.model_args().items() if k not in ("upsample", "norm")}
    rebuilt = UnetGenerator(**old_args)
    assert rebuilt.model_args() == netG.model_args()
    assert rebuilt.model_args()["upsample"] == "transpose" and rebuilt.model_args()["norm"] == "batch"
    rebuilt.load_state_dict(netG.state_dict())  # strict: same keys and shapes as before
    assert isinstance(rebuilt.up[0][1], nn.ConvTranspose2d) and isinstance(rebuilt.up[0][2], nn.BatchNorm2d)
    old_config = {k: v for k, v in NetConfig(K=8, resolution=64).to_dict().items()
                  if k not in ("upsample", "norm", "norm_D")}
    config = NetConfig.from_dict(old_config)
    assert (config.upsample, config.norm, config.norm_D) == ("transpose", "batch", "batch")
    netD = NLayerDiscriminator(ndf=8)
    old_netD_args = {k: v for k, v in netD.model_args().items() if k != "norm"}
    NLayerDiscriminator(**old_netD_args).load_state_dict(netD.state_dict())


def test_net_config_options_are_validated_by_name() -> None:
    config = NetConfig(K=8, resolution=32, upsample="shuffle", norm="none", norm_D="instance")
    assert NetConfig.from_dict(config.to_dict()) == config
    assert config.build_generator().model_args()["upsample"] == "shuffle"
    assert config.build_discriminator().norm == "instance"
    for field, value in (("upsample", "bilinear"), ("norm", "group"), ("norm_D", "spectral")):
        with pytest.raises(DiviewerError, match=rf"net\.{field}: must be one of"):
            NetConfig(**{field: value})
    with pytest.raises(ValueError, match="upsample"):
        UnetGenerator(K=4, levels=3, upsample="deconv")
    with pytest.raises(ValueError, match="norm"):
        NLayerDiscriminator(norm="layer")


def test_fourier_features_are_the_position_octaves_before_the_first_encoder() -> None:
    """sin, then cos, of pi 2^l p for l < L of the three planes from frequency_start, 6 L planes into the first
    conv; the other planes and an L = 0 network as before (an old checkpoint's args rebuild it unchanged)."""
    netG = init_weights(UnetGenerator(in_channels=16, K=4, levels=3, frequencies=3))
    assert netG.down[0][0].in_channels == 16 + 18
    x = torch.rand(2, 16, 16, 24) * 2 - 1
    f = netG.fourier_features(x)
    p = x[:, INPUT_CHANNEL_COUNT:INPUT_CHANNEL_COUNT + 3]
    want = [torch.sin(torch.pi * 2 ** level * p) for level in range(3)]
    want += [torch.cos(torch.pi * 2 ** level * p) for level in range(3)]
    torch.testing.assert_close(f, torch.cat(want, 1), atol=1e-6, rtol=0)
    args = netG.model_args()
    assert (args["frequencies"], args["frequency_start"]) == (3, INPUT_CHANNEL_COUNT)
    rebuilt = UnetGenerator(**args)
    rebuilt.load_state_dict(netG.state_dict())  # strict
    netG.eval()
    rebuilt.eval()
    with torch.no_grad():
        assert torch.equal(netG(x), rebuilt(x))
        moved = x.clone()
        moved[:, INPUT_CHANNEL_COUNT] += 0.01  # the network reads the position's fine detail
        assert not torch.equal(netG(x), netG(moved))
    plain = UnetGenerator(in_channels=16, K=4, levels=3)
    assert "frequencies" not in plain.model_args() and plain.down[0][0].in_channels == 16
    with pytest.raises(ValueError, match="frequencies"):
        UnetGenerator(in_channels=12, K=4, levels=3, frequencies=2)  # no three planes from plane 10
    with pytest.raises(ValueError, match="frequencies"):
        UnetGenerator(in_channels=16, K=4, levels=3, frequencies=-1)


def test_net_config_world_frequencies() -> None:
    config = NetConfig(K=4, levels=3, resolution=32, world_frequencies=2)
    assert NetConfig.from_dict(config.to_dict()) == config
    assert config.build_generator(16).model_args()["frequencies"] == 2
    assert NetConfig.from_dict({k: v for k, v in config.to_dict().items() if k != "world_frequencies"}
                               ).world_frequencies == 0  # a card from before the option
    for bad in (-1, 13, True, 2.0):
        with pytest.raises(DiviewerError, match=r"net\.world_frequencies"):
            NetConfig(K=4, resolution=32, world_frequencies=bad)
