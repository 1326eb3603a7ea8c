"""How much texture SSIM can see in a set of frames: the local variance in SSIM's window against its constant C2.

SSIM's contrast-structure term ``(2 σ_xy + C2) / (σ_x² + σ_y² + C2)`` is flat in a texture whose local variance is
far below ``C2 = (0.03 L)²`` (L the data range): a D-SSIM loss then barely asks for that texture. Dark, blurry frames
(the DAVIS346-like scenes, issue 43) sit there: the median local variance of their blurry frames is 1–3 % of C2,
against 11–54 % at the 128×96 scenes (docs/results.md, "Why `eigs+` renders smooth at 346×260").

Definition: luminance ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` (BT.709, values as stored, [0, 1] scale; one channel
as is), the local variance ``E_w[Y²] − E_w[Y]²`` over SSIM's 11 × 11 Gaussian window (σ = 1.5 px) at every position
where the window fits ("valid"), in float64 (clipped at 0 against rounding), and its median over all positions of
all frames (the lower middle value for an even count, as ``torch.median``) divided by ``C2 = 0.03²`` (data
range 1). Dimensionless, scale-consistent with 8-bit DN (× 255² on both).
"""

from __future__ import annotations

import torch
from torch import Tensor

from eigs.errors import EigsError
from eigs.metrics.pixel import gaussian_window
from eigs.metrics.sharpness import LUMA

SSIM_C2 = 0.03**2  # SSIM's C2 at data range 1 (K2 = 0.03)
WINDOW = 11  # SSIM's window side (px), Gaussian σ = 1.5 px
# Below this share of C2 a scene's blurry frames count as dark for the sharp-frame term of EiGS (option
# `latent_weight_dark`, docs/methods.md): the measured scenes split at 0.012–0.026 (346×260) against 0.11–0.54
# (128×96), so any value between gives the same choice on all of them
DARK_TEXTURE = 0.05


def luma(images: Tensor) -> Tensor:
    """(N, H, W, C) with C ∈ {1, 3}, [0, 1] scale → (N, H, W) float64 BT.709 luminance."""
    if images.ndim != 4 or images.shape[-1] not in (1, 3):
        raise EigsError(None, f"images must be (N, H, W, 1 or 3), got {tuple(images.shape)}")
    x = images.to(torch.float64)
    if x.shape[-1] == 1:
        return x[..., 0]
    return x @ torch.from_numpy(LUMA).to(torch.float64)  # BT.709, the weights of the sharpness metric


def local_variance(y: Tensor) -> Tensor:
    """(N, H, W) → (N, H − 10, W − 10) float64 local variance in SSIM's window (≥ 0). One frame at a time: the
    float64 convolution unfolds its input 121-fold (30 frames of 800×800 at once: an 18.6 GB buffer, which an
    `eigs+` run at that size met while it set up; one frame: 0.6 GB)."""
    if y.ndim != 3 or y.shape[1] < WINDOW or y.shape[2] < WINDOW:
        raise EigsError(None, f"frames must be (N, H ≥ {WINDOW}, W ≥ {WINDOW}), got {tuple(y.shape)}")
    g = gaussian_window(WINDOW, 1.5, dtype=torch.float64)
    w = torch.outer(g, g)[None, None]  # (1, 1, 11, 11), sums to 1
    out = y.new_empty((y.shape[0], y.shape[1] - WINDOW + 1, y.shape[2] - WINDOW + 1), dtype=torch.float64)
    for i in range(y.shape[0]):
        x = y[i : i + 1].to(torch.float64)[:, None]  # (1, 1, H, W)
        mean = torch.nn.functional.conv2d(x, w)
        mean_sq = torch.nn.functional.conv2d(x * x, w)
        out[i] = (mean_sq - mean * mean).clamp_min(0.0)[0, 0]
    return out


def ssim_texture_visibility(images: Tensor) -> float:
    """Median local variance of ``images`` (N, H, W, C) in [0, 1] over SSIM's C2: the module's definition.
    Raises :class:`EigsError` on non-finite values."""
    if not bool(torch.isfinite(images).all()):
        raise EigsError(None, "texture visibility: the frames hold NaN or Inf")
    return float(local_variance(luma(images)).median()) / SSIM_C2
