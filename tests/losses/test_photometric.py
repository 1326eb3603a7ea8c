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
