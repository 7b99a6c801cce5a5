"""diviewer.evaluation.truthmargin: a training truth's margin over a model's error, frame by frame (the tool that reports every
rung, and `diviewer eval`'s own figure on an evaluation set, are tested in test_metrics.py and test_evalset.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from diviewer.evaluation import truthmargin as tm


def test_truth_margin_takes_the_truths_noise_out_of_both_errors_before_the_margin():
    """The truth's own noise taken out of a rung's and a model's error before their margin is read, and a truth of
    more samples projected from a rung."""
    # against the converged image: the model's error 4e-4, a 256-spp rung's 1e-4 (6.0 dB); the truth's noise 2e-5
    assert tm.margin_db(4e-4 + 2e-5, 1e-4 + 2e-5, 2e-5) == pytest.approx(10 * math.log10(4.0))
    assert tm.margin_db(4e-4 + 2e-5, 1e-4 + 2e-5, 0.0) < 6.0 - 0.3, "read as scored, the truth's noise hides margin"
    # an error at or below the truth's own noise is one the truth cannot resolve: no margin, not a floored one
    assert tm.margin_db(1e-4, 2e-4, 1e-4) is None and tm.margin_db(4e-4, 1e-4, 1e-4) is None
    # twice the samples halve the rung's own error; the truth's noise comes back as a measured rung would carry it
    assert tm.projected_mse(1e-4 + 2e-5, 2e-5, 256, 512) == pytest.approx(5e-5 + 2e-5)
    assert tm.projected_mse(1e-5, 2e-5, 256, 512) is None
    s = tm.summarize([{"m": 7.0}, {"m": 5.0}, {"m": 6.0}, {"m": 9.0}, {"m": None}], "m")
    assert s == {"median_db": 6.5, "lowest_db": 5.0, "share_at_least_6db": 0.75, "frames": 4, "unresolved": 1}
    assert tm.summarize([{"m": None}], "m") == {"median_db": None, "lowest_db": None, "share_at_least_6db": None,
                                                   "frames": 0, "unresolved": 1}


def test_truth_margin_of_simulated_renders_is_the_one_against_the_converged_image():
    """Noisy images as the evaluation set holds them (a converged image, a truth and its second seed at 1024 spp, a
    rung at 256): read through mse(pt_b, pt) / 2, the margin is the converged image's within 0.2 dB."""
    rng = np.random.default_rng(0)
    converged = rng.random((128, 128, 3))
    sigma = 0.5
    render = lambda spp: converged + rng.normal(0.0, sigma / math.sqrt(spp), converged.shape)  # noqa: E731
    truth, second, rung = render(1024), render(1024), render(256)
    model = converged + 0.1 * np.sin(np.arange(128))[None, :, None]
    mse = lambda a, b: float(np.mean((a - b) ** 2))  # noqa: E731
    exact = 10 * math.log10(mse(model, converged) / mse(rung, converged))
    got = tm.margin_db(mse(model, truth), mse(rung, truth), mse(second, truth) / 2)
    assert got == pytest.approx(exact, abs=0.2)
    assert 10 * math.log10(mse(model, truth) / mse(rung, truth)) < exact - 0.5  # as scored: the noise hides ~1 dB
    projected = tm.projected_mse(mse(rung, truth), mse(second, truth) / 2, 256, 1024)
    assert projected - mse(second, truth) / 2 == pytest.approx(sigma ** 2 / 1024, rel=0.05)


def test_the_truth_a_model_trained_on_is_read_from_its_card():
    assert tm.model_truth_spp({"recipe": {"capture": {"spp": 64}}}) == 64
    # a refined truth: its fewest samples over the train frames (the sampler rounds some counts up), not the recipe's
    assert tm.model_truth_spp({"truth_spp": {"min": 259, "max": 262}, "recipe": {"capture": {"spp": 256}}}) == 259
    assert tm.model_truth_spp({}) is None and tm.model_truth_spp({"recipe": {"capture": None}}) is None
    assert tm.model_truth_spp({"recipe": {"capture": {"spp": 64, "gt": "vxgi"}}}) is None  # not a noisy truth
    # a filtered truth: the set's ladder is not filtered, its rungs do not measure it (filtered_truth_margin.py does)
    assert tm.model_truth_spp({"truth_spp": {"min": 259, "max": 262},
                               "recipe": {"capture": {"spp": 256, "truth_filter": {"levels": 1}}}}) is None


def test_a_split_reads_its_truths_rung_or_projects_the_top_one():
    """Rows as `diviewer eval` scores them frame by frame: the rung of the truth's count where the ladder has it,
    else the top rung scaled by 1 / spp; a frame the truth cannot resolve is counted, not scored."""
    noise = [{"mse_tm": 4e-5}, {"mse_tm": 4e-5}, {"mse_tm": 4e-5}]  # the second seed's: twice the truth's own 2e-5
    model = [{"mse_tm": 4e-4 + 2e-5}, {"mse_tm": 1e-3 + 2e-5}, {"mse_tm": 1e-5}]  # the third below the truth's noise
    ladder = {64: [{"mse_tm": 4e-4 + 2e-5}] * 3, 256: [{"mse_tm": 1e-4 + 2e-5}] * 3}
    at64 = tm.truth_margin(model, noise, ladder, 64)
    assert at64["truth_spp"] == 64 and at64["from"] == "pt_spp64"
    assert (at64["frames"], at64["unresolved"]) == (2, 1)
    assert at64["lowest_db"] == pytest.approx(0.0, abs=1e-9)
    assert at64["median_db"] == pytest.approx(10 * math.log10(2.5) / 2, abs=1e-9)
    at512 = tm.truth_margin(model, noise, ladder, 512)
    assert at512["from"] == "pt_spp256, projected to 512 spp"
    assert at512["lowest_db"] == pytest.approx(10 * math.log10(4e-4 / 5e-5))  # the 256 rung's own error halved
    assert at512["share_at_least_6db"] == 1.0
    with pytest.raises(ValueError):  # rows of other frames: refused, not paired short
        tm.truth_margin(model[:2], noise, ladder, 64)
