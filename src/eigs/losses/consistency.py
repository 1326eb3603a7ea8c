"""EiGS's motion-consistency loss (paper Eq. 3–6): per-Gaussian displacements against the best-fitting rigid motion.

A twist ξ = (ω, ν) moves a point x by δx̂ = −ω × x − ν = [x]ₓ ω − ν (Eq. 3–4), linear in ξ: δx̂ = A(x) ξ with the
3 × 6 block A(x) = [[x]ₓ, −I]. The fit ξ* = argmin ‖Aξ − b‖² + λ‖ξ‖² (Eq. 5) is solved in closed form from the
6 × 6 normal equations, accumulated from sums over the Gaussians without forming A (3N × 6):

    AᵀA = [[Σ(|x|² I − x xᵀ), [Σx]ₓ], [−[Σx]ₓ, N I]],   Aᵀb = [−Σ x × δx, −Σ δx].

Conditioning: the sums use centred, scaled coordinates x' = (x − c)/s (c the mean, s the RMS radius), which
reparametrises ξ = T ξ' linearly (ω = ω'/s, ν = ν' + c × ω); the regulariser λ‖ξ‖² = λ ξ'ᵀ TᵀT ξ' is carried over
exactly, so the solution is that of Eq. 5 in the original coordinates. The 6 × 6 solve runs in float64.

Precision: for well-conditioned inputs (non-degenerate centres) a noise-free rigid field is recovered to ~1e-12
relative in float64 and ~1e-6 in float32 inputs; degenerate inputs (one point, collinear points) are handled by
λ > 0 (the null space gets the minimum-norm answer) and stay finite.
"""

from __future__ import annotations

import torch
from torch import Tensor

DEFAULT_REG = 1e-8  # λ_reg of Eq. 5 ("a small regularization weight"), relative to the number of Gaussians
DEFAULT_DELTA = 0.1  # Huber threshold δ of Eq. 6


def _skew(v: Tensor) -> Tensor:
    """(3,) → (3, 3) with skew(v) @ w = v × w."""
    z = v.new_zeros(())
    return torch.stack([
        torch.stack([z, -v[2], v[1]]),
        torch.stack([v[2], z, -v[0]]),
        torch.stack([-v[1], v[0], z]),
    ])  # fmt: skip


def fit_twist(x: Tensor, dx: Tensor, reg: float = DEFAULT_REG) -> tuple[Tensor, Tensor]:
    """Best-fitting twist of displacements ``dx`` (N, 3) at points ``x`` (N, 3): (omega (3,), nu (3,)) in x's dtype.

    Minimises Σ‖−ω × x_j − ν − δx_j‖² + reg·N·‖ξ‖² (the regulariser scales with N so its strength does not depend on
    the number of Gaussians). Differentiable in ``dx`` (and ``x``); N = 0 returns zeros.
    """
    if x.shape != dx.shape or x.dim() != 2 or x.shape[1] != 3:
        raise ValueError(f"x and dx must both be (N, 3), got {tuple(x.shape)} and {tuple(dx.shape)}")
    n = x.shape[0]
    if n == 0:
        return x.new_zeros(3), x.new_zeros(3)
    xd, dd = x.to(torch.float64), dx.to(torch.float64)
    c = xd.detach().mean(dim=0)
    s = ((xd.detach() - c) ** 2).sum(dim=1).mean().sqrt()
    if not bool(s > 1e-9 * (1.0 + c.abs().max())):  # all points (numerically) at one place: centre, no scaling
        s = torch.ones((), dtype=torch.float64, device=x.device)
    xs = (xd - c) / s  # (N, 3) conditioned coordinates
    eye = torch.eye(3, dtype=torch.float64, device=x.device)
    sx = xs.sum(dim=0)
    ata = torch.zeros(6, 6, dtype=torch.float64, device=x.device)
    ata[:3, :3] = (xs * xs).sum() * eye - xs.T @ xs
    ata[:3, 3:] = _skew(sx)
    ata[3:, :3] = -_skew(sx)
    ata[3:, 3:] = n * eye
    atb = torch.cat([-torch.cross(xs, dd, dim=1).sum(dim=0), -dd.sum(dim=0)])
    # ξ = T ξ': ω = ω'/s, ν = ν' + c × ω'/s
    t = torch.zeros(6, 6, dtype=torch.float64, device=x.device)
    t[:3, :3] = eye / s
    t[3:, :3] = _skew(c) / s
    t[3:, 3:] = eye
    lhs = ata + (reg * n) * (t.T @ t)  # symmetric positive definite for reg > 0
    sol, info = torch.linalg.solve_ex(lhs, atb)
    if int(info) != 0 or not bool(torch.isfinite(sol).all()):
        # reg = 0 with degenerate points (one point, a line): the minimum-norm least-squares answer
        sol = torch.linalg.lstsq(lhs, atb.unsqueeze(1), driver="gelsd").solution.squeeze(1)
    xi = t @ sol
    return xi[:3].to(x.dtype), xi[3:].to(x.dtype)


def rigid_displacement(x: Tensor, omega: Tensor, nu: Tensor) -> Tensor:
    """Eq. 3: −ω × x − ν for points ``x`` (N, 3)."""
    return -torch.cross(omega.expand_as(x), x, dim=1) - nu


def motion_consistency_loss(
    x: Tensor,
    dx: Tensor,
    reg: float = DEFAULT_REG,
    delta: float = DEFAULT_DELTA,
    grad_through_fit: bool = True,
) -> Tensor:
    """Eq. 6: mean over Gaussians of the Huber loss (threshold ``delta``, summed over x, y, z) between ``dx``
    (N, 3) and the displacement of the best-fitting twist. ``grad_through_fit``: whether gradients flow through ξ*
    (for a squared loss both give the same gradient, since the residual is orthogonal to the rigid fits); ``x`` is
    treated as a constant. N = 0 gives 0."""
    if x.shape[0] == 0:
        return dx.sum() * 0.0
    x = x.detach()
    omega, nu = fit_twist(x, dx if grad_through_fit else dx.detach(), reg)
    fitted = rigid_displacement(x, omega, nu)
    return torch.nn.functional.huber_loss(dx, fitted, reduction="sum", delta=delta) / x.shape[0]
