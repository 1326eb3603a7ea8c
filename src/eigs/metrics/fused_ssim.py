"""The SSIM of the 3DGS lineage as one fused CPU kernel with its own backward (``csrc/ssim.cpp``).

:func:`ssim_fused` computes what :func:`eigs.metrics.pixel.ssim_torch` computes (its reference: 11-tap Gaussian,
σ 1.5, zero padding, constants at ``data_range``) for float32 CPU tensors whose second image takes no gradient (the
training losses: a render against its target). Where the reference builds ~30 whole-image tensors and two depthwise
convolutions per call, the kernel makes one pass per axis over the five windowed moments and, for the backward, one
over three maps. Measured on the `eigs+` step at 346×260 (docs/benchmarks.md "The fused SSIM").
Precision: float32, within 2e-6 of the float64 reference per pixel on images in [0, 1] (tests/metrics).
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import torch
from torch import Tensor
from torch.autograd.function import once_differentiable

from eigs.metrics.pixel import K1, K2, as_planes, gaussian_window, reduce_ssim_map
from eigs.util.extension import load_extension

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("ssim.cpp",)


def load() -> ModuleType:
    """The compiled kernel (built on first use, cached)."""
    return load_extension("eigs_ssim", CSRC, SOURCES, (), "the fused SSIM kernel")


class _SSIMMap(torch.autograd.Function):
    """SSIM map (P, H, W) of planes ``x``, ``y`` (P, H, W); the gradient flows to ``x`` only."""

    @staticmethod
    def forward(ctx, x: Tensor, y: Tensor, window: Tensor, c1: float, c2: float) -> Tensor:  # type: ignore[override]
        smap, partials = load().ssim_map_fwd(x, y, window, c1, c2, ctx.needs_input_grad[0])
        ctx.save_for_backward(x, y, window, partials)
        return smap

    @staticmethod
    @once_differentiable
    def backward(ctx, v_map: Tensor) -> tuple[Tensor | None, None, None, None, None]:  # type: ignore[override]
        x, y, window, partials = ctx.saved_tensors
        v_x = load().ssim_map_bwd(v_map.contiguous(), x, y, partials, window)
        return v_x, None, None, None, None


def fused_ssim_applies(x: Tensor, y: Tensor) -> bool:
    """Whether :func:`ssim_fused` takes ``x``, ``y``: float32 on the CPU, one shape, ``y`` without gradient."""
    return (x.device.type == "cpu" and y.device.type == "cpu" and x.dtype == torch.float32
            and y.dtype == torch.float32 and x.shape == y.shape and not y.requires_grad)  # fmt: skip


def ssim_constants(data_range: float) -> tuple[float, float]:
    """The SSIM's (C1, C2) = ((K1 L)², (K2 L)²) for data range L, finite and > 0."""
    if not (data_range > 0 and data_range < float("inf")):
        raise ValueError(f"data_range must be finite and > 0, got {data_range}")
    return (K1 * data_range) ** 2, (K2 * data_range) ** 2


def ssim_fused(x: Tensor, y: Tensor, reduction: str = "mean", data_range: float = 1.0) -> Tensor:
    """SSIM mode ``3dgs`` of ``x`` against ``y``, ``(N, C, H, W)`` or ``(C, H, W)`` float32 CPU, as
    :func:`eigs.metrics.pixel.ssim_torch` (same reductions and ``data_range``); differentiable in ``x`` only."""
    if not fused_ssim_applies(x, y):
        raise ValueError(f"ssim_fused takes float32 CPU tensors of one shape, y without gradient; got "
                         f"{tuple(x.shape)} {x.dtype} {x.device}, {tuple(y.shape)} {y.dtype} {y.device}")  # fmt: skip
    c1, c2 = ssim_constants(data_range)
    xp, yp, n, batched = as_planes(x, y)
    window = gaussian_window()  # the 3DGS window (11 taps, σ 1.5), float32: the kernel's
    smap = _SSIMMap.apply(xp.contiguous(), yp.contiguous(), window, c1, c2)  # (N C, H, W)
    return reduce_ssim_map(smap, n, batched, reduction)


class _L1SSIM(torch.autograd.Function):
    """Mean |x − y| and mean SSIM (mode ``3dgs``) of channels-last images ``x``, ``y`` (K, H, W, C), both 0-dim
    float32; the gradient flows to ``x`` only."""

    @staticmethod
    def forward(ctx, x: Tensor, y: Tensor, window: Tensor, c1: float, c2: float) -> tuple[Tensor, Tensor]:  # type: ignore[override]
        sums, partials = load().l1_ssim_fwd(x, y, window, c1, c2, ctx.needs_input_grad[0])
        ctx.save_for_backward(x, y, window, partials)
        n = x.numel()  # no values: NaN, as a mean over nothing is in torch
        return (sums[0] / n).to(x.dtype), (sums[1] / n).to(x.dtype)

    @staticmethod
    @once_differentiable
    def backward(ctx, v_l1: Tensor, v_ssim: Tensor) -> tuple[Tensor | None, None, None, None, None]:  # type: ignore[override]
        x, y, window, partials = ctx.saved_tensors
        v_x = load().l1_ssim_bwd(x, y, partials, window, float(v_l1), float(v_ssim))
        return v_x, None, None, None, None


def l1_ssim_fused(x: Tensor, y: Tensor, data_range: float = 1.0) -> tuple[Tensor, Tensor]:
    """(mean |x − y|, mean SSIM) of channels-last images ``x``, ``y`` ((H, W, C) or (K, H, W, C), float32 CPU, ``y``
    without gradient), differentiable in ``x``: what ``(x - y).abs().mean()`` and :func:`ssim_fused` of the images
    moved to (…, C, H, W) give, in one pass over the images and without their channels-first copies. The gradient is
    the same float32 arithmetic as those two graphs' (tested bit for bit); the two means are summed in float64, so
    they differ from the graphs' float32 sums in the last bits."""
    if not fused_ssim_applies(x, y) or x.dim() not in (3, 4):
        raise ValueError(f"l1_ssim_fused takes (H, W, C) or (K, H, W, C) float32 CPU tensors of one shape, y without "
                         f"gradient; got {tuple(x.shape)} {x.dtype} {x.device}, {tuple(y.shape)} {y.dtype} "
                         f"{y.device}")  # fmt: skip
    c1, c2 = ssim_constants(data_range)
    if x.dim() == 3:
        x, y = x.unsqueeze(0), y.unsqueeze(0)
    return _L1SSIM.apply(x.contiguous(), y.contiguous(), gaussian_window(), c1, c2)
