"""Latent poses filled within their view from the view's known ones (interpolation: :mod:`eigs.scene.truth`)."""

from __future__ import annotations

import numpy as np

from eigs.scene.truth import interpolate_c2w


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
