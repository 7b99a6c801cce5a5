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
