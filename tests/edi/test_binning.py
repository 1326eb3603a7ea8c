"""Binning and latent times: vectorised binning equals a slow reference loop exactly."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.edi import binning
from eigs.errors import EigsError


def _slow_bins(x, y, t, p, edges, h, w, mask=None):
    out = np.zeros((len(edges) - 1, h, w), np.int64)
    for xi, yi, ti, pi in zip(x, y, t, p, strict=True):
        if mask is not None and mask[yi, xi]:
            continue
        for k in range(len(edges) - 1):
            if edges[k] <= ti < edges[k + 1]:
                out[k, yi, xi] += pi
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bin_events_matches_loop(seed):
    rng = np.random.default_rng(seed)
    h, w, n = 7, 9, 3000
    edges = np.sort(rng.choice(np.arange(0, 10_000), size=6, replace=False)).astype(np.int64)
    t = rng.integers(-100, 10_100, size=n).astype(np.int64)
    t[:50] = rng.choice(edges, size=50)  # events exactly on edges
    x = rng.integers(0, w, size=n).astype(np.uint16)
    y = rng.integers(0, h, size=n).astype(np.uint16)
    p = rng.choice(np.array([-1, 1], np.int8), size=n)
    mask = rng.random((h, w)) < 0.1 if seed == 2 else None
    got = binning.bin_events(x, y, t, p, edges, h, w, mask)
    assert got.dtype == np.int32
    np.testing.assert_array_equal(got, _slow_bins(x, y, t, p, edges, h, w, mask))


def test_cumulative_counts():
    counts = np.arange(2 * 3 * 2 * 2).reshape(2, 3, 2, 2) - 10
    cum = binning.cumulative_counts(counts)
    assert cum.shape == (2, 4, 2, 2)
    assert np.all(cum[:, 0] == 0)
    np.testing.assert_array_equal(cum[:, 3], counts.sum(axis=1))


def test_latent_times_formula_and_synth_convention():
    exp = np.array([[1000, 101_000], [5, 12]], np.int64)
    lt = binning.latent_times(exp, 4)
    np.testing.assert_array_equal(lt[0], [1000, 26_000, 51_000, 76_000, 101_000])
    assert lt[1, 0] == 5 and lt[1, -1] == 12 and np.all(np.diff(lt[1]) >= 0)
    from eigs.synth.trajectory import Timeline  # a broken import must fail this test, not skip it

    tl = Timeline(3, 100_000, 200_000, 10_000, 80, 40, 2)
    for b in (2, 4, 8):
        np.testing.assert_array_equal(binning.latent_times(tl.exposures, b), tl.latent_times(b))


def test_prebinned_mismatch_is_a_clear_error():
    assert binning.check_prebinned("s.h5", 4, None) == 4
    assert binning.check_prebinned("s.h5", 4, 4) == 4
    with pytest.raises(EigsError, match="pre-binned into 4 bins.*--bins 4"):
        binning.check_prebinned("s.h5", 4, 8)
