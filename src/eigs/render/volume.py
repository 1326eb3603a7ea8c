"""Volume rendering of radiance fields along rays: ray–box intersection and the standard alpha-compositing
quadrature (NeRF Eq. 3), vectorised over a batch of rays with a fixed number of samples each.

Contract (shared with the float64 one-ray reference :func:`eigs.render.volume_reference.composite_ray`):

- sample i of a ray has density σ_i ≥ 0 (1 / world unit), colour c_i (C,) and interval length δ_i ≥ 0 (world
  units; the ray direction has unit length, so t is a distance);
- optical depth τ_i = min(σ_i δ_i, ``TAU_MAX``); α_i = 1 − exp(−τ_i); transmittance T_i = exp(−Σ_{j<i} τ_j);
  weight w_i = T_i α_i; colour Σ_i w_i c_i + T_S · background with T_S = exp(−Σ_j τ_j); opacity Σ_i w_i = 1 − T_S.

A NaN density counts as 0 and an infinite one as saturated (``TAU_MAX``): empty rays, rays that miss the grid and
saturated density give finite colours and gradients.
"""

from __future__ import annotations

import torch
from torch import Tensor

TAU_MAX = 30.0  # optical depth of one sample is clamped here: exp(−30) ≈ 1e-13, opaque at float32 precision
SIGMA_INF = 1e30  # an infinite density is replaced by this (saturates τ at any δ > 3e-29)
DIR_EPS = 1e-9  # direction components below this are treated as parallel to a slab


def ray_aabb(origins: Tensor, dirs: Tensor, lo: Tensor, hi: Tensor, near: float) -> tuple[Tensor, Tensor]:
    """Entry and exit distances of rays through the axis-aligned box [lo, hi] (slab method).

    ``origins``, ``dirs``: (R, 3) (dirs of unit length); ``lo``, ``hi``: (3,). Returns ``t_near``, ``t_far`` (R,)
    with ``t_near ≥ near``; a ray that misses the box (or leaves it before ``near``) has ``t_far ≤ t_near``."""
    safe = torch.where(dirs.abs() < DIR_EPS, torch.full_like(dirs, DIR_EPS), dirs)
    inv = 1.0 / safe
    t0 = (lo - origins) * inv
    t1 = (hi - origins) * inv
    t_near = torch.minimum(t0, t1).amax(dim=-1).clamp_min(near)
    t_far = torch.maximum(t0, t1).amin(dim=-1)
    return t_near, torch.maximum(t_far, t_near)


def composite(sigmas: Tensor, colours: Tensor, deltas: Tensor, background: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Alpha-composite R rays of S samples front to back.

    ``sigmas`` (R, S) densities, ``colours`` (R, S, C), ``deltas`` (R, S) interval lengths, ``background`` (C,).
    Returns the colours (R, C), the opacities (R,) and the weights (R, S). Differentiable in every input."""
    sig = torch.nan_to_num(sigmas, nan=0.0, posinf=SIGMA_INF, neginf=0.0).clamp_min(0.0)
    tau = (sig * deltas).clamp(0.0, TAU_MAX)
    csum = torch.cumsum(tau, dim=-1)
    excl = torch.cat([torch.zeros_like(csum[:, :1]), csum[:, :-1]], dim=-1)  # Σ_{j<i} τ_j, no inf − inf
    trans = torch.exp(-excl)
    alpha = -torch.expm1(-tau)
    weights = trans * alpha
    rgb = (weights.unsqueeze(-1) * colours).sum(dim=1)
    t_end = torch.exp(-csum[:, -1]) if csum.shape[1] else torch.ones_like(csum[:, 0])
    rgb = rgb + t_end.unsqueeze(-1) * background
    return rgb, 1.0 - t_end, weights


def distortion(weights: Tensor, s: Tensor, ds: Tensor) -> Tensor:
    """Mip-NeRF 360's distortion loss of R rays (Barron et al. 2022, Eq. 15), per ray (R,):
    Σ_i Σ_j w_i w_j |s_i − s_j| + ⅓ Σ_i w_i² Δs_i, for ``weights`` (R, S), sample positions ``s`` (R, S) ascending
    along each ray (any unit, e.g. the fraction of the ray's stretch) and interval lengths ``ds`` (R, S) in the same
    unit. Computed in O(S) with cumulative sums (2 Σ_i w_i (s_i Σ_{j<i} w_j − Σ_{j<i} w_j s_j)); samples with zero
    weight (padding) contribute nothing. Small when each ray's weight sits in one short stretch (a surface), large
    for weight spread along the ray (fog, floaters)."""
    ws = weights * s
    w_before = torch.cumsum(weights, dim=-1) - weights
    ws_before = torch.cumsum(ws, dim=-1) - ws
    cross = 2.0 * (weights * (s * w_before - ws_before)).sum(dim=-1)
    return cross + (weights * weights * ds).sum(dim=-1) / 3.0
