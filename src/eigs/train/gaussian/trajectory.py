"""Camera trajectories within an exposure, for the trajectory baselines (BAD-Gaussians, BeSplat, EvaGaussians).

A view's camera during its exposure is ``P(u) = P_ref · Δ(u)``, u ∈ [0, 1] the fraction of the exposure, with a
camera-frame delta ``Δ(u) = exp(ξ(u))`` and ``ξ(u)`` a curve in se(3) through K learnable control twists: linear
(K = 2), a uniform cubic B-spline (K = 4) or a Bézier curve (any K ≥ 2). The curve is taken in the Lie algebra of
the delta, the first-order form of BAD-Gaussians' separate translation-lerp / rotation-slerp interpolation and of
the cumulative B-spline; exposure motions are small (a few degrees, a few percent of the scene), where the two agree
to second order in the motion.

The rasterizer has no pose gradients, so a camera at ``P(u)`` is rendered as the camera ``P_ref`` looking at the
Gaussians moved by ``P_ref · Δ(u)⁻¹ · P_ref⁻¹`` (exact for a rigid motion: :mod:`eigs.train.gaussian.rigid`).

Twists are ``ξ = (ω, ν)``: rotation vector (radians) first, then translation (scene units), 6 numbers.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from eigs.train.gaussian.options import control_problem


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


def curve_weights(mode: str, n_control: int, u: Tensor) -> Tensor:
    """Weights (U, K) of the K control twists at the times ``u`` (U,) in [0, 1]; each row sums to 1, so a curve
    whose control twists are all equal is constant. A mode (:data:`eigs.train.gaussian.options.MODES`) or control
    count that do not fit raise ValueError."""
    problem = control_problem(mode, n_control)
    if problem:
        raise ValueError(problem)
    u = u.to(torch.float64)
    if mode == "linear":
        return torch.stack([1 - u, u], -1)
    if mode == "cubic":  # uniform cubic B-spline segment over 4 knots (BAD-Gaussians' "cubic")
        return torch.stack([(1 - u) ** 3, 3 * u**3 - 6 * u**2 + 4, -3 * u**3 + 3 * u**2 + 3 * u + 1, u**3], -1) / 6
    n = n_control - 1  # Bézier
    return torch.stack([math.comb(n, i) * u**i * (1 - u) ** (n - i) for i in range(n_control)], -1)


def fit_controls(mode: str, n_control: int, u: Tensor, xi: Tensor, reg: float = 1e-6) -> Tensor:
    """Least-squares control twists (K, 6) whose curve passes closest to the twists ``xi`` (M, 6) at times ``u``
    (M,), with a small ridge ``reg`` (relative to the normal matrix's trace) so K > M stays well posed."""
    w = curve_weights(mode, n_control, u)  # (M, K) float64
    a = w.T @ w
    a = a + reg * (a.diagonal().sum() / n_control + 1e-12) * torch.eye(n_control, dtype=a.dtype)
    return torch.linalg.solve(a, w.T @ xi.to(torch.float64))


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
