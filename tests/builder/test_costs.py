"""The build's cost model: a training step's time across K on the CPU (diviewer.builder.costs)."""

from __future__ import annotations

import math

import pytest

from diviewer.builder import costs


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

    from diviewer.builder.plan import make_plan
    from diviewer.train.recipe import load_recipe

    cpu = costs.Machine("cpu", 2, "test")
    plan = make_plan("sponza", load_recipe("sponza"), Path("w"), machine=cpu)
    est = {s.name: s.seconds for s in plan.stages}
    assert est["train_k8"] == pytest.approx(4043.0)
    assert est["train_k16"] == pytest.approx(5186.0)
    assert est["train_k32"] == pytest.approx(9774.0)



def test_the_direct_light_over_each_pixels_area_reads_sponzas_capture_as_measured():
    """Sponza's 2026-12-03 capture (228x128, the direct light over 4x4): 0.4775 s of GL a frame, the median of its
    sidecars; the G-buffer's 0.05 s a 128x128 frame, then 16 passes of the area's direct light."""
    px = 228 * 128 / costs.PIXELS_REF
    area = costs.capture_seconds("cpu", "sponza", 1, 228, 128, 64, direct_samples=4)
    plain = costs.capture_seconds("cpu", "sponza", 1, 228, 128, 64)
    assert area - costs.refine_seconds("cpu", "sponza", 1, 228, 128, 64) == pytest.approx(0.4775)
    assert plain - costs.refine_seconds("cpu", "sponza", 1, 228, 128, 64) == pytest.approx(0.05 * px)
    # s x s passes: the area's cost grows with s squared, none at s = 1
    a2 = costs.capture_seconds("cpu", "sponza", 1, 228, 128, 64, direct_samples=2) - plain
    assert (area - plain) / a2 == pytest.approx(4.0)
    assert costs.capture_seconds("cpu", "sponza", 1, 228, 128, 64, direct_samples=1) == plain
    # path tracing stays linear in the samples (measured so: 16 / 64 / 192 spp)
    assert costs.refine_seconds("cpu", "sponza", 1, 228, 128, 192) == pytest.approx(
        3 * costs.refine_seconds("cpu", "sponza", 1, 228, 128, 64))
