"""diviewer.contract.padding: any frame size to the network's stride and back, the same for training and the runtime."""

from __future__ import annotations

import numpy as np
import pytest

from diviewer.contract.padding import crop_nhwc, crop_slice, pad_before, pad_index, pad_nhwc, padded_size, valid_mask


@pytest.mark.parametrize(("n", "m", "size", "before"), [(128, 128, 128, 0), (228, 128, 256, 14), (72, 128, 128, 28),
                                                       (5, 4, 8, 1), (1, 16, 16, 7), (33, 32, 64, 15)])
def test_sizes_and_placement(n, m, size, before):
    assert padded_size(n, m) == size and pad_before(n, m) == before
    idx = pad_index(n, m)
    assert len(idx) == size and idx[before] == 0 and idx[before + n - 1] == n - 1
    assert np.all(idx[:before] == 0) and np.all(idx[before + n:] == n - 1)  # edges replicated
    assert valid_mask(n, m).sum() == n and valid_mask(n, m)[crop_slice(n, m)].all()


def test_pad_then_crop_is_the_identity_and_padding_replicates_edges():
    rng = np.random.default_rng(0)
    x = rng.random((2, 20, 45, 10)).astype(np.float32)
    p = pad_nhwc(x, 16)
    assert p.shape == (2, 32, 48, 10) and p.flags.c_contiguous
    np.testing.assert_array_equal(crop_nhwc(p, 20, 45, 16), x)
    np.testing.assert_array_equal(p[:, 0], p[:, pad_before(20, 16)])  # the top row, repeated
    np.testing.assert_array_equal(p[:, :, -1], x[:, pad_index(20, 16), -1])  # the right column
    assert pad_nhwc(p, 16) is p  # a multiple already: untouched


def test_the_same_index_pads_torch_tensors_as_training_does():
    torch = pytest.importorskip("torch")
    x = np.random.default_rng(1).random((1, 3, 10, 13)).astype(np.float32)  # NCHW, as training holds it
    rows, cols = (torch.from_numpy(pad_index(n, 8)) for n in (10, 13))
    t = torch.from_numpy(x).index_select(2, rows).index_select(3, cols)
    np.testing.assert_array_equal(t.permute(0, 2, 3, 1).numpy(), pad_nhwc(x.transpose(0, 2, 3, 1), 8))


def test_bad_sizes_are_refused():
    with pytest.raises(ValueError):
        padded_size(0, 16)


@pytest.mark.parametrize(("n", "m", "guard", "size", "before"), [(128, 128, 8, 256, 64), (228, 128, 8, 256, 14),
                                                                (110, 128, 8, 128, 9), (120, 128, 8, 256, 68),
                                                                (16, 16, 1, 32, 8), (7, 4, 0, 8, 0)])
def test_a_guard_asks_for_that_much_padding_a_side_at_least(n, m, guard, size, before):
    assert padded_size(n, m, guard) == size and pad_before(n, m, guard) == before
    assert before >= guard and size - n - before >= guard
    idx = pad_index(n, m, guard)
    assert len(idx) == size and np.all(idx[:before] == 0) and np.all(idx[before + n:] == n - 1)
    assert valid_mask(n, m, guard)[crop_slice(n, m, guard)].all() and valid_mask(n, m, guard).sum() == n


def test_the_guard_pads_columns_only_and_crops_back():
    from diviewer.contract.padding import EDGE_GUARD, edge_guard

    x = np.random.default_rng(1).random((1, 32, 32, 3)).astype(np.float32)
    p = pad_nhwc(x, 16, 4)
    assert p.shape == (1, 32, 48, 3)  # rows fill the stride: unguarded; columns 8 a side
    np.testing.assert_array_equal(crop_nhwc(p, 32, 32, 16, 4), x)
    np.testing.assert_array_equal(p[:, :, :8], np.repeat(x[:, :, :1], 8, axis=2))
    assert edge_guard(None) == 0 and edge_guard((0.5625, 1.7778)) == EDGE_GUARD > 0
    with pytest.raises(ValueError, match="guard"):
        padded_size(10, 4, -1)
