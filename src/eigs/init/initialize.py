"""Initial Gaussians from the SfM points (the reference 3DGS initialization).

Position = point; colour → SH DC; scale = mean distance to the 3 nearest neighbours (log stored); identity
rotation; opacity 0.1 (logit stored). With fewer than ``min_points`` points, random Gaussians uniform in the
scene bounds are added (and the result says so).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from eigs.artifacts.gaussians import GaussianCloud, logit, rgb_to_sh_dc
from eigs.init.options import InitOptions

log = logging.getLogger(__name__)

INIT_OPACITY = 0.1
MIN_SCALE = 1e-7  # floor for the nearest-neighbour distance before the log (duplicate points)


def knn_mean_distance(points: np.ndarray, k: int = 3) -> np.ndarray:
    """Mean distance of each of the (N, 3) points to its ``k`` nearest other points; (N,). N = 1: 1.0·MIN."""
    from scipy.spatial import cKDTree

    p = np.asarray(points, np.float64)
    n = p.shape[0]
    if n < 2:
        return np.full(n, MIN_SCALE)
    kk = min(k, n - 1)
    d, _ = cKDTree(p).query(p, k=kk + 1)
    return np.asarray(d, np.float64).reshape(n, kk + 1)[:, 1:].mean(axis=1)


def gaussians_from_points(
    xyz: np.ndarray, rgb: np.ndarray, *, sh_degree: int = 3, opacity: float = INIT_OPACITY
) -> GaussianCloud:
    """``xyz`` (N, 3) world units; ``rgb`` (N, 3) in [0, 1] (a single channel is repeated)."""
    xyz = np.asarray(xyz, np.float64)
    rgb = np.asarray(rgb, np.float64)
    if rgb.ndim == 2 and rgb.shape[1] == 1:
        rgb = np.repeat(rgb, 3, axis=1)
    n = xyz.shape[0]
    dist = np.maximum(knn_mean_distance(xyz), MIN_SCALE)
    quats = np.zeros((n, 4))
    quats[:, 0] = 1.0
    k = (sh_degree + 1) ** 2 - 1
    return GaussianCloud(
        means=xyz.astype(np.float32),
        f_dc=rgb_to_sh_dc(rgb).astype(np.float32),
        f_rest=np.zeros((n, 3, k), np.float32),
        opacity=np.full(n, float(logit(opacity)), np.float32),
        log_scales=np.repeat(np.log(dist)[:, None], 3, axis=1).astype(np.float32),
        quats=quats.astype(np.float32),
    )


@dataclass
class InitResult:
    cloud: GaussianCloud
    n_sfm: int  # Gaussians from SfM points
    n_random: int  # Gaussians added at random
    bounds: tuple[list[float], list[float]]  # (lo, hi) of the random box


def random_points(n: int, lo: np.ndarray, hi: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` points uniform in the box [lo, hi] with random colours: (n, 3), (n, 3)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, size=(n, 3)), rng.uniform(0.0, 1.0, size=(n, 3))


def scene_bounds(points: np.ndarray, cameras: np.ndarray, min_points: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Box for random Gaussians: the 1–99 % range of the points, expanded by 10 %, when there are at least
    ``min_points`` of them; else the camera centres' box (cameras: (M, 3)), at least [−1, 1]³ in the canonical frame."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    if pts.shape[0] >= min_points:
        lo, hi = np.percentile(pts, 1, axis=0), np.percentile(pts, 99, axis=0)
    else:
        cams = np.asarray(cameras, np.float64).reshape(-1, 3)
        cams = cams[np.all(np.isfinite(cams), axis=1)]
        lo = np.minimum(cams.min(0), -1.0) if cams.size else -np.ones(3)
        hi = np.maximum(cams.max(0), 1.0) if cams.size else np.ones(3)
    pad = 0.1 * np.maximum(hi - lo, 1e-3)
    return lo - pad, hi + pad


def initialize(
    xyz: np.ndarray,
    rgb: np.ndarray,
    camera_centres: np.ndarray,
    *,
    min_points: int = InitOptions.min_points,
    n_random: int = InitOptions.random,
    sh_degree: int = InitOptions.sh_degree,
    seed: int = InitOptions.seed,
) -> InitResult:
    """Gaussians from SfM points ``xyz`` (N, 3) / ``rgb`` (N, 3) in [0, 1]; when N < ``min_points``, add
    ``n_random`` random Gaussians inside :func:`scene_bounds` (``camera_centres`` (M, 3) bound them when the
    points are too few even for a box)."""
    xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
    rgb = np.asarray(rgb, np.float64).reshape(xyz.shape[0], -1)
    lo, hi = scene_bounds(xyz, camera_centres)
    n_add = 0
    if xyz.shape[0] < min_points:
        n_add = int(n_random)
        log.warning(
            "only %d SfM points (< %d): adding %d random Gaussians in the box %s – %s",
            xyz.shape[0],
            min_points,
            n_add,
            np.round(lo, 3).tolist(),
            np.round(hi, 3).tolist(),
        )
        rx, rc = random_points(n_add, lo, hi, seed)
        if rgb.shape[1] == 1:
            rgb = np.repeat(rgb, 3, axis=1)
        xyz = np.concatenate([xyz, rx])
        rgb = np.concatenate([rgb.reshape(-1, 3), rc])
    cloud = gaussians_from_points(xyz, rgb, sh_degree=sh_degree)
    return InitResult(cloud, xyz.shape[0] - n_add, n_add, (lo.tolist(), hi.tolist()))
