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
    With a stack of K displacement fields ``dx`` (K, N, 3) at the same points: (omega (K, 3), nu (K, 3)), one fit
    each (the normal matrix depends on ``x`` only, so it is built and factorised once for all K).

    Minimises Σ‖−ω × x_j − ν − δx_j‖² + reg·N·‖ξ‖² (the regulariser scales with N so its strength does not depend on
    the number of Gaussians). Differentiable in ``dx`` (and ``x``); N = 0 returns zeros.
    """
    batched = dx.dim() == 3
    if x.dim() != 2 or x.shape[1] != 3 or dx.shape[-2:] != x.shape or dx.dim() not in (2, 3):
        raise ValueError(f"x must be (N, 3) and dx (N, 3) or (K, N, 3), got {tuple(x.shape)} and {tuple(dx.shape)}")
    n = x.shape[0]
    if n == 0:
        return x.new_zeros(dx.shape[:-2] + (3,)), x.new_zeros(dx.shape[:-2] + (3,))
    xd, dd = x.to(torch.float64), dx.to(torch.float64)
    if not batched:
        dd = dd.unsqueeze(0)  # (K = 1, N, 3)
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
    # Aᵀb per field: −Σ x × δx (K, 3) and −Σ δx (K, 3)
    cross_sum = torch.cross(xs.expand_as(dd), dd, dim=2).sum(dim=1)
    atb = torch.cat([-cross_sum, -dd.sum(dim=1)], dim=1).T  # (6, K)
    # ξ = T ξ': ω = ω'/s, ν = ν' + c × ω'/s
    t = torch.zeros(6, 6, dtype=torch.float64, device=x.device)
    t[:3, :3] = eye / s
    t[3:, :3] = _skew(c) / s
    t[3:, 3:] = eye
    lhs = ata + (reg * n) * (t.T @ t)  # symmetric positive definite for reg > 0
    sol, info = torch.linalg.solve_ex(lhs, atb)  # (6, K)
    if int(info) != 0 or not bool(torch.isfinite(sol).all()):
        # reg = 0 with degenerate points (one point, a line): the minimum-norm least-squares answer
        sol = torch.linalg.lstsq(lhs, atb, driver="gelsd").solution
    xi = (t @ sol).T.to(x.dtype)  # (K, 6)
    if not batched:
        return xi[0, :3], xi[0, 3:]
    return xi[:, :3], xi[:, 3:]


def rigid_displacement(x: Tensor, omega: Tensor, nu: Tensor) -> Tensor:
    """Eq. 3: −ω × x − ν for points ``x`` (N, 3) and one twist (ω, ν: (3,)) → (N, 3), or K twists ((K, 3)) →
    (K, N, 3)."""
    if omega.dim() == 2:
        return (
            -torch.cross(omega[:, None, :].expand(-1, x.shape[0], 3), x.expand(omega.shape[0], -1, 3), dim=2)
            - nu[:, None, :]
        )
    return -torch.cross(omega.expand_as(x), x, dim=1) - nu


def motion_consistency_loss(
    x: Tensor,
    dx: Tensor,
    reg: float = DEFAULT_REG,
    delta: float = DEFAULT_DELTA,
    grad_through_fit: bool = True,
) -> Tensor:
    """Eq. 6: mean over Gaussians of the Huber loss (threshold ``delta``, summed over x, y, z) between ``dx``
    (N, 3) and the displacement of the best-fitting twist; for a stack ``dx`` (K, N, 3) (the K moved latent times of
    one view) the mean of the K fields' losses, each against its own fit. ``grad_through_fit``: whether gradients
    flow through ξ* (for a squared loss both give the same gradient, since the residual is orthogonal to the rigid
    fits); ``x`` is treated as a constant. N = 0 gives 0."""
    if x.shape[0] == 0:
        return dx.sum() * 0.0
    x = x.detach()
    omega, nu = fit_twist(x, dx if grad_through_fit else dx.detach(), reg)
    fitted = rigid_displacement(x, omega, nu)
    k = dx.shape[0] if dx.dim() == 3 else 1
    return torch.nn.functional.huber_loss(dx, fitted, reduction="sum", delta=delta) / (x.shape[0] * k)
