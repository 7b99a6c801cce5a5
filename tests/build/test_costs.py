"""The build's cost model: a training step's time across K on the CPU (diviewer.build.costs)."""

from __future__ import annotations

import math

import pytest

from diviewer.build import costs


def step(K: int, width: int = 128, height: int = 128) -> float:
    return costs.train_step_seconds("cpu", K, 4, width, height, gan=False)


def test_cpu_step_is_the_measured_rates_at_8_and_16_and_the_measured_ratio_above():
    assert step(8) == pytest.approx(costs.TRAIN_SECONDS_PER_STEP[("cpu", 8)])
    assert step(16) == pytest.approx(costs.TRAIN_SECONDS_PER_STEP[("cpu", 16)])
    assert step(32) / step(16) == pytest.approx(costs.CPU_WIDE_K_STEP_RATIO)
    assert step(64) / step(32) == pytest.approx(costs.CPU_WIDE_K_STEP_RATIO)
    assert 1.0 < costs.CPU_WIDE_K_STEP_RATIO < 4.0  # measured, below the convolutions' 4x


def test_cpu_step_grows_with_K_and_pixels_and_doubles_with_the_discriminator():
    ks = [2, 4, 8, 12, 16, 24, 32, 64, 128]
    times = [step(k) for k in ks]
    assert all(a < b for a, b in zip(times, times[1:]))
    assert all(math.isfinite(t) and t > 0 for t in times)
    assert step(16, 256, 128) == pytest.approx(2 * step(16))
    assert costs.train_step_seconds("cpu", 16, 4, 128, 128, gan=True) == pytest.approx(costs.GAN_STEP_FACTOR * step(16))


def test_a_step_sees_the_mean_aspect_crop_as_the_trainer_draws_it():
    from diviewer.train.targets import crop_widths

    crops = (0.5625, 16 / 9)
    assert crop_widths(crops, 128, 228) == (72, 227)
    assert costs.train_pixels(228, 128, crops) == costs.SPONZA_LADDER_PIXELS == (72 + 227) / 2 * 128
    assert costs.train_pixels(228, 128) == costs.train_pixels(228, 128, None) == 228 * 128
    # a frame narrower than the widest crop: the crops stop at its width
    assert costs.train_pixels(100, 128, crops) == (72 + 100) / 2 * 128
    with_crops = costs.train_step_seconds("cpu", 16, 4, 228, 128, gan=False, aspect_crops=crops)
    assert with_crops == pytest.approx(step(16, 228, 128) * (72 + 227) / 2 / 228)


def test_sponzas_plan_reads_its_ladder_as_it_trained():
    """The costs come from Sponza's ladder on the Intel Xeon (45,900 steps: K = 8 4,043 s, 16 5,186 s, 32 9,774
    s); its recipe planned on a CPU gives those times back, where the plan read 1 h 36 / 2 h 41 / 5 h 38 before."""
    from pathlib import Path

    from diviewer.build.plan import make_plan
    from diviewer.train.recipe import load_recipe

    cpu = costs.Machine("cpu", 2, "test")
    plan = make_plan("sponza", load_recipe("sponza"), Path("w"), machine=cpu)
    est = {s.name: s.seconds for s in plan.stages}
    assert est["train_k8"] == pytest.approx(4043.0)
    assert est["train_k16"] == pytest.approx(5186.0)
    assert est["train_k32"] == pytest.approx(9774.0)


def test_sponzas_path_tracing_reads_its_capture_and_refinement_as_measured():
    """Sponza on the Intel Xeon (228x128, one pass): the 2026-12-03 capture's sidecars at 64 spp (median path tracing
    4.35 s, GL with the direct light over 4x4 0.4775 s), the 256-spp refinement's 9.6 s a frame for 192 samples, and
    the full evaluation set's 113.2 s a frame in seven renders (two at 1024 spp and the ladder)."""
    assert costs.refine_seconds("cpu", "sponza", 1, 228, 128, 64) == pytest.approx(4.35)
    assert costs.refine_seconds("cpu", "sponza", 1, 228, 128, 192) == pytest.approx(9.6)
    assert costs.capture_seconds("cpu", "sponza", 1, 228, 128, 64, direct_samples=4) == pytest.approx(4.35 + 0.4775)
    predicted = costs.capture_seconds("cpu", "sponza", 1, 228, 128, 2 * 1024 + 1 + 4 + 16 + 64 + 256, renders=7)
    assert predicted == pytest.approx(113.2, rel=0.03)
    assert costs.EVALSET_FACTOR["sponza"] == pytest.approx(113.2 / predicted)
    # each render pays the fixed part once; a scene costed as Sponza pays it too, cornell (measured whole) does not
    two = costs.refine_seconds("cpu", "sponza", 1, 228, 128, 64, renders=2)
    assert two - costs.refine_seconds("cpu", "sponza", 1, 228, 128, 64) == pytest.approx(
        costs.PT_SECONDS_PER_RENDER[("cpu", "sponza")])
    elsewhere = costs.refine_seconds("cpu", "elsewhere", 3, 64, 64, 16)
    assert elsewhere == costs.refine_seconds("cpu", "sponza", 3, 64, 64, 16)
    assert costs.refine_seconds("cpu", "cornell", 1, 128, 128, 256) == pytest.approx(1.2 * costs.ONE_PASS_SHARE)
    assert 0 < costs.PT_SECONDS_PER_RENDER[("cpu", "sponza")] < 4.35
