"""The truth filter at the extremes (diviewer.data.truth_filter): frames of one row or one column, light from 0 to
float16's largest, grazing and degenerate normals, depths from 1e-4 to 1e4, range terms from none to 1e3, broken
texels: every output finite and within the light around it, texels without geometry or with a broken input left as
they were."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from diviewer.data.truth_filter import TruthFilter, filter_irradiance, filter_truth

FOV = 60.0


def frame(h: int, w: int, seed: int, depth_scale: float = 3.0):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(h, w, 3)).astype(np.float32)
    n[..., 2] = np.abs(n[..., 2])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    depth = (depth_scale * rng.uniform(0.5, 2.0, (h, w))).astype(np.float32)
    return n, depth


@settings(max_examples=40, deadline=None)
@given(h=st.integers(1, 9), w=st.integers(1, 9), seed=st.integers(0, 2**16), levels=st.integers(1, 3),
       scale=st.sampled_from([0.0, 1e-6, 1.0, 1e3, 6.5e4]), depth=st.sampled_from([1e-4, 1.0, 1e4]),
       range_sigma=st.sampled_from([0.0, 1e-3, 0.6, 1e3]))
def test_outputs_are_finite_and_within_the_light_around_them(h, w, seed, levels, scale, depth, range_sigma):
    n, z = frame(h, w, seed, depth)
    e = (scale * np.random.default_rng(seed + 1).random((h, w, 3))).astype(np.float32)
    out = filter_irradiance(e, n, z, FOV, TruthFilter(levels=levels, range_sigma=range_sigma))
    assert out.shape == e.shape and out.dtype == np.float32 and np.all(np.isfinite(out))
    lo, hi = e.min(axis=(0, 1)), e.max(axis=(0, 1))
    assert np.all(out >= lo - 1e-6 * (1 + hi)) and np.all(out <= hi * (1 + 1e-5) + 1e-30)


@given(e=hnp.arrays(np.float32, (6, 7, 3), elements=st.floats(0, 6.5e4, width=32)))
@settings(max_examples=30, deadline=None)
def test_a_grazing_or_zero_normal_and_no_geometry_take_nothing_and_give_nothing(e):
    n, z = frame(6, 7, 0)
    n[1, 1] = [1.0, 0.0, 0.0]  # seen edge-on
    n[2, 2] = 0.0  # a G-buffer texel with no normal
    z[3, 3] = 0.0  # sky
    out = filter_irradiance(e, n, z, FOV, TruthFilter(levels=2))
    assert np.all(np.isfinite(out))
    np.testing.assert_array_equal(out[2, 2], e[2, 2])
    np.testing.assert_array_equal(out[3, 3], e[3, 3])


@pytest.mark.parametrize("range_sigma", [0.0, 0.6])
@pytest.mark.parametrize("bad", ["light", "normal", "depth"])
@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_a_broken_texel_stays_where_it_is(bad, value, range_sigma):
    n, z = frame(8, 8, 3)
    e = np.full((8, 8, 3), 0.5, np.float32)
    {"light": e, "normal": n, "depth": z}[bad][4, 4] = value
    out = filter_irradiance(e, n, z, FOV, TruthFilter(levels=2, range_sigma=range_sigma))
    others = np.ones((8, 8), bool)
    others[4, 4] = False
    assert np.all(np.isfinite(out[others])) and np.allclose(out[others], 0.5)


def test_black_and_white_albedo_and_huge_direct_light_round_trip_where_nothing_varies():
    n, z = frame(5, 5, 4)
    n[:] = [0.0, 0.0, 1.0]
    z[:] = 2.0
    for albedo in (0.0, 1e-8, 1.0):
        a = np.full((5, 5, 3), albedo, np.float32)
        direct = np.full((5, 5, 3), 6e4, np.float32)
        pt = direct + max(albedo, 0.05) * 3.0
        out = filter_truth(pt, direct, a, n, z, FOV)
        np.testing.assert_allclose(out, pt, rtol=1e-6)
