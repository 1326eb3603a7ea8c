"""Render a Gaussian model (3DGS parametrisation) from a camera: activations, spherical harmonics, rasterize.

Training, evaluation and ``eigs render`` all go through :func:`render_gaussians`, so a model looks the same
everywhere. The parametrisation is the 3DGS PLY's: ``log_scales`` (exp → standard deviations), ``opacity_logits``
(sigmoid), unnormalised ``quats`` (w, x, y, z), and colour as real spherical harmonics per channel whose DC term
maps to colour by ``0.5 + C0·dc`` (clamped at 0 as 3DGS does).
"""

from __future__ import annotations

import torch
from torch import Tensor

from eigs.render import rasterize

# Real spherical-harmonics constants of the 3DGS reference implementation (Sloan, "Stupid Spherical Harmonics
# Tricks", 2008): degree 0, 1, 2, 3.
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)
MAX_SH_DEGREE = 3


def sh_basis(dirs: Tensor, degree: int) -> Tensor:
    """Real SH basis at unit directions ``dirs`` (N, 3): (N, (degree+1)²) in the 3DGS ordering."""
    if not 0 <= degree <= MAX_SH_DEGREE:
        raise ValueError(f"SH degree must lie in 0..{MAX_SH_DEGREE}, got {degree}")
    n = dirs.shape[0]
    cols = [torch.full((n,), SH_C0, dtype=dirs.dtype, device=dirs.device)]
    if degree >= 1:
        x, y, z = dirs.unbind(-1)
        cols += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
        if degree >= 2:
            xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
            cols += [
                SH_C2[0] * xy,
                SH_C2[1] * yz,
                SH_C2[2] * (2.0 * zz - xx - yy),
                SH_C2[3] * xz,
                SH_C2[4] * (xx - yy),
            ]
            if degree >= 3:
                cols += [
                    SH_C3[0] * y * (3 * xx - yy),
                    SH_C3[1] * xy * z,
                    SH_C3[2] * y * (4 * zz - xx - yy),
                    SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
                    SH_C3[4] * x * (4 * zz - xx - yy),
                    SH_C3[5] * z * (xx - yy),
                    SH_C3[6] * x * (xx - 3 * yy),
                ]
    return torch.stack(cols, dim=-1)


def sh_to_color(sh: Tensor, means: Tensor, campos: Tensor, degree: int) -> Tensor:
    """Colours (N, C) ≥ 0 of Gaussians with SH coefficients ``sh`` (N, K, C), K ≥ (degree+1)², seen from
    ``campos`` (3,). Degree 0 needs no directions (view-independent)."""
    if degree == 0:
        return (SH_C0 * sh[:, 0, :] + 0.5).clamp_min(0.0)
    k = (degree + 1) ** 2
    d = means.detach() - campos
    d = d / d.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    basis = sh_basis(d, degree)  # (N, k)
    return (torch.einsum("nk,nkc->nc", basis, sh[:, :k, :]) + 0.5).clamp_min(0.0)


def render_gaussians(
    means: Tensor,
    quats: Tensor,
    log_scales: Tensor,
    opacity_logits: Tensor,
    sh: Tensor,
    c2w: Tensor,
    K: Tensor,
    width: int,
    height: int,
    background: Tensor | None = None,
    sh_degree: int = 0,
    backend: str = "auto",
) -> tuple[Tensor, Tensor, dict]:
    """Render one camera; differentiable in every Gaussian tensor.

    Args:
        means (N, 3), quats (N, 4) w x y z, log_scales (N, 3), opacity_logits (N,), sh (N, K, C) with
        K ≥ (sh_degree+1)²; c2w (4, 4) camera-to-world (OpenCV axes; any float dtype, not differentiated);
        K (3, 3) intrinsics; background (C,) or None (black).

    Returns:
        image (H, W, C), alpha (H, W), info (see :func:`eigs.render.rasterize`).
    """
    c2w = c2w.detach().to(device=means.device, dtype=torch.float64)
    viewmat = torch.linalg.inv(c2w)
    colors = sh_to_color(sh, means, c2w[:3, 3].to(means.dtype), sh_degree)
    return rasterize(
        means,
        quats,
        torch.exp(log_scales),
        torch.sigmoid(opacity_logits),
        colors,
        viewmat,
        K,
        width,
        height,
        background=background,
        backend=backend,  # type: ignore[arg-type]
    )
