"""Rigid motions of Gaussians and of cameras: moving the camera by T equals moving every Gaussian by T⁻¹, exactly for
centres and rotations (scales and colours do not change; view-dependent colour aside), and differentiably — so a
method can model camera motion, and evaluation can refine a test camera, without pose gradients from the rasterizer.
Twists ``ξ = (ω, ν)``: rotation vector (radians) first, then translation (scene units), 6 numbers; ``se3_exp`` and
``se3_log`` map them to and from (4, 4) rigid transforms."""

from __future__ import annotations

import torch
from torch import Tensor


def _skew(w: Tensor) -> Tensor:
    """(…, 3) → (…, 3, 3) cross-product matrices."""
    z = torch.zeros_like(w[..., 0])
    return torch.stack([
        torch.stack([z, -w[..., 2], w[..., 1]], -1),
        torch.stack([w[..., 2], z, -w[..., 0]], -1),
        torch.stack([-w[..., 1], w[..., 0], z], -1),
    ], -2)  # fmt: skip


def se3_exp(xi: Tensor) -> Tensor:
    """(…, 6) twists (ω, ν) → (…, 4, 4) rigid transforms. Exact Rodrigues formulas; below θ = 1e-4 rad the
    coefficients use their Taylor series (error < 1e-12 relative), so the map and its gradient are finite at 0."""
    w, v = xi[..., :3], xi[..., 3:]
    th2 = (w * w).sum(-1)
    small = th2 < 1e-8
    th2s = torch.where(small, torch.ones_like(th2), th2)
    th = th2s.sqrt()
    a = torch.where(small, 1 - th2 / 6, torch.sin(th) / th)
    b = torch.where(small, 0.5 - th2 / 24, (1 - torch.cos(th)) / th2s)
    c = torch.where(small, 1.0 / 6 - th2 / 120, (th - torch.sin(th)) / (th2s * th))
    wx = _skew(w)
    wx2 = wx @ wx
    eye = torch.eye(3, dtype=xi.dtype, device=xi.device).expand(wx.shape)
    r = eye + a[..., None, None] * wx + b[..., None, None] * wx2
    jac = eye + b[..., None, None] * wx + c[..., None, None] * wx2  # left Jacobian of SO(3)
    t = (jac @ v.unsqueeze(-1)).squeeze(-1)
    out = torch.zeros(*xi.shape[:-1], 4, 4, dtype=xi.dtype, device=xi.device)
    out[..., :3, :3] = r
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def se3_log(t: Tensor) -> Tensor:
    """(…, 4, 4) rigid transforms with rotation angle < π − 1e-3 → (…, 6) twists (ω, ν), the inverse of
    :func:`se3_exp` (float64 recommended; used once per view to initialise trajectories, not differentiated)."""
    r, p = t[..., :3, :3], t[..., :3, 3]
    cos = ((r.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1.0, 1.0)
    th = torch.arccos(cos)
    small = th < 1e-6
    ths = torch.where(small, torch.ones_like(th), th)
    k = torch.where(small, 0.5 + th**2 / 12, ths / (2 * torch.sin(ths)))
    vee = torch.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    w = k[..., None] * vee
    th2 = (w * w).sum(-1)
    th2s = torch.where(small, torch.ones_like(th2), th2)
    # inverse left Jacobian: I − ½[ω]× + (1/θ² − (1 + cos θ)/(2θ sin θ))[ω]×²
    d = torch.where(small, 1.0 / 12 + th2 / 720, 1 / th2s - (1 + torch.cos(ths)) / (2 * ths * torch.sin(ths)))
    wx = _skew(w)
    eye = torch.eye(3, dtype=t.dtype, device=t.device).expand(wx.shape)
    jinv = eye - 0.5 * wx + d[..., None, None] * (wx @ wx)
    return torch.cat([w, (jinv @ p.unsqueeze(-1)).squeeze(-1)], -1)


def rotmat_to_quat(r: Tensor) -> Tensor:
    """(…, 3, 3) rotation matrices → (…, 4) unit quaternions w x y z with w ≥ 0 (Shepperd's method, stable)."""
    m = r
    t = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = torch.stack([
        torch.stack([1 + t, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        torch.stack([m[..., 2, 1] - m[..., 1, 2], 1 + 2 * m[..., 0, 0] - t, m[..., 0, 1] + m[..., 1, 0],
                     m[..., 0, 2] + m[..., 2, 0]], -1),
        torch.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 + 2 * m[..., 1, 1] - t,
                     m[..., 1, 2] + m[..., 2, 1]], -1),
        torch.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1],
                     1 + 2 * m[..., 2, 2] - t], -1),
    ], -2)  # fmt: skip
    diag = torch.stack([t, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], -1)
    best = diag.argmax(dim=-1)
    q = torch.gather(cands, -2, best[..., None, None].expand(*best.shape, 1, 4)).squeeze(-2)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return torch.where(q[..., :1] < 0, -q, q)


def quat_multiply(a: Tensor, b: Tensor) -> Tensor:
    """Hamilton product a ⊗ b of (…, 4) quaternions w x y z (rotation b, then a)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], -1)  # fmt: skip


def quat_left_matrix(a: Tensor) -> Tensor:
    """(…, 4) quaternions w x y z → (…, 4, 4) matrices L(a) with L(a) b = a ⊗ b (:func:`quat_multiply`)."""
    aw, ax, ay, az = a.unbind(-1)
    return torch.stack([
        torch.stack([aw, -ax, -ay, -az], -1),
        torch.stack([ax, aw, -az, ay], -1),
        torch.stack([ay, az, aw, -ax], -1),
        torch.stack([az, -ay, ax, aw], -1),
    ], -2)  # fmt: skip


def rotation_product_matrix(t: Tensor) -> Tensor:
    """(…, 4, 4) rigid transforms → (…, 4, 4) L(q_R)ᵀ, the matrix :func:`transform_gaussians` right-multiplies
    the rotations by (q ↦ q_R ⊗ q as ``q @ L(q_R)ᵀ``)."""
    return quat_left_matrix(rotmat_to_quat(t[..., :3, :3])).transpose(-1, -2)


def transform_gaussians(
    means: Tensor, quats: Tensor, t: Tensor, lt: Tensor | None = None
) -> tuple[Tensor, Tensor]:
    """Apply the rigid (4, 4) transform ``t`` to Gaussians: centres (N, 3) ↦ R x + p, rotations (N, 4) ↦ q_R ⊗ q
    (the quaternions keep their norm). With a stack ``t`` (K, 4, 4): every transform at once, (K, N, 3) centres and
    (K, N, 4) rotations. The rotations as one product with L(q_R)ᵀ (:func:`quat_left_matrix`): one kernel and one
    in the backward instead of some thirty element-wise ones over (K, N). ``lt``: :func:`rotation_product_matrix`
    of ``t`` when the caller keeps it (a constant ``t``: some sixty small ops a call saved)."""
    r = t[..., :3, :3].to(means.dtype)
    p = t[..., :3, 3].to(means.dtype)
    lt = rotation_product_matrix(r) if lt is None else lt.to(means.dtype)  # (…, 4, 4)
    if t.dim() == 3:
        moved = torch.matmul(means, r.transpose(1, 2)) + p[:, None, :]  # (K, N, 3)
        return moved, torch.matmul(quats, lt)  # (K, N, 4)
    return means @ r.T + p, quats @ lt


def se3_adjoint(t: Tensor) -> Tensor:
    """(…, 4, 4) rigid transforms ``T = [R p]`` → (…, 6, 6) adjoints for twists ordered (ω, ν):
    ``T · exp(ξ) · T⁻¹ = exp(Ad_T ξ)`` with ``Ad_T = [[R, 0], [p× R, R]]`` (exact, no small-angle assumption)."""
    r, p = t[..., :3, :3], t[..., :3, 3]
    top = torch.cat([r, torch.zeros_like(r)], -1)
    return torch.cat([top, torch.cat([_skew(p) @ r, r], -1)], -2)


def gaussian_motion(c2w: Tensor, xi: Tensor, c2w_inv: Tensor) -> Tensor:
    """(…, 4, 4) ``c2w · exp(−ξ) · c2w⁻¹``: the motion of the Gaussians that renders, from camera ``c2w``, what the
    camera ``c2w · exp(ξ)`` sees (``xi`` (…, 6) a camera-frame twist; ``c2w_inv`` the inverse of ``c2w``)."""
    return c2w @ se3_exp(-xi) @ c2w_inv
