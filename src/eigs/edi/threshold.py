"""Contrast-threshold estimation for the estimated EDI mode: an energy over c and a bounded 1-D search.

**Energy** (in the spirit of Pan et al.: an edge term rewarding latent frames whose edges sit where the events
are, plus a TV term; definitions in ``docs/edi.md``). For each latent frame k of a view, with ℓ = ln(Y_k + ε) the
log luma of the latent frame for threshold c and r_k the signed event map in a window of one latent interval
centred on t_k (Gaussian-smoothed, σ = 1 px, as are the gradients):

- edge term: R²_k(c), the fraction of r_k explained by a linear regression on ∇ℓ projected on an affine optical
  flow (6 unknowns: brightness constancy ∂ℓ/∂t = −∇ℓ·v with v affine in (x, y)). With the right c the latent
  frame's edges are sharp and exactly where (and with the sign that) the events fire; with c too small they are
  smeared along the path, with c too large they ring with ghosts. R² is invariant to the scale of r, so it
  compares c values fairly.
- TV term: Σ|∇Y_k| / Σ|∇Y_blur| − 1 (isotropic, Sobel), weighted by λ = :data:`TV_WEIGHT`. It costs little where
  the events explain the edges and decides (towards small c, i.e. trusting the events less) where they do not,
  e.g. when most events are sensor noise.

E(c) = mean_k [−R²_k(c)] + λ · mean_k TV_k(c), summed over the views of the scope.

**Search**: :func:`bounded_search` over [0.05, 1.0] in log c: a 13-point log-spaced grid (robust to a non-unimodal
energy), then golden-section refinement inside the bracket of the best grid point to a relative width of 1e-3.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from eigs.edi.edi import LOG_EPS, ExposureIntegral, edi_continuous, edi_discrete, luma

C_MIN, C_MAX = 0.05, 1.0
TV_WEIGHT = 0.01
GRID_POINTS = 13
REL_TOL = 1e-3
SMOOTH_SIGMA = 1.0


@dataclass
class ViewEvidence:
    """What the energy needs of one view.

    ``blurry_linear``: (H, W, C) float64 linear intensity; ``integral``: the exact exposure integral (raw events,
    reference = latent time 0) or None (binned events: the discrete model over ``cum_counts``);
    ``cum_counts``: (L, H, W) event integral from latent time 0 to each latent time (the output frames);
    ``eval_counts``: (K, H, W) event integral from latent time 0 to each time the energy is evaluated at;
    ``rate``: (K, H, W) signed event map in a window around each of those times."""

    blurry_linear: np.ndarray
    integral: ExposureIntegral | None
    cum_counts: np.ndarray
    eval_counts: np.ndarray
    rate: np.ndarray

    def __post_init__(self) -> None:
        self._tv_blur = max(_tv(luma(self.blurry_linear)), 1e-12)
        self._rate_s = np.stack([_smooth(r) for r in self.rate])

    def _frames(self, counts: np.ndarray, c: float) -> np.ndarray:
        if self.integral is not None:
            return edi_continuous(self.blurry_linear, counts, self.integral.log_mean_exp(c), c)
        return edi_discrete(self.blurry_linear, self.cum_counts, c, at=counts)

    def latent(self, c: float) -> np.ndarray:
        """(L, H, W, C) float64 linear latent frames for threshold ``c`` (not clipped)."""
        return self._frames(self.cum_counts, c)

    def energy(self, c: float, tv_weight: float | None = None) -> float:
        """E(c) of this view (module docstring). ``tv_weight``: λ, default :data:`TV_WEIGHT`."""
        tv_weight = TV_WEIGHT if tv_weight is None else tv_weight
        lat = np.clip(luma(self._frames(self.eval_counts, c)), 0.0, 1.0)
        e = 0.0
        for k in range(lat.shape[0]):
            e -= _flow_r2(self._rate_s[k], np.log(lat[k] + LOG_EPS))
            e += tv_weight * (_tv(lat[k]) / self._tv_blur - 1.0)
        return e / lat.shape[0]


def _smooth(a: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.GaussianBlur(np.asarray(a, np.float64), (0, 0), SMOOTH_SIGMA)


def _grad(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    a = np.asarray(a, np.float64)
    return cv2.Sobel(a, cv2.CV_64F, 1, 0, ksize=3) / 8.0, cv2.Sobel(a, cv2.CV_64F, 0, 1, ksize=3) / 8.0


def _tv(img: np.ndarray) -> float:
    gx, gy = _grad(img)
    return float(np.sqrt(gx * gx + gy * gy).sum())


@lru_cache(maxsize=8)
def _coords(h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    return (xx - w / 2) / max(w, h), (yy - h / 2) / max(w, h)


def _flow_r2(rate_s: np.ndarray, ell: np.ndarray) -> float:
    """R² of the least-squares fit rate ≈ ∇ℓ · v(x, y), v affine (6 unknowns). 0 when there is nothing to fit."""
    h, w = ell.shape
    gx, gy = _grad(ell)
    gx, gy = _smooth(gx), _smooth(gy)
    xx, yy = _coords(h, w)
    f = np.empty((6, h * w), np.float64)
    f[0], f[1] = gx.reshape(-1), gy.reshape(-1)
    f[2], f[3] = f[0] * xx.reshape(-1), f[0] * yy.reshape(-1)
    f[4], f[5] = f[1] * xx.reshape(-1), f[1] * yy.reshape(-1)
    b = rate_s.reshape(-1)
    bb = float(b @ b)
    if bb <= 0:
        return 0.0
    ata = f @ f.T
    atb = f @ b
    scale = np.sqrt(np.maximum(np.diag(ata), 1e-300))
    sol, *_ = np.linalg.lstsq(ata / np.outer(scale, scale), atb / scale, rcond=1e-12)
    r2 = float(sol @ (atb / scale)) / bb  # = bᵀA(AᵀA)⁻¹Aᵀb / bᵀb
    return float(np.clip(r2, 0.0, 1.0)) if math.isfinite(r2) else 0.0


def bounded_search(
    energy: Callable[[float], float],
    lo: float = C_MIN,
    hi: float = C_MAX,
    grid: int = GRID_POINTS,
    rel_tol: float = REL_TOL,
) -> tuple[float, float]:
    """Minimise ``energy`` over [lo, hi] (0 < lo < hi) in log space; returns (c, energy(c)).

    A log-spaced grid of ``grid`` points finds the best bracket; golden-section search refines it until the bracket's
    relative width is below ``rel_tol``. Non-finite energies count as +inf.
    """
    if not 0 < lo < hi:
        raise ValueError(f"need 0 < lo < hi, got [{lo}, {hi}]")
    cache: dict[float, float] = {}

    def f(u: float) -> float:
        if u not in cache:
            v = float(energy(math.exp(u)))
            cache[u] = v if math.isfinite(v) else math.inf
        return cache[u]

    us = np.linspace(math.log(lo), math.log(hi), max(grid, 3))
    vals = [f(float(u)) for u in us]
    i = int(np.argmin(vals))
    a, b = float(us[max(i - 1, 0)]), float(us[min(i + 1, len(us) - 1)])
    g = (math.sqrt(5) - 1) / 2
    x1, x2 = b - g * (b - a), a + g * (b - a)
    while b - a > rel_tol:
        if f(x1) <= f(x2):
            b, x2 = x2, x1
            x1 = b - g * (b - a)
        else:
            a, x1 = x1, x2
            x2 = a + g * (b - a)
    best = min(cache, key=lambda u: cache[u])
    return math.exp(best), cache[best]
