"""Pure-PyTorch dense reference of the rasterizer (tests and benchmarks only).

It evaluates the contract of ``docs/rasterizer.md`` literally: every pixel against every kept Gaussian in
depth order, with an exclusive ``cumprod`` for the transmittance and a termination mask for the early stop.
Every log/sqrt/division/exp is guarded so that masked entries cannot poison gradients (the inputs of culled
Gaussians are replaced by harmless values before any arithmetic). Memory grows as pixels x Gaussians x ~20
values: keep it to unit-test sizes (<= 128^2 pixels, <= a few thousand Gaussians).
"""

from __future__ import annotations

import torch
from torch import Tensor

ALPHA_MAX = 0.99
ALPHA_MIN = 1.0 / 255.0
TRANS_MIN = 1e-4
NEAR = 0.01
BLUR = 0.3
CLAMP_FOV = 0.3
MIN_QUAT_NORM2 = 1e-12
MIN_SCALE = 1e-8


def quat_to_rotmat(quats: Tensor) -> Tensor:
    """Rotation matrices of unit quaternions. quats: (N, 4) wxyz, normalised -> (N, 3, 3)."""
    w, x, y, z = quats.unbind(-1)
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]  # fmt: skip
    return torch.stack(rows, -1).reshape(quats.shape[:-1] + (3, 3))


def project_reference(
    means: Tensor,
    quats: Tensor,
    scales: Tensor,
    opacities: Tensor,
    viewmat: Tensor,
    K: Tensor,
    width: int,
    height: int,
) -> tuple[Tensor, Tensor, Tensor, Tensor]:
    """Differentiable projection with the contract's culling.

    Args: means (N, 3), quats (N, 4) wxyz (unnormalised), scales (N, 3), opacities (N,), viewmat (4, 4)
    world-to-camera (OpenCV axes), K (3, 3).
    Returns: means2d (N, 2) px, conics (N, 3) = upper triangle of the inverse 2-D covariance, depths (N,),
    kept (N,) bool. Culled rows hold finite dummy values (their gradients are zero).
    """
    dt = means.dtype
    with torch.no_grad():
        finite = (
            torch.isfinite(means).all(-1)
            & torch.isfinite(quats).all(-1)
            & torch.isfinite(scales).all(-1)
            & torch.isfinite(opacities)
        )
        q2 = torch.where(finite[:, None], quats, torch.zeros_like(quats)).pow(2).sum(-1)
        ok = finite & (q2 >= MIN_QUAT_NORM2) & (scales > MIN_SCALE).all(-1) & (opacities >= ALPHA_MIN)
    one = torch.ones((), dtype=dt)
    m = torch.where(ok[:, None], means, torch.zeros_like(means))
    q = torch.where(ok[:, None], quats, torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=dt))
    s = torch.where(ok[:, None], scales, torch.ones_like(scales))

    Rw, tw = viewmat[:3, :3], viewmat[:3, 3]
    t = m @ Rw.T + tw
    with torch.no_grad():
        ok = ok & (t[:, 2] >= NEAR) & torch.isfinite(t).all(-1)
    t = torch.where(ok[:, None], t, torch.tensor([0.0, 0.0, 1.0], dtype=dt))
    qn = q / q.norm(dim=-1, keepdim=True).clamp_min(MIN_QUAT_NORM2**0.5)
    R = quat_to_rotmat(qn)
    M = R * s[:, None, :]
    Sigma = M @ M.transpose(-1, -2)
    Ccam = Rw @ Sigma @ Rw.T

    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x, y, z = t.unbind(-1)
    lim_xp = (width - cx) / fx + CLAMP_FOV * width / (2 * fx)
    lim_xn = cx / fx + CLAMP_FOV * width / (2 * fx)
    lim_yp = (height - cy) / fy + CLAMP_FOV * height / (2 * fy)
    lim_yn = cy / fy + CLAMP_FOV * height / (2 * fy)
    txc = z * torch.clamp(x / z, -lim_xn, lim_xp)
    tyc = z * torch.clamp(y / z, -lim_yn, lim_yp)
    zero = torch.zeros_like(z)
    J = torch.stack(
        [
            torch.stack([fx / z, zero, -fx * txc / z**2], -1),
            torch.stack([zero, fy / z, -fy * tyc / z**2], -1),
        ],
        -2,
    )  # (N, 2, 3)
    cov2 = J @ Ccam @ J.transpose(-1, -2) + BLUR * torch.eye(2, dtype=dt)
    s00, s01, s11 = cov2[:, 0, 0], cov2[:, 0, 1], cov2[:, 1, 1]
    det = s00 * s11 - s01 * s01
    with torch.no_grad():
        ok = ok & (det > 0) & torch.isfinite(det)
    det = torch.where(ok, det, one)
    conics = torch.stack([s11 / det, -s01 / det, s00 / det], -1)
    means2d = torch.stack([fx * x / z + cx, fy * y / z + cy], -1)
    with torch.no_grad():
        ok = ok & torch.isfinite(conics).all(-1) & torch.isfinite(means2d).all(-1)
    conics = torch.where(ok[:, None], conics, torch.zeros_like(conics))
    means2d = torch.where(ok[:, None], means2d, torch.zeros_like(means2d))
    depths = torch.where(ok, z, zero).detach()
    return means2d, conics, depths, ok


def rasterize_dense_reference(
    means2d: Tensor,
    conics: Tensor,
    colors: Tensor,
    opacities: Tensor,
    depths: Tensor,
    kept: Tensor,
    width: int,
    height: int,
    background: Tensor,
) -> tuple[Tensor, Tensor, Tensor]:
    """Dense front-to-back compositing of every kept Gaussian at every pixel.

    Args: means2d (N, 2) px, conics (N, 3), colors (N, D), opacities (N,), depths (N,), kept (N,) bool,
    background (D,).
    Returns: image (H, W, D), alpha (H, W), near_threshold (H, W) bool: pixels where some Gaussian's alpha
    lies within 1e-6 of 1/255, or its T (1 - alpha) within 1e-6 of 1e-4 (decisions that rounding can flip).
    """
    dt = means2d.dtype
    idx = kept.nonzero().squeeze(-1)
    idx = idx[torch.argsort(depths[idx], stable=True)]  # ascending depth, ties by index
    m, con, col, op = means2d[idx], conics[idx], colors[idx], opacities[idx]
    jj, ii = torch.meshgrid(torch.arange(width, dtype=dt), torch.arange(height, dtype=dt), indexing="xy")
    pix = torch.stack([jj + 0.5, ii + 0.5], -1).reshape(-1, 2)  # (P, 2)
    d = pix[:, None, :] - m[None, :, :]  # (P, K, 2)
    dx, dy = d[..., 0], d[..., 1]
    sigma = 0.5 * (con[:, 0] * dx * dx + con[:, 2] * dy * dy) + con[:, 1] * dx * dy
    raw = op * torch.exp(-sigma.clamp_min(0.0))
    alpha = raw.clamp(max=ALPHA_MAX)
    with torch.no_grad():
        valid = (sigma >= 0) & (alpha >= ALPHA_MIN)
    a = alpha * valid
    one_minus = 1 - a
    T = torch.cat([torch.ones_like(one_minus[:, :1]), torch.cumprod(one_minus, -1)[:, :-1]], -1)
    with torch.no_grad():
        term = valid & (T * (1 - alpha) < TRANS_MIN)
        alive = torch.cumsum(term.to(torch.int32), -1) == 0
    w = a * T * alive
    image = w @ col  # (P, D)
    t_final = torch.where(alive, one_minus, torch.ones_like(one_minus)).prod(-1)
    image = image + t_final[:, None] * background
    with torch.no_grad():
        reached = alive | term
        near = (alpha - ALPHA_MIN).abs() < 1e-6
        near |= valid & reached & ((T * (1 - alpha) - TRANS_MIN).abs() < 1e-6)
        near_px = near.any(-1)
    D = colors.shape[1]
    return image.reshape(height, width, D), (1 - t_final).reshape(height, width), near_px.reshape(height, width)


def render_reference(
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
) -> tuple[Tensor, Tensor, dict]:
    """The dense reference of :func:`eigs.render.rasterize` (same arguments; pure PyTorch, differentiable).

    Returns: image (H, W, D), alpha (H, W), info with ``means2d`` (N, 2), ``conics`` (N, 3), ``depths`` (N,),
    ``kept`` (N,) bool and ``near_threshold`` (H, W) bool.
    """
    if background is None:
        background = torch.zeros(colors.shape[1], dtype=colors.dtype)
    means2d, conics, depths, kept = project_reference(
        means, quats, scales, opacities, viewmat, K, width, height
    )
    kept = kept & torch.isfinite(colors).all(-1)  # a non-finite colour culls its Gaussian too
    image, alpha, near = rasterize_dense_reference(
        means2d, conics, colors, opacities, depths, kept, width, height, background
    )
    info = {"means2d": means2d, "conics": conics, "depths": depths, "kept": kept, "near_threshold": near}
    return image, alpha, info
