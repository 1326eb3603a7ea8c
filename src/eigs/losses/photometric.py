"""The 3DGS photometric loss: (1 − λ)·L1 + λ·(1 − SSIM), SSIM in the ``3dgs`` lineage (``eigs.metrics``): on float32
CPU tensors with a fixed target both means in one fused kernel (:func:`eigs.metrics.fused_ssim.l1_ssim_fused`, the
same gradient as the tensor ops), else the tensor ops with the reference SSIM."""

from __future__ import annotations

import torch
from torch import Tensor

from eigs.metrics.fused_ssim import fused_ssim_applies, l1_ssim_fused
from eigs.metrics.pixel import ssim_torch


def photometric_loss(
    image: Tensor, target: Tensor, lambda_dssim: float = 0.2, ssim_range: float = 1.0
) -> tuple[Tensor, Tensor, Tensor]:
    """``image``, ``target``: (H, W, C) or a stack (K, H, W, C) in [0, 1]. Returns (loss, l1, dssim), each a scalar
    tensor; of a stack, the mean of its K images' terms.

    ``lambda_dssim = 0`` skips the SSIM (its cost is a few convolutions per channel). ``ssim_range``: the SSIM's data
    range L (:func:`eigs.metrics.pixel.ssim_torch`; 1 as 3DGS, below 1 to see the contrast of dark frames).
    """
    if image.shape != target.shape:
        raise ValueError(f"image {tuple(image.shape)} and target {tuple(target.shape)} differ")
    if image.dim() not in (3, 4):
        raise ValueError(f"expected (H, W, C) or (K, H, W, C), got {tuple(image.shape)}")
    if lambda_dssim != 0 and fused_ssim_applies(image, target):
        l1, ssim = l1_ssim_fused(image, target, ssim_range)
        dssim = 1.0 - ssim
        return (1.0 - lambda_dssim) * l1 + lambda_dssim * dssim, l1, dssim
    l1 = (image - target).abs().mean()
    if lambda_dssim == 0:
        return l1, l1, torch.zeros((), dtype=l1.dtype)
    x, y = image.movedim(-1, -3), target.movedim(-1, -3)  # (…, C, H, W)
    dssim = 1.0 - ssim_torch(x, y, data_range=ssim_range)
    return (1.0 - lambda_dssim) * l1 + lambda_dssim * dssim, l1, dssim
