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
    """(…, 3) → (…, 3, 3) with skew(v) @ w = v × w."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack([
        torch.stack([o, -z, y], dim=-1),
        torch.stack([z, o, -x], dim=-1),
        torch.stack([-y, x, o], dim=-1),
    ], dim=-2)  # fmt: skip


class _TwistSystem:
    """The part of the fit that depends on the points only: for ``x`` (N, 3) the conditioned coordinates with a
    column of ones, ``xa`` (N, 4) float64, the normal matrix ``lhs`` (6, 6) with its regulariser and the
    reparametrisation ``t`` (6, 6). Built once per set of points and used for any number of fields (autograd-friendly:
    differentiable in ``x`` when it requires grad)."""

    def __init__(self, x: Tensor, reg: float):
        n = x.shape[0]
        xd = x.to(torch.float64)
        c = xd.detach().mean(dim=0)
        s = ((xd.detach() - c) ** 2).sum(dim=1).mean().sqrt()
        if not bool(s > 1e-9 * (1.0 + c.abs().max())):  # all points (numerically) at one place: centre, no scaling
            s = torch.ones((), dtype=torch.float64, device=x.device)
        xs = (xd - c) / s  # (N, 3) conditioned coordinates
        self.xa = torch.cat([xs, torch.ones_like(xs[:, :1])], dim=1)  # (N, 4)
        eye = torch.eye(3, dtype=torch.float64, device=x.device)
        sx = xs.sum(dim=0)
        ata = torch.zeros(6, 6, dtype=torch.float64, device=x.device)
        ata[:3, :3] = (xs * xs).sum() * eye - xs.T @ xs
        ata[:3, 3:] = _skew(sx)
        ata[3:, :3] = -_skew(sx)
        ata[3:, 3:] = n * eye
        # ξ = T ξ': ω = ω'/s, ν = ν' + c × ω'/s
        t = torch.zeros(6, 6, dtype=torch.float64, device=x.device)
        t[:3, :3] = eye / s
        t[3:, :3] = _skew(c) / s
        t[3:, 3:] = eye
        self.t = t
        self.lhs = ata + (reg * n) * (t.T @ t)  # symmetric positive definite for reg > 0

    def solve(self, fields: Tensor) -> Tensor:
        """K fields as the columns of ``fields`` (N, 3K) (field k in columns 3k..3k+2) → their twists (K, 6) float64,
        (ω, ν) in the points' original coordinates."""
        k = fields.shape[1] // 3
        mom = self.xa.T @ fields.to(torch.float64)  # (4, 3K): Σ x' δxᵀ per field, then Σ δx
        # Aᵀb per field: −Σ x' × δx (K, 3) and −Σ δx (K, 3); (Σ x × δx)_i = M_jl − M_lj for (i, j, l) cyclic
        m = mom[:3].reshape(3, k, 3).transpose(0, 1)  # (K, 3, 3): m[k, j, l] = Σ x'_j δx_kl
        cross_sum = torch.stack([m[:, 1, 2] - m[:, 2, 1], m[:, 2, 0] - m[:, 0, 2], m[:, 0, 1] - m[:, 1, 0]], dim=1)
        atb = torch.cat([-cross_sum, -mom[3].reshape(k, 3)], dim=1).T  # (6, K)
        sol, info = torch.linalg.solve_ex(self.lhs, atb)  # (6, K)
        if int(info) != 0 or not bool(torch.isfinite(sol).all()):
            # reg = 0 with degenerate points (one point, a line): the minimum-norm least-squares answer
            sol = torch.linalg.lstsq(self.lhs, atb, driver="gelsd").solution
        return (self.t @ sol).T


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
    dd = dx if batched else dx.unsqueeze(0)  # (K, N, 3)
    xi = _TwistSystem(x, reg).solve(dd.transpose(0, 1).reshape(n, -1)).to(x.dtype)  # (K, 6)
    if not batched:
        return xi[0, :3], xi[0, 3:]
    return xi[:, :3], xi[:, 3:]


def _rigid_columns(omega: Tensor, nu: Tensor) -> Tensor:
    """K twists (K, 3) each → (4, 3K): the rigid displacements of the points ``xa`` = [x, 1] (N, 4) are ``xa @ W``,
    field k in columns 3k..3k+2 (x·[ω]ₓ − ν = −ω × x − ν)."""
    w = torch.cat([_skew(omega), -nu[:, None, :]], dim=1)  # (K, 4, 3): rows [ω]ₓ, then −ν
    return w.transpose(0, 1).reshape(4, 3 * omega.shape[0])


def rigid_displacement(x: Tensor, omega: Tensor, nu: Tensor) -> Tensor:
    """Eq. 3: −ω × x − ν for points ``x`` (N, 3) and one twist (ω, ν: (3,)) → (N, 3), or K twists ((K, 3)) →
    (K, N, 3)."""
    if omega.dim() == 2:  # one product for the K twists
        xa = torch.cat([x, torch.ones_like(x[:, :1])], dim=1)
        return (xa @ _rigid_columns(omega, nu)).reshape(x.shape[0], -1, 3).transpose(0, 1)
    return -torch.cross(omega.expand_as(x), x, dim=1) - nu


class _ConsistencyLoss(torch.autograd.Function):
    """Eq. 6 for a stack ``dx`` (K, N, 3) at constant points ``x`` (N, 3), forward and backward without an autograd
    graph of the fit. The fields are held as the columns of an (N, 3K) matrix, so that the fit's sums are one product
    with [x', 1] and the fitted fields one product with [x, 1]. The fit is linear in the field, ``fitted = P dx``
    with P = A (AᵀA + λI)⁻¹ Aᵀ symmetric, so the gradient through it is ``h − P h`` for the Huber term's gradient h:
    the same fit applied to h, with the normal matrix of the forward. Agrees with
    :func:`motion_consistency_loss_reference` to float rounding (tests/losses/test_consistency.py)."""

    @staticmethod
    def forward(ctx, dx: Tensor, x: Tensor, reg: float, delta: float, through: bool) -> Tensor:  # noqa: ANN001
        k, n = dx.shape[0], dx.shape[1]
        system = _TwistSystem(x, reg)
        xa = torch.cat([x, torch.ones_like(x[:, :1])], dim=1)  # (N, 4) in x's dtype
        cols = dx.transpose(0, 1).reshape(n, 3 * k)  # (N, 3K)
        xi = system.solve(cols).to(x.dtype)  # (K, 6)
        r = cols - xa @ _rigid_columns(xi[:, :3], xi[:, 3:])  # (N, 3K) residual
        scale = 1.0 / (n * k)
        ctx.save_for_backward(xa, r)
        ctx.system, ctx.delta, ctx.through, ctx.scale = system, delta, through, scale
        return torch.nn.functional.huber_loss(r, torch.zeros_like(r), reduction="sum", delta=delta) * scale

    @staticmethod
    def backward(ctx, v_loss: Tensor) -> tuple[Tensor | None, ...]:  # noqa: ANN001
        xa, r = ctx.saved_tensors
        h = r.clamp(-ctx.delta, ctx.delta) * (v_loss * ctx.scale)  # the Huber term's gradient (N, 3K)
        if ctx.through:
            xi = ctx.system.solve(h).to(h.dtype)
            h = h - xa @ _rigid_columns(xi[:, :3], xi[:, 3:])
        v_dx = h.reshape(h.shape[0], -1, 3).transpose(0, 1)  # (K, N, 3)
        return v_dx, None, None, None, None


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
    fits); ``x`` is treated as a constant. N = 0 gives 0. One autograd Function (:class:`_ConsistencyLoss`); the
    same loss through autograd is :func:`motion_consistency_loss_reference`."""
    if x.shape[0] == 0:
        return dx.sum() * 0.0
    stack = dx if dx.dim() == 3 else dx.unsqueeze(0)
    return _ConsistencyLoss.apply(stack, x.detach(), reg, delta, grad_through_fit)


def motion_consistency_loss_reference(
    x: Tensor, dx: Tensor, reg: float = DEFAULT_REG, delta: float = DEFAULT_DELTA, grad_through_fit: bool = True
) -> Tensor:
    """:func:`motion_consistency_loss` (same arguments, same value) through autograd on every tensor op: the
    reference its tests compare it with."""
    if x.shape[0] == 0:
        return dx.sum() * 0.0
    x = x.detach()
    omega, nu = fit_twist(x, dx if grad_through_fit else dx.detach(), reg)
    fitted = rigid_displacement(x, omega, nu)
    k = dx.shape[0] if dx.dim() == 3 else 1
    return torch.nn.functional.huber_loss(dx, fitted, reduction="sum", delta=delta) / (x.shape[0] * k)
