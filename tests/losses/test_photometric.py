"""The 3DGS photometric loss on one image and on a stack: closed forms and the stack as the mean of its images."""

from __future__ import annotations

import pytest
import torch

from eigs.losses import photometric_loss


def test_closed_forms_of_an_offset_image():
    """An image off its target by a constant d: L1 = d; against itself the D-SSIM is 0 and so is the loss."""
    g = torch.Generator().manual_seed(0)
    target = torch.rand(20, 24, 3, generator=g, dtype=torch.float64) * 0.5
    loss, l1, dssim = photometric_loss(target + 0.125, target, 0.0)
    assert l1.item() == pytest.approx(0.125, abs=1e-15) and loss is l1 and dssim.item() == 0.0
    loss, l1, dssim = photometric_loss(target, target, 0.2)
    assert loss.item() == pytest.approx(0.0, abs=1e-12) and dssim.item() == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("lam", [0.0, 0.2, 1.0])
def test_a_stack_is_the_mean_of_its_images(lam):
    g = torch.Generator().manual_seed(1)
    image = torch.rand(4, 17, 23, 3, generator=g, dtype=torch.float64)
    target = torch.rand(4, 17, 23, 3, generator=g, dtype=torch.float64)
    loss, l1, dssim = photometric_loss(image, target, lam)
    single = [photometric_loss(image[k], target[k], lam) for k in range(4)]
    for i, got in enumerate((loss, l1, dssim)):
        torch.testing.assert_close(got, torch.stack([s[i] for s in single]).mean(), atol=1e-14, rtol=0)
    assert (dssim > 0.5) == (lam > 0)  # independent noise images: SSIM near 0


def test_shape_errors():
    with pytest.raises(ValueError, match="differ"):
        photometric_loss(torch.zeros(4, 5, 3), torch.zeros(4, 6, 3))
    with pytest.raises(ValueError, match="expected"):
        photometric_loss(torch.zeros(5, 3), torch.zeros(5, 3))


def test_ssim_range_is_ssim_of_the_images_divided_by_it():
    """SSIM at data range L equals SSIM of x / L, y / L at range 1 (every term of the formula scales by 1/L²)."""
    from eigs.metrics.pixel import ssim_torch

    gen = torch.Generator().manual_seed(3)
    x = 0.06 * torch.rand(2, 3, 24, 20, generator=gen, dtype=torch.float64)
    y = 0.06 * torch.rand(2, 3, 24, 20, generator=gen, dtype=torch.float64)
    for rng in (0.5, 0.1, 0.06):
        got = ssim_torch(x, y, data_range=rng)
        want = ssim_torch(x / rng, y / rng)
        assert abs(float(got - want)) < 1e-12, rng
    assert abs(float(ssim_torch(x, y, data_range=1.0) - ssim_torch(x, y))) == 0.0
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="data_range"):
            ssim_torch(x, y, data_range=bad)


def test_a_smaller_ssim_range_sees_the_contrast_of_a_dark_frame():
    """A dark texture (mean 13/255, local spread ~1.5/255, as the DAVIS346-like frames) against a flat render of its
    mean: at range 1 the constants swamp the contrast (D-SSIM near 0); at range 0.1 the missing texture costs."""
    gen = torch.Generator().manual_seed(4)
    target = (13.0 + 1.5 * torch.randn(96, 128, 3, generator=gen, dtype=torch.float64)) / 255.0
    flat = torch.full_like(target, float(target.mean()))
    _, _, d1 = photometric_loss(flat, target, 0.2, ssim_range=1.0)
    _, _, d01 = photometric_loss(flat, target, 0.2, ssim_range=0.1)
    # C2 = (0.03 L)²: 58.5 DN² at L = 1 against a variance of 2.25 DN² (for a flat render of the mean, away from the
    # zero-padded border, 1 − SSIM = 1 − C2 / (σ² + C2): 0.037); at L = 0.1, C2 = 0.585 DN²: 1 − 0.585 / 2.835 = 0.79
    assert float(d1) < 0.05 and 0.6 < float(d01) < 0.8
    loss, l1, d = photometric_loss(flat, target, 0.2, ssim_range=0.1)
    assert torch.allclose(loss, 0.8 * l1 + 0.2 * d)


def test_train_config_checks_ssim_range():
    from eigs.errors import EigsError
    from eigs.train.config import TrainConfig

    assert TrainConfig().ssim_range == 1.0
    for bad in (0.0, 1.5, -0.2):
        with pytest.raises(EigsError, match="ssim_range"):
            TrainConfig.from_dict({"ssim_range": bad})
