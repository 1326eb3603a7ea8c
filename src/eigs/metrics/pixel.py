"""Full-reference pixel metrics: PSNR and SSIM in three named modes.

SSIM lineages differ in window, padding, input range and covariance estimator, so a mode must be named:

============================ ======================= =========== ============ =========== =================
mode                         window                  padding     inputs       data range  covariance
============================ ======================= =========== ============ =========== =================
``3dgs``                     11x11 Gaussian, σ = 1.5 zeros, mean [0, 1]       1           population (1/N)
                             (separable)             over every
                                                     pixel
``skimage-gaussian``         11x11 Gaussian, σ = 1.5 symmetric,  [0, 1]       1           population (1/N)
                             (truncate 3.5)          border of 5
                                                     cropped
``deblurnerf``               7x7 uniform             symmetric,  2x - 1 in    2           sample (1/(N-1))
                                                     border of 3 [-1, 1]
                                                     cropped
============================ ======================= =========== ============ =========== =================

All modes use K1 = 0.01, K2 = 0.03, C1 = (K1 L)^2, C2 = (K2 L)^2 with L the data range, compute SSIM per channel
and average over channels (and over the batch for :func:`ssim_torch`). ``3dgs`` is the 3DGS code's
``utils/loss_utils.ssim`` and what training uses as D-SSIM = 1 - SSIM; ``skimage-gaussian`` is
``skimage.metrics.structural_similarity(gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
data_range=1)``; ``deblurnerf`` is ``structural_similarity`` with its defaults on images mapped to [-1, 1], as the
Deblur-NeRF lineage (Deblurring-3DGS, EBAD-NeRF) computes it.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch
import torch.nn.functional as F

from eigs.errors import EigsError
from eigs.metrics.image import float_pair

SSIM_MODES = ("3dgs", "skimage-gaussian", "deblurnerf")
K1, K2 = 0.01, 0.03


# ----------------------------------------------------------------------------------------------- PSNR


def psnr(img: np.ndarray, ref: np.ndarray) -> float:
    """PSNR in dB of ``img`` against ``ref`` on [0, 1] values: ``10 log10(1 / MSE)``, MSE over pixels and channels.

    Inputs as in :mod:`eigs.metrics.image` (uint8 is divided by 255). Identical images give ``inf``.
    """
    a, b = float_pair(img, ref)
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(1.0 / mse)


def psnr_torch(x: torch.Tensor, y: torch.Tensor, eps: float = 1e-10) -> torch.Tensor:
    """Per-image PSNR of ``(N, C, H, W)`` (or ``(C, H, W)``) tensors in [0, 1] -> ``(N,)`` (or ``()``) dB.

    MSE is floored at ``eps`` so identical images give a finite 100 dB instead of ``inf``.
    """
    mse = ((x - y) ** 2).flatten(start_dim=-3).mean(dim=-1)
    return -10.0 * torch.log10(mse.clamp_min(eps))


# ----------------------------------------------------------------------------------------------- SSIM core


def gaussian_window(size: int = 11, sigma: float = 1.5, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """``(size,)`` 1-D Gaussian weights centred on the middle tap, summing to 1 (a fresh copy of a cached tensor:
    a training step asks for it on every SSIM)."""
    return _gaussian_window(int(size), float(sigma), dtype).clone()


@functools.lru_cache(maxsize=16)
def _gaussian_window(size: int, sigma: float, dtype: torch.dtype) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float64) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    return (g / g.sum()).to(dtype)


def _symmetric_index(n: int, pad: int) -> torch.Tensor:
    """Indices of a length-``n`` axis padded by ``pad`` on both sides with symmetric (edge-repeating) reflection."""
    idx = np.arange(-pad, n + pad)
    period = 2 * n
    idx = np.mod(idx, period)
    idx = np.where(idx >= n, period - 1 - idx, idx)
    return torch.from_numpy(idx)


def _filter2d(x: torch.Tensor, window: torch.Tensor, padding: str) -> torch.Tensor:
    """Separable correlation of ``x`` ``(B, H, W)`` with ``window`` ``(k,)`` along both axes -> ``(B, H, W)``.

    ``padding="zeros"``: zero padding (3DGS). ``padding="symmetric"``: edge-repeating reflection, as
    ``scipy.ndimage`` mode "reflect" (scikit-image). Differentiable. float32/float16 use one depthwise conv per
    axis (each image of the stack is a channel, channels-last: the fast CPU path); float64, which oneDNN does
    not accelerate, sums k shifted slices per axis instead.
    """
    k = window.numel()
    pad = k // 2
    h, w = x.shape[-2:]
    if padding == "zeros":
        x = F.pad(x, (pad, pad, pad, pad))
    elif padding == "symmetric":
        x = x.index_select(2, _symmetric_index(w, pad).to(x.device))
        x = x.index_select(1, _symmetric_index(h, pad).to(x.device))
    else:  # pragma: no cover - internal
        raise ValueError(padding)
    if x.dtype == torch.float64:
        taps = [float(v) for v in window]
        rows = x[:, :, 0:w] * taps[0]
        for i in range(1, k):
            rows.add_(x[:, :, i : i + w], alpha=taps[i])  # in place: no temporaries; autograd-safe (add)
        out = rows[:, 0:h, :] * taps[0]
        for i in range(1, k):
            out.add_(rows[:, i : i + h, :], alpha=taps[i])
        return out
    b = x.shape[0]
    xc = x.unsqueeze(0).contiguous(memory_format=torch.channels_last)
    wh = window.to(x).view(1, 1, 1, k).expand(b, 1, 1, k).contiguous()
    wv = window.to(x).view(1, 1, k, 1).expand(b, 1, k, 1).contiguous()
    out = F.conv2d(F.conv2d(xc, wh, groups=b), wv, groups=b)
    return out.squeeze(0).contiguous()


def _ssim_map(
    x: torch.Tensor, y: torch.Tensor, window: torch.Tensor, padding: str, data_range: float, cov_norm: float
) -> torch.Tensor:
    """SSIM map ``(B, H, W)`` of single-channel stacks ``x``, ``y`` ``(B, H, W)``."""
    b = x.shape[0]
    stats = _filter2d(torch.cat([x, y, x * x, y * y, x * y], dim=0), window, padding)
    mu_x, mu_y, e_xx, e_yy, e_xy = stats.split(b, dim=0)
    var_x = cov_norm * (e_xx - mu_x * mu_x)
    var_y = cov_norm * (e_yy - mu_y * mu_y)
    cov = cov_norm * (e_xy - mu_x * mu_y)
    c1 = (K1 * data_range) ** 2
    c2 = (K2 * data_range) ** 2
    num = (2 * mu_x * mu_y + c1) * (2 * cov + c2)
    # var_x + var_y can round to a tiny negative value; the floor keeps the denominator >= c1 * c2 / 2 > 0.
    den = (mu_x * mu_x + mu_y * mu_y + c1) * (var_x + var_y + c2).clamp_min(c2 / 2)
    return num / den


def ssim_torch(
    x: torch.Tensor,
    y: torch.Tensor,
    window_size: int = 11,
    sigma: float = 1.5,
    reduction: str = "mean",
    data_range: float = 1.0,
) -> torch.Tensor:
    """SSIM mode ``3dgs`` of tensors in [0, 1]: differentiable, separable Gaussian, zero padding.

    ``x``, ``y``: ``(N, C, H, W)`` or ``(C, H, W)``, any float dtype/device, any size >= 1x1.
    ``reduction="mean"``: a scalar, the mean over every pixel, channel and image (as 3DGS's ``ssim``);
    ``"none"``: ``(N,)`` per image (``()`` for 3-D input). D-SSIM for training is ``1 - ssim_torch(x, y)``.
    ``data_range``: L in the constants C1 = (K1 L)², C2 = (K2 L)² (> 0; 1 for [0, 1] images, as 3DGS). The SSIM of
    ``x``, ``y`` at range L equals that of ``x / L``, ``y / L`` at range 1 (every term scales by 1/L²).
    """
    if x.shape != y.shape:
        raise ValueError(f"shapes differ: {tuple(x.shape)} vs {tuple(y.shape)}")
    if not (math.isfinite(data_range) and data_range > 0):
        raise ValueError(f"data_range must be finite and > 0, got {data_range}")
    xp, yp, n, batched = as_planes(x, y)
    window = gaussian_window(window_size, sigma, dtype=x.dtype).to(x.device)
    return reduce_ssim_map(_ssim_map(xp, yp, window, "zeros", data_range, 1.0), n, batched, reduction)


def as_planes(x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, int, bool]:
    """``(N, C, H, W)`` or ``(C, H, W)`` images as single-channel planes ``(N·C, H, W)``, with N and whether they
    were batched (the SSIM's input convention; :func:`ssim_torch`, :func:`eigs.metrics.fused_ssim.ssim_fused`)."""
    if x.dim() not in (3, 4):
        raise ValueError(f"expected (C, H, W) or (N, C, H, W), got {tuple(x.shape)}")
    batched = x.dim() == 4
    if not batched:
        x, y = x.unsqueeze(0), y.unsqueeze(0)
    n, c, h, w = x.shape
    return x.reshape(n * c, h, w), y.reshape(n * c, h, w), n, batched


def reduce_ssim_map(smap: torch.Tensor, n: int, batched: bool, reduction: str) -> torch.Tensor:
    """An SSIM map ``(N·C, H, W)`` reduced as :func:`ssim_torch` documents: ``"mean"`` a scalar, ``"none"`` ``(N,)``
    per image (``()`` when the input was one image)."""
    if reduction == "mean":
        return smap.mean()
    if reduction == "none":
        per_image = smap.reshape(n, -1).mean(dim=1)
        return per_image if batched else per_image[0]
    raise ValueError(f"reduction must be 'mean' or 'none', got {reduction!r}")


# ----------------------------------------------------------------------------------------------- SSIM API

# window size of the scikit-image modes
_WINDOWS = {"skimage-gaussian": 11, "deblurnerf": 7}


def ssim(img: np.ndarray, ref: np.ndarray, mode: str = "3dgs") -> float:
    """SSIM of ``img`` against ``ref`` in the named ``mode`` (see the module docstring); float64 throughout.

    Inputs as in :mod:`eigs.metrics.image`: ``(H, W[, C])`` uint8 or float in [0, 1], same H and W.
    ``3dgs`` works for any size; the scikit-image modes need H and W at least their window (11 or 7) and
    raise :class:`EigsError` otherwise, as scikit-image does.
    """
    if mode not in SSIM_MODES:
        raise EigsError(None, f"unknown SSIM mode {mode!r}; expected one of {', '.join(SSIM_MODES)}")
    a, b = float_pair(img, ref)
    x = torch.from_numpy(np.ascontiguousarray(a.transpose(2, 0, 1)))
    y = torch.from_numpy(np.ascontiguousarray(b.transpose(2, 0, 1)))
    if mode == "3dgs":
        return float(ssim_torch(x, y))
    k = _WINDOWS[mode]
    h, w = a.shape[:2]
    if min(h, w) < k:
        raise EigsError(
            None, f"image is {w}x{h}, smaller than the {k}x{k} window of SSIM mode {mode!r}; use mode '3dgs'"
        )
    if mode == "skimage-gaussian":
        window = gaussian_window(k, 1.5, dtype=torch.float64)
        data_range, cov_norm = 1.0, 1.0
    else:  # deblurnerf: uniform 7x7 on 2x - 1, data range 2, sample covariance
        window = torch.full((k,), 1.0 / k, dtype=torch.float64)
        x, y = 2 * x - 1, 2 * y - 1
        data_range, cov_norm = 2.0, k * k / (k * k - 1)
    smap = _ssim_map(x, y, window, "symmetric", data_range, cov_norm)
    pad = (k - 1) // 2
    return float(smap[:, pad : h - pad, pad : w - pad].mean(dim=(1, 2)).mean())
