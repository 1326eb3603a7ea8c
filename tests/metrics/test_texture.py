"""eigs.metrics.texture: SSIM's window local variance against closed forms, and the visibility ratio."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eigs.errors import EigsError
from eigs.metrics.texture import SSIM_C2, local_variance, luma, ssim_texture_visibility

G = np.exp(-((np.arange(11) - 5) ** 2) / (2 * 1.5**2))
G = G / G.sum()  # SSIM's 1-D window, independently


def test_flat_frames_have_no_local_variance():
    var = local_variance(torch.full((2, 40, 50), 0.3, dtype=torch.float64))
    assert var.shape == (2, 30, 40) and float(var.max()) < 1e-15


def test_white_noise_gives_its_variance_times_one_minus_the_window_energy():
    # i.i.d. noise of variance s²: E[Σ w x² − (Σ w x)²] = s² (1 − Σ w²)
    noise = torch.from_numpy(np.random.default_rng(0).normal(0.4, 0.02, (4, 200, 200)))
    expected = 0.02**2 * (1.0 - (np.outer(G, G) ** 2).sum())
    assert abs(float(local_variance(noise).mean()) / expected - 1) < 0.01


def test_a_step_edge_gives_the_window_tail_closed_form():
    # a step of height h: a window with weight P beyond it has variance h² P (1 − P); P the 1-D window's tail sums
    edge = torch.zeros(1, 21, 22, dtype=torch.float64)
    edge[:, :, 11:] = 0.1
    tails = np.array([G[k:].sum() for k in range(12)])
    assert abs(float(local_variance(edge).max()) - (0.01 * tails * (1 - tails)).max()) < 1e-15


def test_visibility_is_the_median_over_c2_and_luma_is_bt709():
    rgb = torch.zeros(1, 12, 12, 3)
    rgb[..., 1] = 1.0
    assert torch.allclose(luma(rgb), torch.full((1, 12, 12), 0.7152, dtype=torch.float64))
    rng = np.random.default_rng(1)
    frames = torch.from_numpy(rng.uniform(0, 1, (3, 30, 30, 1)))
    v = np.sort(local_variance(frames[..., 0]).numpy().ravel())
    med = v[(len(v) - 1) // 2]  # the lower middle value (an even count here)
    assert ssim_texture_visibility(frames) == pytest.approx(med / 0.03**2, rel=1e-12)
    assert SSIM_C2 == pytest.approx(0.0009)


def test_bad_frames_raise_clear_errors():
    with pytest.raises(EigsError, match="11"):
        local_variance(torch.zeros(1, 5, 40))
    with pytest.raises(EigsError, match=r"\(N, H, W, 1 or 3\)"):
        luma(torch.zeros(2, 5, 5))
    bad = torch.zeros(1, 12, 12, 3)
    bad[0, 0, 0, 0] = float("nan")
    with pytest.raises(EigsError, match="NaN"):
        ssim_texture_visibility(bad)


def test_local_variance_frame_by_frame_equals_the_batched_convolution():
    """local_variance convolves one frame at a time (bounded memory at 800×800); it must give the batched float64
    convolution's values exactly."""
    import torch

    from eigs.metrics.pixel import gaussian_window
    from eigs.metrics.texture import local_variance

    y = torch.rand(5, 37, 52, generator=torch.Generator().manual_seed(3))
    g = gaussian_window(11, 1.5, dtype=torch.float64)
    w = torch.outer(g, g)[None, None]
    x = y.to(torch.float64)[:, None]
    mean, mean_sq = torch.nn.functional.conv2d(x, w), torch.nn.functional.conv2d(x * x, w)
    expected = (mean_sq - mean * mean).clamp_min(0.0)[:, 0]
    got = local_variance(y)
    assert got.shape == (5, 27, 42) and got.dtype == torch.float64
    assert torch.equal(got, expected)
