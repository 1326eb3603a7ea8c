"""PSNR and SSIM against closed forms, a float64 NumPy reference and scikit-image."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from numpy.lib.stride_tricks import sliding_window_view
from skimage.metrics import structural_similarity

from eigs.errors import EigsError
from eigs.metrics.pixel import SSIM_MODES, psnr, psnr_torch, ssim, ssim_torch


def _pair(shape: tuple[int, ...], seed: int = 0, noise: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    # smooth structure plus noise, so SSIM is far from 0 and 1
    a = rng.random(shape)
    a = (a + np.roll(a, 1, axis=0) + np.roll(a, 1, axis=1)) / 3
    b = np.clip(a + noise * rng.standard_normal(shape), 0, 1)
    return a, b


def ssim_3dgs_reference(a: np.ndarray, b: np.ndarray) -> float:
    """3DGS SSIM by its definition: direct 11x11 Gaussian window sums over zero-padded images, float64."""
    a = a[:, :, None] if a.ndim == 2 else a
    b = b[:, :, None] if b.ndim == 2 else b
    x = np.arange(11) - 5
    g = np.exp(-(x**2) / (2 * 1.5**2))
    g /= g.sum()
    w = np.outer(g, g)
    c1, c2 = 0.01**2, 0.03**2
    maps = []
    for c in range(a.shape[2]):
        pa = sliding_window_view(np.pad(a[:, :, c], 5), (11, 11))
        pb = sliding_window_view(np.pad(b[:, :, c], 5), (11, 11))
        mu_a = np.einsum("ijkl,kl->ij", pa, w)
        mu_b = np.einsum("ijkl,kl->ij", pb, w)
        s_aa = np.einsum("ijkl,kl->ij", pa * pa, w) - mu_a**2
        s_bb = np.einsum("ijkl,kl->ij", pb * pb, w) - mu_b**2
        s_ab = np.einsum("ijkl,kl->ij", pa * pb, w) - mu_a * mu_b
        maps.append(((2 * mu_a * mu_b + c1) * (2 * s_ab + c2)) / ((mu_a**2 + mu_b**2 + c1) * (s_aa + s_bb + c2)))
    return float(np.mean(maps))


def skimage_ssim(a: np.ndarray, b: np.ndarray, mode: str) -> float:
    a = a[:, :, None] if a.ndim == 2 else a
    b = b[:, :, None] if b.ndim == 2 else b
    if mode == "skimage-gaussian":
        return structural_similarity(
            a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0, channel_axis=2
        )
    return structural_similarity(2 * a - 1, 2 * b - 1, data_range=2.0, channel_axis=2)


# ----------------------------------------------------------------------------------------------- PSNR


def test_psnr_closed_form():
    a = np.zeros((8, 9, 3))
    assert psnr(a, a + 0.1) == pytest.approx(20.0, abs=1e-12)
    u = np.zeros((4, 5), np.uint8)
    assert psnr(u, u + 51) == pytest.approx(10 * math.log10(1 / 0.2**2), abs=1e-12)  # 51/255 = 0.2 exactly


def test_psnr_random_matches_formula_and_torch():
    a, b = _pair((33, 47, 3))
    expected = 10 * math.log10(1 / np.mean((a - b) ** 2))
    assert psnr(a, b) == pytest.approx(expected, abs=1e-12)
    t = psnr_torch(torch.from_numpy(a.transpose(2, 0, 1)), torch.from_numpy(b.transpose(2, 0, 1)))
    assert float(t) == pytest.approx(expected, abs=1e-9)


def test_psnr_identical_is_inf_and_torch_finite():
    a, _ = _pair((5, 5, 3))
    assert psnr(a, a) == math.inf
    assert torch.isfinite(psnr_torch(torch.zeros(2, 3, 4, 4), torch.zeros(2, 3, 4, 4))).all()


# ----------------------------------------------------------------------------------------------- SSIM 3dgs


@pytest.mark.parametrize("shape", [(40, 52, 3), (37, 29), (31, 30, 1), (5, 7, 3), (1, 1, 3), (3, 12)])
def test_ssim_3dgs_matches_float64_reference(shape):
    a, b = _pair(shape, seed=len(shape) + shape[0])
    assert abs(ssim(a, b, "3dgs") - ssim_3dgs_reference(a, b)) < 1e-6


def test_ssim_torch_float32_batched_and_per_image():
    a1, b1 = _pair((24, 30, 3), seed=1)
    a2, b2 = _pair((24, 30, 3), seed=2, noise=0.3)
    x = torch.from_numpy(np.stack([a1, a2]).transpose(0, 3, 1, 2)).float()
    y = torch.from_numpy(np.stack([b1, b2]).transpose(0, 3, 1, 2)).float()
    ref = [ssim_3dgs_reference(a1, b1), ssim_3dgs_reference(a2, b2)]
    per = ssim_torch(x, y, reduction="none")
    assert per.shape == (2,)
    np.testing.assert_allclose(per.numpy(), ref, atol=2e-6)
    assert float(ssim_torch(x, y)) == pytest.approx(np.mean(ref), abs=2e-6)
    assert float(ssim_torch(x[0], y[0])) == pytest.approx(ref[0], abs=2e-6)


def test_ssim_torch_is_differentiable():
    gen = torch.Generator().manual_seed(0)
    x = torch.rand(1, 2, 4, 5, dtype=torch.float64, generator=gen, requires_grad=True)
    y = torch.rand(1, 2, 4, 5, dtype=torch.float64, generator=gen)
    assert torch.autograd.gradcheck(lambda t: ssim_torch(t, y), (x,))
    # as D-SSIM loss in float32
    xf = x.detach().float().requires_grad_(True)
    loss = 1 - ssim_torch(xf, y.float())
    loss.backward()
    assert xf.grad is not None and torch.isfinite(xf.grad).all() and xf.grad.abs().sum() > 0


def test_ssim_identical_is_one_and_constants_are_finite():
    a, _ = _pair((20, 20, 3))
    for mode in SSIM_MODES:
        assert ssim(a, a, mode) == pytest.approx(1.0, abs=1e-12)
    zeros, ones = np.zeros((16, 16, 3)), np.ones((16, 16, 3))
    for mode in SSIM_MODES:
        assert ssim(zeros, zeros, mode) == pytest.approx(1.0, abs=1e-12)
        v = ssim(zeros, ones, mode)
        assert math.isfinite(v) and v < 0.01
        assert math.isfinite(ssim(np.full((16, 16), 0.5), a[:16, :16, 0], mode))


# ----------------------------------------------------------------------------------------------- SSIM skimage modes


@pytest.mark.parametrize(
    "mode,shape",
    [
        (mode, shape)
        for mode in ("skimage-gaussian", "deblurnerf")
        for shape in [(48, 61, 3), (23, 17), (11, 11, 1), (7, 40, 3)]
        if min(shape[:2]) >= (11 if mode == "skimage-gaussian" else 7)
    ],
)
def test_ssim_skimage_modes_match_scikit_image(mode, shape):
    a, b = _pair(shape, seed=shape[0])
    assert abs(ssim(a, b, mode) - skimage_ssim(a, b, mode)) < 1e-4


def test_deblurnerf_luminance_is_not_shift_invariant():
    # the [-1, 1] lineage differs from SSIM on [0, 1] with data range 1 (peers.md §2): keep the modes distinct
    a, b = _pair((32, 32, 3), noise=0.2)
    plain = structural_similarity(a, b, data_range=1.0, channel_axis=2)
    assert abs(ssim(a, b, "deblurnerf") - plain) > 1e-4


@pytest.mark.parametrize("mode,k", [("skimage-gaussian", 11), ("deblurnerf", 7)])
def test_ssim_smaller_than_window_is_a_clear_error(mode, k):
    a, b = _pair((k - 1, 30, 3))
    with pytest.raises(EigsError, match=f"smaller than the {k}x{k} window"):
        ssim(a, b, mode)
    assert math.isfinite(ssim(a, b, "3dgs"))


# ----------------------------------------------------------------------------------------------- inputs


@pytest.mark.parametrize("mode", SSIM_MODES)
def test_uint8_equals_float_and_rgba_drops_alpha(mode):
    rng = np.random.default_rng(3)
    u = rng.integers(0, 256, (24, 26, 3), dtype=np.uint8)
    v = np.clip(u.astype(int) + rng.integers(-20, 21, u.shape), 0, 255).astype(np.uint8)
    f, g = u / 255.0, v / 255.0
    assert ssim(u, v, mode) == pytest.approx(ssim(f, g, mode), abs=1e-12)
    assert ssim(u, v, mode) == pytest.approx(ssim(f.astype(np.float32), g.astype(np.float32), mode), abs=1e-6)
    alpha = rng.integers(0, 256, (24, 26, 1), dtype=np.uint8)
    assert ssim(np.concatenate([u, alpha], 2), v, mode) == pytest.approx(ssim(u, v, mode), abs=1e-12)
    assert psnr(np.concatenate([u, alpha], 2), v) == pytest.approx(psnr(u, v), abs=1e-12)


def test_gray_against_rgb_repeats_the_channel():
    a, b = _pair((20, 22, 3))
    gray = a[:, :, 0]
    rgb = np.repeat(gray[:, :, None], 3, axis=2)
    for mode in SSIM_MODES:
        assert ssim(gray, b, mode) == pytest.approx(ssim(rgb, b, mode), abs=1e-12)
    assert psnr(gray, b) == pytest.approx(psnr(rgb, b), abs=1e-12)


def test_bad_inputs_are_clear_errors():
    a, b = _pair((20, 22, 3))
    with pytest.raises(EigsError, match="sizes must match"):
        ssim(a, b[:, :-1])
    with pytest.raises(EigsError, match="sizes must match"):
        psnr(a, b[:-1])
    with pytest.raises(EigsError, match=r"expected \[0, 1\]"):
        psnr(a * 255.0, b)
    bad = a.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(EigsError, match="NaN"):
        ssim(bad, b)
    with pytest.raises(EigsError, match="unknown SSIM mode"):
        ssim(a, b, "matlab")
    with pytest.raises(EigsError, match="image"):
        psnr(np.zeros((4, 4, 2)), np.zeros((4, 4, 2)))
    with pytest.raises(EigsError, match="unsupported dtype"):
        psnr(np.zeros((4, 4), np.int32), np.zeros((4, 4), np.int32))
