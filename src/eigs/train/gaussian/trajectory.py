"""Camera trajectories within an exposure, for the trajectory baselines (BAD-Gaussians, BeSplat, EvaGaussians).

A view's camera during its exposure is ``P(u) = P_ref · Δ(u)``, u ∈ [0, 1] the fraction of the exposure, with a
camera-frame delta ``Δ(u) = exp(ξ(u))`` and ``ξ(u)`` a curve in se(3) through K learnable control twists: linear
(K = 2), a uniform cubic B-spline (K = 4) or a Bézier curve (any K ≥ 2). The curve is taken in the Lie algebra of
the delta, the first-order form of BAD-Gaussians' separate translation-lerp / rotation-slerp interpolation and of
the cumulative B-spline; exposure motions are small (a few degrees, a few percent of the scene), where the two agree
to second order in the motion.

The rasterizer has no pose gradients, so a camera at ``P(u)`` is rendered as the camera ``P_ref`` looking at the
Gaussians moved by ``P_ref · Δ(u)⁻¹ · P_ref⁻¹`` (exact for a rigid motion: :mod:`eigs.render.rigid`).

Twists are ``ξ = (ω, ν)``: rotation vector (radians) first, then translation (scene units), 6 numbers.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from eigs.train.gaussian.options import control_problem


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
