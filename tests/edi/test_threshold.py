"""Threshold search: the bounded search finds known minima; the energy recovers the simulator's C; the mask."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eigs.edi import threshold as thr
from eigs.edi.mask import event_rate_map, hot_pixel_mask
from eigs.edi.pipeline import EdiOptions, compute_edi
from tests.edi.sim import make_scene


@pytest.mark.parametrize("c0", [0.05, 0.137, 0.5, 1.0])
def test_bounded_search_finds_minimum(c0):
    calls = []

    def f(c):
        calls.append(c)
        return (math.log(c) - math.log(c0)) ** 2

    c, e = thr.bounded_search(f)
    assert abs(c / c0 - 1) < 2e-3 and e < 1e-5
    assert all(thr.C_MIN - 1e-12 <= x <= thr.C_MAX + 1e-12 for x in calls)
    assert len(calls) < 60


def test_bounded_search_ignores_nan():
    c, _ = thr.bounded_search(lambda c: float("nan") if c > 0.3 else (c - 0.2) ** 2)
    assert abs(c - 0.2) < 1e-3


@pytest.mark.parametrize("c_true", [0.2, 0.3])
def test_estimated_threshold_recovers_simulator_c(c_true):
    scene, sharp = make_scene(n_views=3, h=72, w=96, c=c_true, shake_px=6.0, seed=5)
    res = compute_edi(scene, EdiOptions(show_progress=False))
    c = float(res.threshold[0])
    assert res.threshold_scope == "scene" and np.all(res.threshold == c)
    assert abs(c / c_true - 1) <= 0.2, c
    # and the latent frames beat the blurry frame against the truth at the same times
    psnr = lambda a, b: 10 * np.log10(1 / np.mean((a - b) ** 2))  # noqa: E731
    lat = np.mean([psnr(res.latent[v, k], sharp[v, k]) for v in range(3) for k in range(5)])
    blur = np.mean([psnr(scene.frames.blurry[v] / 255.0, sharp[v, k]) for v in range(3) for k in range(5)])
    assert lat > blur + 3.0
    per_view = compute_edi(scene, EdiOptions(threshold_scope="view", show_progress=False))
    assert per_view.threshold_scope == "view" and np.all(np.abs(per_view.threshold / c_true - 1) < 0.35)


def test_hot_pixel_mask():
    rng = np.random.default_rng(0)
    h, w = 50, 60
    x = rng.integers(0, w, 20000)
    y = rng.integers(0, h, 20000)
    # 10 flickering pixels with 300 events each
    hx, hy = rng.integers(0, w, 10), rng.integers(0, h, 10)
    x = np.concatenate([x, np.repeat(hx, 300)])
    y = np.concatenate([y, np.repeat(hy, 300)])
    m = hot_pixel_mask(event_rate_map(x, y, h, w))
    assert m[hy, hx].all() and m.sum() == len(set(zip(hx.tolist(), hy.tolist(), strict=True)))
    # a clean recording (busiest pixels a few times the mean) keeps every pixel
    clean = hot_pixel_mask(event_rate_map(x[:20000], y[:20000], h, w))
    assert not clean.any()
    assert not hot_pixel_mask(np.zeros((4, 4)), 0.01).any()
    assert not hot_pixel_mask(event_rate_map(x, y, h, w), 0.0).any()
