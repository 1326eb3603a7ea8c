"""The fused SSIM kernel (eigs.metrics.fused_ssim) against the tensor-op reference ssim_torch in float64: the map and
both reductions within the stated 2e-6, the gradient with random cotangents, the edges (images smaller than the
window, one pixel, flat and black images, NaN), and the photometric loss that picks it."""

from __future__ import annotations

import pytest
import torch

from eigs.losses import photometric_loss
from eigs.metrics.fused_ssim import _SSIMMap, fused_ssim_applies, ssim_fused
from eigs.metrics.pixel import K1, K2, _ssim_map, gaussian_window, ssim_torch

TOL = 2e-6


def pair(shape: tuple[int, ...], seed: int, scale: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
    """float64 images in [0, scale]: y a noisy copy of x (SSIM well inside (0, 1))."""
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(shape, generator=g, dtype=torch.float64) * scale
    y = (x + 0.1 * scale * torch.randn(shape, generator=g, dtype=torch.float64)).clamp(0, scale)
    return x, y


@pytest.mark.parametrize("shape", [(3, 1, 1), (1, 2, 5, 7), (2, 3, 12, 9), (1, 3, 40, 33), (2, 1, 3, 50)])
@pytest.mark.parametrize("data_range", [1.0, 0.1])
def test_ssim_matches_the_float64_reference(shape, data_range) -> None:
    x, y = pair(shape, seed=len(shape) + shape[-1], scale=min(data_range, 1.0))
    for reduction in ("mean", "none"):
        ref = ssim_torch(x, y, reduction=reduction, data_range=data_range)
        got = ssim_fused(x.float(), y.float(), reduction=reduction, data_range=data_range)
        assert got.shape == ref.shape
        assert torch.allclose(got.double(), ref, atol=TOL, rtol=0), (reduction, (got.double() - ref).abs().max())


@pytest.mark.parametrize("shape", [(1, 1, 1), (2, 6, 4), (3, 23, 31), (6, 64, 48)])
def test_map_and_gradient_match_the_reference_with_random_cotangents(shape) -> None:
    x, y = pair(shape, seed=shape[1])
    window64 = gaussian_window(11, 1.5, dtype=torch.float64)
    c1, c2 = K1**2, K2**2
    xr = x.clone().requires_grad_()
    ref = _ssim_map(xr, y, window64, "zeros", 1.0, 1.0)
    xf = x.float().requires_grad_()
    got = _SSIMMap.apply(xf, y.float(), gaussian_window(11, 1.5), c1, c2)
    assert torch.allclose(got.double(), ref, atol=TOL, rtol=0)
    v = torch.randn(shape, generator=torch.Generator().manual_seed(7), dtype=torch.float64)
    (v_ref,) = torch.autograd.grad(ref, xr, v)
    (v_got,) = torch.autograd.grad(got, xf, v.float())
    err = (v_got.double() - v_ref).abs().max() / v_ref.abs().max()
    assert err < 1e-5, err


def test_flat_and_black_images_score_one_and_have_no_gradient_blowup() -> None:
    for value in (0.0, 0.37):
        x = torch.full((1, 3, 16, 16), value)
        s = ssim_fused(x.clone().requires_grad_(), x.clone())
        assert abs(s.item() - 1.0) < 1e-6
        xg = x.clone().requires_grad_()
        ssim_fused(xg, x).backward()
        assert torch.isfinite(xg.grad).all() and xg.grad.abs().max() < 1e-3  # the maximum: gradient ~0


def test_nan_propagates_instead_of_vanishing() -> None:
    x, y = pair((1, 1, 8, 8), seed=1)
    x = x.float()
    x[0, 0, 4, 4] = float("nan")
    assert torch.isnan(ssim_fused(x, y.float()))


def test_it_refuses_what_it_does_not_compute() -> None:
    x, y = pair((1, 1, 8, 8), seed=2)
    assert not fused_ssim_applies(x, y)  # float64
    assert not fused_ssim_applies(x.float(), y.float().requires_grad_())  # a target with gradient
    with pytest.raises(ValueError, match="float32 CPU"):
        ssim_fused(x, y)
    with pytest.raises(ValueError, match="data_range"):
        ssim_fused(x.float(), y.float(), data_range=0.0)


def test_photometric_loss_takes_the_fused_kernel_and_agrees_with_the_reference() -> None:
    x, y = pair((4, 30, 20, 3), seed=3)  # a (K, H, W, C) stack, as the multi-render losses pass it
    img = x.float().requires_grad_()
    loss, _, dssim = photometric_loss(img, y.float(), 0.2, 0.5)
    loss.backward()
    img64 = x.clone().requires_grad_()
    loss64, _, dssim64 = photometric_loss(img64, y, 0.2, 0.5)  # float64: the reference path
    loss64.backward()
    assert abs(dssim.item() - dssim64.item()) < TOL
    assert (img.grad.double() - img64.grad).abs().max() / img64.grad.abs().max() < 1e-5
    # a target that takes gradient goes to the reference, which differentiates both images
    tgt = y.float().requires_grad_()
    photometric_loss(x.float(), tgt)[0].backward()
    assert tgt.grad is not None and tgt.grad.abs().sum() > 0


def composite_photometric(image: torch.Tensor, target: torch.Tensor, lam: float, data_range: float):
    """The photometric loss as tensor ops around the fused SSIM: what l1_ssim_fused replaces."""
    l1 = (image - target).abs().mean()
    dssim = 1.0 - ssim_fused(image.movedim(-1, -3), target.movedim(-1, -3), data_range=data_range)
    return (1.0 - lam) * l1 + lam * dssim, l1, dssim


@pytest.mark.parametrize("shape", [(1, 1, 3), (2, 7, 5, 1), (16, 16, 3), (5, 23, 31, 3), (3, 40, 18, 2)])
@pytest.mark.parametrize(("lam", "data_range", "upstream"), [(0.2, 1.0, 1.0), (0.5, 0.3, 2.0), (0.9, 1.0, -0.37)])
def test_fused_photometric_loss_has_the_tensor_ops_gradient_bit_for_bit(shape, lam, data_range, upstream) -> None:
    """photometric_loss through l1_ssim_fused against the same loss as tensor ops around the SSIM kernel: the gradient
    identical (the same float32 operations), the loss and its terms within float32 summation order; some pixels equal
    to their target (the L1's subgradient 0)."""
    x, y = pair(shape, seed=shape[-2] + int(10 * lam), scale=min(data_range, 1.0))
    x, y = x.float(), y.float()
    x.view(-1)[::7] = y.view(-1)[::7]
    got_x = x.clone().requires_grad_()
    got = photometric_loss(got_x, y, lam, data_range)
    (upstream * got[0]).backward()
    ref_x = x.clone().requires_grad_()
    ref = composite_photometric(ref_x, y, lam, data_range)
    (upstream * ref[0]).backward()
    assert torch.equal(got_x.grad, ref_x.grad), (got_x.grad - ref_x.grad).abs().max()
    for a, b in zip(got, ref, strict=True):
        assert a.dtype == torch.float32 and a.shape == ()
        assert abs(a.item() - b.item()) <= 1e-6 * max(1.0, abs(b.item())), (a.item(), b.item())


def test_fused_photometric_means_match_float64_and_refuse_what_they_cannot_take() -> None:
    from eigs.metrics.fused_ssim import l1_ssim_fused

    x, y = pair((4, 21, 19, 3), seed=3)
    l1, s = l1_ssim_fused(x.float(), y.float())
    assert abs(l1.item() - (x.float().double() - y.float().double()).abs().mean().item()) < 1e-7
    ref = ssim_torch(x.movedim(-1, -3), y.movedim(-1, -3))
    assert abs(s.item() - ref.item()) < TOL
    with pytest.raises(ValueError, match="l1_ssim_fused takes"):
        l1_ssim_fused(x, y)  # float64
    with pytest.raises(ValueError, match="l1_ssim_fused takes"):
        l1_ssim_fused(x.float().reshape(-1), y.float().reshape(-1))
    with pytest.raises(ValueError, match="data_range"):
        l1_ssim_fused(x.float(), y.float(), data_range=0.0)
    empty = torch.zeros(0, 4, 4, 3)
    l1, s = l1_ssim_fused(empty.requires_grad_(), torch.zeros(0, 4, 4, 3))
    assert torch.isnan(l1) and torch.isnan(s)  # a mean over nothing, as torch's
