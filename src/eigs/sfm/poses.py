"""Pose interpolation in time: linear centres, spherical-linear rotations (camera-to-world, OpenCV axes)."""

from __future__ import annotations

import numpy as np


def interpolate_c2w(t_src: np.ndarray, c2w_src: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Poses at ``t_query`` (Q,) from samples ``t_src`` (N,) strictly increasing, ``c2w_src`` (N, 4, 4).

    Queries outside [t_src[0], t_src[-1]] take the nearest end pose (no extrapolation). N = 1 copies the pose.
    Returns (Q, 4, 4) float64.
    """
    from scipy.spatial.transform import Rotation, Slerp

    t_src = np.asarray(t_src, np.float64)
    c2w_src = np.asarray(c2w_src, np.float64)
    tq = np.clip(np.asarray(t_query, np.float64), t_src[0], t_src[-1])
    out = np.tile(np.eye(4), (tq.shape[0], 1, 1))
    if t_src.shape[0] == 1:
        out[:] = c2w_src[0]
        return out
    for i in range(3):
        out[:, i, 3] = np.interp(tq, t_src, c2w_src[:, i, 3])
    out[:, :3, :3] = Slerp(t_src, Rotation.from_matrix(c2w_src[:, :3, :3]))(tq).as_matrix()
    return out


def fill_within_views(c2w: np.ndarray, known: np.ndarray, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fill unknown latent poses of each view from that view's known ones (never across views).

    ``c2w`` (V, L, 4, 4) with arbitrary values where unknown; ``known`` (V, L) bool; ``t_us`` (V, L) times.
    Returns ``(filled, interpolated)``: poses with the unknown slots interpolated in time (held constant
    beyond the first/last known latent), NaN for views without any known latent; ``interpolated`` (V, L) bool.
    """
    out = np.array(c2w, np.float64, copy=True)
    interp = np.zeros(known.shape, bool)
    for v in range(c2w.shape[0]):
        k_ok = np.flatnonzero(known[v])
        missing = np.flatnonzero(~known[v])
        if missing.size == 0:
            continue
        if k_ok.size == 0:
            out[v, missing] = np.nan
            continue
        out[v, missing] = interpolate_c2w(t_us[v, k_ok], c2w[v, k_ok], t_us[v, missing])
        interp[v, missing] = True
    return out, interp
