"""A tiny NumPy ray caster for SfM tests: a textured ground plane, back walls and two spheres.

Independent of ``eigs.synth``: the surfaces are analytic, so the distance of a triangulated point to the true
geometry is known in closed form (:func:`surface_distance`). Cameras are OpenCV (x right, y down, z forward),
K with pixel centres at (j + 0.5, i + 0.5); the world has z up.
"""

from __future__ import annotations

import numpy as np

SPHERES = [(np.array([0.0, 0.0, 0.6]), 0.6), (np.array([0.9, -0.7, 0.35]), 0.35)]
WALLS = [(np.array([0.0, 1.0, 0.0]), -3.0), (np.array([1.0, 0.0, 0.0]), -3.0)]  # n·x = d planes (y=-3, x=-3)


def _value_noise(u: np.ndarray, v: np.ndarray, seed: int, cell: float) -> np.ndarray:
    """Bilinear value noise: (N,) → (N, 3) in [0, 1]."""
    x, y = u / cell, v / cell
    i, j = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - i, y - j

    def h(a, b):
        return np.stack(
            [
                np.modf(np.abs(np.sin(a * 12.9898 + b * 78.233 + seed * 3.7 + c * 1.618) * 43758.5453))[0]
                for c in range(3)
            ],
            -1,
        )

    fx, fy = fx[:, None], fy[:, None]
    return (
        h(i, j) * (1 - fx) * (1 - fy)
        + h(i + 1, j) * fx * (1 - fy)
        + h(i, j + 1) * (1 - fx) * fy
        + h(i + 1, j + 1) * fx * fy
    )


def texture(u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
    return np.clip(0.6 * _value_noise(u, v, seed, 0.4) + 0.4 * _value_noise(u, v, seed + 7, 0.12), 0, 1)


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Camera-to-world 4×4 (OpenCV axes) at ``eye`` looking at ``target``."""
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, :3] = np.stack([x, y, z], 1)
    m[:3, 3] = eye
    return m


def intrinsics(width: int, height: int, fov_deg: float = 60.0) -> np.ndarray:
    f = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
    return np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1.0]])


def render(c2w: np.ndarray, K: np.ndarray, width: int, height: int) -> np.ndarray:
    """(H, W, 3) uint8 image of the scene."""
    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    pix = np.stack([jj.ravel(), ii.ravel(), np.ones(jj.size)], 1)
    d = pix @ np.linalg.inv(K).T @ c2w[:3, :3].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = c2w[:3, 3]
    n = d.shape[0]
    best = np.full(n, np.inf)
    col = np.full((n, 3), 0.2)
    # ground z = 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -o[2] / d[:, 2]
    p = o + t[:, None] * d
    hit = (t > 1e-6) & (t < best)
    best[hit] = t[hit]
    col[hit] = texture(p[hit, 0], p[hit, 1], 1)
    for k, (nrm, dist) in enumerate(WALLS):
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (dist - nrm @ o) / (d @ nrm)
        p = o + t[:, None] * d
        hit = (t > 1e-6) & (t < best)
        best[hit] = t[hit]
        uv = p[hit][:, [1, 2]] if nrm[0] else p[hit][:, [0, 2]]
        col[hit] = texture(uv[:, 0], uv[:, 1], 10 + k)
    for k, (c, r) in enumerate(SPHERES):
        oc = o - c
        b = d @ oc
        disc = b**2 - (oc @ oc - r * r)
        t = -b - np.sqrt(np.maximum(disc, 0))
        hit = (disc > 0) & (t > 1e-6) & (t < best)
        best[hit] = t[hit]
        q = (o + t[hit, None] * d[hit] - c) / r
        col[hit] = texture(np.arctan2(q[:, 1], q[:, 0]) * r * 2, np.arccos(np.clip(q[:, 2], -1, 1)) * r * 2, 20 + k)
    return (np.clip(col, 0, 1) * 255 + 0.5).astype(np.uint8).reshape(height, width, 3)


def surface_distance(x: np.ndarray) -> np.ndarray:
    """Distance of points (N, 3) to the nearest true surface."""
    d = [np.abs(x[:, 2])]
    d += [np.abs(x @ n - dist) for n, dist in WALLS]
    d += [np.abs(np.linalg.norm(x - c, axis=1) - r) for c, r in SPHERES]
    return np.min(np.stack(d, 1), axis=1)


def orbit(n: int, radius: float = 3.2, height: float = 1.6, arc_deg: float = 100.0, start_deg: float = -10.0):
    """(n, 4, 4) cameras on an arc around the origin looking at (0, 0, 0.4)."""
    out = []
    for a in np.radians(np.linspace(start_deg, start_deg + arc_deg, n)):
        eye = np.array([radius * np.cos(a), radius * np.sin(a), height])
        out.append(look_at(eye, np.array([0.0, 0.0, 0.4])))
    return np.stack(out)
