"""Rigid motions applied to Gaussians: moving the camera by T equals moving every Gaussian by T⁻¹, exactly for
centres and rotations (scales and colours do not change; view-dependent colour aside), and differentiably — so
methods can model camera motion without pose gradients from the rasterizer."""

from __future__ import annotations

import torch
from torch import Tensor


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


def transform_gaussians(means: Tensor, quats: Tensor, t: Tensor) -> tuple[Tensor, Tensor]:
    """Apply the rigid (4, 4) transform ``t`` to Gaussians: centres (N, 3) ↦ R x + p, rotations (N, 4) ↦ q_R ⊗ q
    (the quaternions keep their norm). With a stack ``t`` (K, 4, 4): every transform at once, (K, N, 3) centres and
    (K, N, 4) rotations."""
    r = t[..., :3, :3].to(means.dtype)
    p = t[..., :3, 3].to(means.dtype)
    qr = rotmat_to_quat(r)
    if t.dim() == 3:
        moved = torch.matmul(means, r.transpose(1, 2)) + p[:, None, :]  # (K, N, 3)
        return moved, quat_multiply(qr[:, None, :].expand(-1, quats.shape[0], 4), quats.expand(t.shape[0], -1, 4))
    moved = means @ r.T + p
    return moved, quat_multiply(qr.expand_as(quats), quats)
