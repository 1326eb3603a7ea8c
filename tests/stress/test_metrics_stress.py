"""SSIM and LPIPS on constant images; BRISQUE's clear error on them.

Extends tests/metrics (zeros against ones): for any two constant levels, every SSIM mode equals the closed form
(2ab + C1)/(a² + b² + C1) where the windows see only the constants (the skimage modes after their border crop;
the 3dgs mode is compared with an independent SciPy zero-padded filtering), float32 D-SSIM (training) stays within
a stated bound of float64 with finite gradients; LPIPS of an image with itself is 0 and of two constants finite,
non-negative and symmetric; BRISQUE raises EigsError("constant image") by design.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from eigs.errors import EigsError
from eigs.metrics.pixel import K1, K2, SSIM_MODES, ssim, ssim_torch
from tests.metrics.conftest import resources_dir  # noqa: F401  (the LPIPS/BRISQUE model files fixture)
from tests.stress.budget import stress

LEVELS = st.sampled_from([0.0, 1 / 255, 0.5, 254 / 255, 1.0]) | st.floats(0.0, 1.0)


def _ssim_3dgs_scipy(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM mode 3dgs with SciPy: 11×11 Gaussian σ 1.5 (normalised), zero padding, population statistics."""
    from scipy.ndimage import correlate1d

    x = np.arange(11) - 5.0
    g = np.exp(-(x**2) / (2 * 1.5**2))
    g /= g.sum()

    def filt(img: np.ndarray) -> np.ndarray:
        return correlate1d(correlate1d(img, g, axis=0, mode="constant"), g, axis=1, mode="constant")

    vals = []
    for ch in range(a.shape[2]):
        x_, y_ = a[..., ch], b[..., ch]
        mx, my = filt(x_), filt(y_)
        vx, vy, cxy = filt(x_ * x_) - mx**2, filt(y_ * y_) - my**2, filt(x_ * y_) - mx * my
        c1, c2 = K1**2, K2**2
        vals.append(((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx**2 + my**2 + c1) * (vx + vy + c2)))
    return float(np.mean(vals))


@stress(40)
@given(a=LEVELS, b=LEVELS, h=st.integers(1, 30), w=st.integers(1, 30), c=st.sampled_from([1, 3]))
def test_ssim_of_constant_images(a, b, h, w, c):
    x, y = np.full((h, w, c), a), np.full((h, w, c), b)
    closed = lambda a, b, L: (2 * a * b + (K1 * L) ** 2) / (a * a + b * b + (K1 * L) ** 2)  # noqa: E731
    for mode in SSIM_MODES:
        if mode != "3dgs" and min(h, w) < (11 if mode == "skimage-gaussian" else 7):
            with pytest.raises(EigsError, match="smaller than"):
                ssim(x, y, mode)
            continue
        got = ssim(x, y, mode)
        assert math.isfinite(got) and -1.0 <= got <= 1.0 + 1e-12
        if mode == "skimage-gaussian":
            assert abs(got - closed(a, b, 1.0)) <= 1e-12
        elif mode == "deblurnerf":
            assert abs(got - closed(2 * a - 1, 2 * b - 1, 2.0)) <= 1e-12
        else:
            assert abs(got - _ssim_3dgs_scipy(x, y)) <= 1e-9
        assert abs(ssim(x, x, mode) - 1.0) <= 1e-12


@stress(30)
@given(a=LEVELS, b=LEVELS, h=st.integers(1, 24), w=st.integers(1, 24))
def test_dssim_float32_on_constants_is_within_its_bound_with_finite_gradients(a, b, h, w):
    """float32 (training) against float64: |Δ SSIM| ≤ 2e-4 on constant images (var = E[x²] − μ² cancels in
    float32: ~1e-7 against C2 = 9e-4); gradients finite."""
    x = torch.full((1, 3, h, w), a, dtype=torch.float32, requires_grad=True)
    y = torch.full((1, 3, h, w), b, dtype=torch.float32)
    s32 = ssim_torch(x, y)
    (1 - s32).backward()
    assert torch.isfinite(x.grad).all()
    s64 = ssim_torch(x.detach().double(), y.double())
    assert abs(s32.item() - s64.item()) <= 2e-4




@stress(4)
@given(a=LEVELS, b=LEVELS, net=st.sampled_from(["alex", "vgg"]))
def test_lpips_of_constant_images(resources_dir, a, b, net):  # noqa: F811
    from eigs.metrics.perceptual import lpips

    x, y = np.full((64, 64, 3), a), np.full((64, 64, 3), b)
    d_xy = lpips(x, y, net, resources_dir)
    assert math.isfinite(d_xy) and d_xy >= 0.0
    assert abs(d_xy - lpips(y, x, net, resources_dir)) <= 1e-6
    assert lpips(x, x, net, resources_dir) == 0.0


@stress(6)
@given(level=st.integers(0, 255), channels=st.sampled_from([1, 3]), variant=st.sampled_from(["original", "opencv"]))
def test_brisque_on_a_constant_image_is_the_clear_error(resources_dir, level, channels, variant):  # noqa: F811
    from eigs.metrics.noreference import brisque

    with pytest.raises(EigsError, match="constant image") as info:
        brisque(np.full((48, 40, channels), level, np.uint8), resources_dir, variant=variant)
    assert "\n" not in str(info.value)
