"""Adapter from eigs's rasterizer conventions to gsplat (CUDA tensors only; the optional extra ``gpu``).

Both use OpenCV camera axes, a world-to-camera ``viewmat``, a pinhole K with pixel centres at (j + 0.5, i + 0.5),
post-activation scales and opacities, wxyz quaternions, a 0.3 px^2 blur, near plane 0.01, an opacity-aware
box and 2-D mean gradients in pixel units. The rules that differ in gsplat 1.5.3 are listed in
``DEVIATIONS`` (logged once per process when the gsplat backend is first used) and in docs/rasterizer.md.
"""

from __future__ import annotations

import logging

import torch
from torch import Tensor

from eigs.errors import EigsError

log = logging.getLogger(__name__)

DEVIATIONS = (
    "alpha is capped at 0.999 (eigs: 0.99)",
    "a pixel stops when T*(1-alpha) <= 1e-4 (eigs: < 1e-4)",
    "Gaussians beyond far_plane = 1e10 are culled (eigs: no far plane)",
    "equal depths are ordered by gsplat's radix sort (eigs: by index)",
    "float32 only; no float64 path",
    "projected boxes are rounded up to whole pixels (the same pixels reach alpha >= 1/255)",
)
_logged = False


def _cull_mask(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor) -> Tensor:
    """(N,) bool: Gaussians eigs culls before projection (non-finite inputs, zero quaternion, scale <= 1e-8)."""
    finite = (
        torch.isfinite(means).all(-1)
        & torch.isfinite(quats).all(-1)
        & torch.isfinite(scales).all(-1)
        & torch.isfinite(opacities)
        & torch.isfinite(colors).all(-1)
    )
    q2 = torch.where(finite[:, None], quats, torch.zeros_like(quats)).pow(2).sum(-1)
    return ~(finite & (q2 >= 1e-12) & (scales > 1e-8).all(-1))


def rasterize_gsplat(
    means: Tensor,
    quats: Tensor,
    scales: Tensor,
    opacities: Tensor,
    colors: Tensor,
    viewmat: Tensor,
    K: Tensor,
    width: int,
    height: int,
    background: Tensor,
) -> tuple[Tensor, Tensor, dict]:
    """Render with ``gsplat.rasterization`` and return eigs's (image (H,W,D), alpha (H,W), info).

    ``info["means2d"]`` is gsplat's (1, N, 2) tensor (it is the node in the graph, so ``retain_grad`` works on
    it); use :func:`eigs.render.means2d_grad` to read its gradient as (N, 2).
    """
    global _logged
    try:
        import gsplat
    except ImportError as exc:
        raise EigsError(None, "backend 'gsplat' needs the optional extra: pip install 'eigs[gpu]'") from exc
    if not _logged:
        log.info("gsplat %s backend; rules that differ from eigs's CPU rasterizer: %s",
                 getattr(gsplat, "__version__", "?"), "; ".join(DEVIATIONS))
        _logged = True
    with torch.no_grad():
        culled = _cull_mask(means, quats, scales, opacities, colors)
    if bool(culled.any()):
        # Map eigs's culling onto gsplat's: harmless geometry, zero opacity (gsplat culls opacity < 1/255).
        keep = ~culled
        means = torch.where(keep[:, None], means, torch.zeros_like(means))
        quats = torch.where(keep[:, None], quats, torch.tensor([1.0, 0.0, 0.0, 0.0], device=quats.device,
                                                                 dtype=quats.dtype))
        scales = torch.where(keep[:, None], scales, torch.ones_like(scales))
        opacities = torch.where(keep, opacities, torch.zeros_like(opacities))
        colors = torch.where(keep[:, None], colors, torch.zeros_like(colors))
    render, alphas, meta = gsplat.rasterization(
        means, quats, scales, opacities, colors, viewmat[None], K[None], width, height,
        near_plane=0.01, far_plane=1e10, eps2d=0.3, sh_degree=None, packed=False, tile_size=16,
        backgrounds=background[None], render_mode="RGB", rasterize_mode="classic", camera_model="pinhole",
    )  # fmt: skip
    info = {
        "backend": "gsplat",
        "means2d": meta["means2d"],
        "conics": meta["conics"][0],
        "depths": meta["depths"][0],
        "radii": meta["radii"][0],
        "width": width,
        "height": height,
        "gsplat_meta": meta,
    }
    return render[0], alphas[0, ..., 0], info
