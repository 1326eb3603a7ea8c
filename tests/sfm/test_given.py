"""Epipolar-band matching of the known-pose mode: the fast `band_matches` against the dense definition."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.sfm.given import band_matches


def dense_reference(sims, num, scale_a, scale_b, max_px, ratio):
    """The definition written out on full matrices: descriptor distances, the band as distances in pixels, mutual
    nearest neighbours, and the ratio test against the second-smallest distance of the row and of the column."""
    na, nb = sims.shape
    if na == 0 or nb == 0:
        return np.zeros((0, 2), np.int64)
    dist = np.sqrt(np.maximum(2.0 - 2.0 * sims.astype(np.float64), 0.0))
    band = (num * scale_a[:, None] <= max_px) & (num * scale_b[None, :] <= max_px)
    dist[~band] = np.inf
    out = []
    for i in range(na):
        j = int(np.argmin(dist[i]))
        d1 = dist[i, j]
        if not np.isfinite(d1) or int(np.argmin(dist[:, j])) != i:
            continue
        row = np.sort(dist[i])
        col = np.sort(dist[:, j])
        d2_row = row[1] if nb >= 2 else np.inf
        d2_col = col[1] if na >= 2 else np.inf
        if d1 < ratio * d2_row and d1 < ratio * d2_col:
            out.append((i, j))
    return np.array(out, np.int64).reshape(-1, 2)


def _case(rng, na, nb, planted):
    """Unit descriptors with ``planted`` true correspondences (noisy copies), band values spread around the
    threshold; similarities in float32 as the matcher computes them."""
    d = 16
    a = rng.normal(size=(na, d))
    b = rng.normal(size=(nb, d))
    k = min(planted, na, nb)
    b[:k] = a[:k] + 0.3 * rng.normal(size=(k, d))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    sims = (a.astype(np.float32) @ b.astype(np.float32).T).astype(np.float32)
    num = np.abs(rng.normal(scale=2e-3, size=(na, nb)))
    num[np.arange(k), np.arange(k)] *= 0.1  # true pairs lie near their epipolar lines
    scale_a = rng.uniform(500, 1500, na)
    scale_b = rng.uniform(500, 1500, nb)
    return sims, num, scale_a, scale_b


@pytest.mark.parametrize(("na", "nb", "planted"), [(60, 50, 30), (200, 240, 120), (1, 5, 1), (5, 1, 1), (2, 2, 2)])
def test_band_matches_equal_the_dense_definition(na, nb, planted):
    rng = np.random.default_rng(na * 1000 + nb)
    for _ in range(5):
        args = (*_case(rng, na, nb, planted), 4.0, 0.8)
        got = band_matches(*args)
        want = dense_reference(*args)
        np.testing.assert_array_equal(got, want)
    # a realistic case finds the planted pairs
    sims, num, sa, sb = _case(np.random.default_rng(7), 200, 200, 150)
    m = band_matches(sims, num, sa, sb, 4.0, 0.8)
    assert len(m) >= 100 and np.mean(m[:, 0] == m[:, 1]) > 0.95


def test_band_matches_edges():
    empty = band_matches(np.zeros((0, 4), np.float32), np.zeros((0, 4)), np.zeros(0), np.ones(4), 4.0, 0.8)
    assert empty.shape == (0, 2)
    # nothing inside the band: no match
    sims = np.eye(3, dtype=np.float32)
    far = np.full((3, 3), 1.0)
    assert band_matches(sims, far, np.ones(3), np.ones(3), 0.5, 0.8).shape == (0, 2)
    # exact ties with the second best fail the ratio test (d1 < ratio·d2 is strict)
    tie = np.array([[0.9, 0.9], [0.1, 0.2]], np.float32)
    got = band_matches(tie, np.zeros((2, 2)), np.ones(2), np.ones(2), 1.0, 0.8)
    np.testing.assert_array_equal(got, dense_reference(tie, np.zeros((2, 2)), np.ones(2), np.ones(2), 1.0, 0.8))
    assert not any(i == 0 for i, _ in got)
