"""tools/experiments/truth_margin.py: the truth's own noise taken out of a rung's and a model's error before their
margin is read, and a truth of more samples projected from a rung."""

import math

import numpy as np
import pytest

from tool_modules import load_tool


def test_the_truths_noise_is_taken_out_of_both_errors_before_the_margin():
    tool = load_tool("experiments/truth_margin")
    # against the converged image: the model's error 4e-4, a 256-spp rung's 1e-4 (6.0 dB); the truth's noise 2e-5
    assert tool.margin_db(4e-4 + 2e-5, 1e-4 + 2e-5, 2e-5) == pytest.approx(10 * math.log10(4.0))
    assert tool.margin_db(4e-4 + 2e-5, 1e-4 + 2e-5, 0.0) < 6.0 - 0.3, "read as scored, the truth's noise hides margin"
    assert tool.margin_db(1e-4, 2e-4, 1e-4) < -70, "a model at the truth's own noise: floored, not a math error"
    # twice the samples halve the rung's own error; the truth's noise comes back as a measured rung would carry it
    assert tool.projected_mse(1e-4 + 2e-5, 2e-5, 256, 512) == pytest.approx(5e-5 + 2e-5)
    s = tool.summarize([{"m": 7.0}, {"m": 5.0}, {"m": 6.0}, {"m": 9.0}], "m")
    assert s == {"median_db": 6.5, "lowest_db": 5.0, "share_at_least_6db": 0.75, "frames": 4}


def test_the_margin_of_simulated_renders_is_the_one_against_the_converged_image():
    """Noisy images as the evaluation set holds them (a converged image, a truth and its second seed at 1024 spp, a
    rung at 256): read through mse(pt_b, pt) / 2, the margin is the converged image's within 0.2 dB."""
    tool = load_tool("experiments/truth_margin")
    rng = np.random.default_rng(0)
    converged = rng.random((128, 128, 3))
    sigma = 0.5
    render = lambda spp: converged + rng.normal(0.0, sigma / math.sqrt(spp), converged.shape)  # noqa: E731
    truth, second, rung = render(1024), render(1024), render(256)
    model = converged + 0.1 * np.sin(np.arange(128))[None, :, None]
    mse = lambda a, b: float(np.mean((a - b) ** 2))  # noqa: E731
    exact = 10 * math.log10(mse(model, converged) / mse(rung, converged))
    got = tool.margin_db(mse(model, truth), mse(rung, truth), mse(second, truth) / 2)
    assert got == pytest.approx(exact, abs=0.2)
    assert 10 * math.log10(mse(model, truth) / mse(rung, truth)) < exact - 0.5  # as scored: the noise hides ~1 dB
    projected = tool.projected_mse(mse(rung, truth), mse(second, truth) / 2, 256, 1024)
    assert projected - mse(second, truth) / 2 == pytest.approx(sigma ** 2 / 1024, rel=0.05)
