"""Differentiable 3-D Gaussian rasterizer: C++ CPU kernels (SIMD + OpenMP) and a gsplat switch for CUDA.

``rasterize`` is the public entry point; the contract it implements (culling, projection, ordering,
compositing, thresholds, gradient rules) is written down in docs/rasterizer.md and enforced by
tests/render against the dense pure-PyTorch reference in :mod:`eigs.render.reference`.
"""

from __future__ import annotations

import math
from typing import Literal

import torch
from torch import Tensor

from eigs.render._wrapper import camera_list

__all__ = ["rasterize", "means2d_grad"]

Backend = Literal["auto", "cpu", "gsplat"]


def _check(name: str, t: Tensor, shape: tuple[int | None, ...]) -> None:
    if not isinstance(t, Tensor):
        raise TypeError(f"{name} must be a torch.Tensor, got {type(t).__name__}")
    got = t.shape
    ok = len(got) == len(shape)
    if ok:
        for s, n in zip(shape, got, strict=True):  # a plain loop: this runs 8 times per call (per-call latency matters)
            if s is not None and s != n:
                ok = False
    if not ok:
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {tuple(got)}")


def rasterize(
    means: Tensor,
    quats: Tensor,
    scales: Tensor,
    opacities: Tensor,
    colors: Tensor,
    viewmat: Tensor,
    K: Tensor,
    width: int,
    height: int,
    background: Tensor | None = None,
    backend: Backend = "auto",
) -> tuple[Tensor, Tensor, dict]:
    """Render N Gaussians into one camera, differentiably.

    Args:
        means: (N, 3) world positions.
        quats: (N, 4) rotations as w, x, y, z (normalised inside; zero quaternions are culled).
        scales: (N, 3) positive standard deviations (post-activation; the exp stays in PyTorch).
        opacities: (N,) in [0, 1] (post-sigmoid).
        colors: (N, D) features, any D >= 1.
        viewmat: (4, 4) world-to-camera, OpenCV axes (x right, y down, z forward). Not differentiated.
        K: (3, 3) pinhole intrinsics (fx, fy, cx, cy); pixel (row i, column j) has its centre at (j+0.5, i+0.5).
            Not differentiated.
        width, height: image size in pixels.
        background: (D,) colour behind the Gaussians (default zeros).
        backend: ``"cpu"`` (the C++ kernels; float32 or float64), ``"gsplat"`` (CUDA tensors, float32) or
            ``"auto"`` (gsplat for CUDA tensors, else cpu).

    Returns:
        image (H, W, D) = C + T * background, alpha (H, W) = 1 - T, and ``info`` with ``radii`` (N, 2) int32
        (0 = culled), ``means2d`` (N, 2) px, ``depths`` (N,), ``conics`` (N, 3), ``backend``, and on the cpu
        backend ``n_isects``, ``tile_offsets``, ``flatten_ids``. ``info["means2d"]`` is the graph node:
        call ``retain_grad()`` on it before ``backward`` and read :func:`means2d_grad` — the gradient is in
        **pixel units** (the NDC gradient of 3DGS's densification thresholds is this times W/2 in x, H/2 in y).
    """
    _check("means", means, (None, 3))
    n = means.shape[0]
    _check("quats", quats, (n, 4))
    _check("scales", scales, (n, 3))
    _check("opacities", opacities, (n,))
    _check("colors", colors, (n, None))
    _check("viewmat", viewmat, (4, 4))
    _check("K", K, (3, 3))
    d = colors.shape[1]
    if d < 1:
        raise ValueError("colors must have at least one channel")
    width, height = int(width), int(height)
    if width < 1 or height < 1:
        raise ValueError(f"width and height must be >= 1, got {width} x {height}")
    dtype, device = means.dtype, means.device
    if dtype not in (torch.float32, torch.float64):
        raise TypeError(f"means must be float32 or float64, got {dtype}")
    for name, t in (("quats", quats), ("scales", scales), ("opacities", opacities), ("colors", colors)):
        if t.dtype != dtype or t.device != device:
            raise TypeError(f"{name} must be {dtype} on {device} like means, got {t.dtype} on {t.device}")
    if background is None:
        background = torch.zeros(d, dtype=dtype, device=device)
    _check("background", background, (d,))
    if background.dtype != dtype or background.device != device:
        raise TypeError(f"background must be {dtype} on {device} like means")
    viewmat = viewmat.detach().to(device=device, dtype=dtype)
    K = K.detach().to(device=device, dtype=dtype)
    cam = camera_list(viewmat, K, dtype)  # the 25 camera numbers as one host list (the cpu backend takes them so)
    if not all(map(math.isfinite, cam)):
        raise ValueError("viewmat and K must be finite")
    if not (cam[16] > 0 and cam[20] > 0):
        raise ValueError("K must have positive focal lengths fx, fy")

    if backend == "auto":
        backend = "gsplat" if device.type == "cuda" else "cpu"
    if backend == "gsplat":
        from eigs.render._gsplat import rasterize_gsplat

        if device.type != "cuda":
            raise ValueError("backend 'gsplat' needs CUDA tensors")
        return rasterize_gsplat(means, quats, scales, opacities, colors, viewmat, K, width, height, background)
    if backend != "cpu":
        raise ValueError(f"backend must be 'auto', 'cpu' or 'gsplat', got {backend!r}")
    if device.type != "cpu":
        raise ValueError(f"backend 'cpu' needs CPU tensors, got {device}")
    from eigs.render._wrapper import rasterize_cpu

    return rasterize_cpu(
        means.contiguous(), quats.contiguous(), scales.contiguous(), opacities.contiguous(), colors.contiguous(),
        viewmat, K, width, height, background.contiguous(), cam=cam,
    )


def means2d_grad(info: dict) -> Tensor | None:
    """Gradient of the loss w.r.t. the projected means, (N, 2) in pixel units (None if not retained).

    For 3DGS-style densification thresholds in NDC units multiply x by W/2 and y by H/2.
    """
    g = info["means2d"].grad
    if g is None:
        return None
    return g.reshape(-1, 2)
