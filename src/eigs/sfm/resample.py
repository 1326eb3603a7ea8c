"""Latent poses at another B's latent times, resampled from a finished SfM of the same scene (mode ``resample``).

The latent frames of B bins sit at t₀ + k·T/B (k = 0..B) of each view's exposure T, so every B samples the same
camera path inside the same exposures: one SfM of the scene (at the first configured B) gives the path, and the
latent poses of another B are that path read at their own times. A time the base sampled is its pose exactly
(``registered`` when the base registered it); a time in between is interpolated within the view, translation
linearly and rotation by slerp (:func:`eigs.scene.truth.interpolate_c2w`), never across views; a time outside
the base's samples of that view takes the nearest one (no extrapolation). The base's points and test cameras
stay valid as they are: the frame, the scale and the scene are the same. docs/sfm.md, "One SfM per scene".
"""

from __future__ import annotations

import numpy as np

from eigs.scene.truth import interpolate_c2w


def resample_latent_poses(
    c2w: np.ndarray,
    t_us: np.ndarray,
    valid: np.ndarray,
    registered: np.ndarray,
    t_query: np.ndarray,
    sharp: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses of V views at the latent times ``t_query`` (V, L) from the base's ``c2w`` (V, L₀, 4, 4) at ``t_us``
    (V, L₀), whose ``valid`` (V, L₀) slots hold a pose and ``registered`` (V, L₀) ones came from SfM; ``sharp``
    (V,): views with one image (EDI), whose first slot's pose is copied to every slot, as SfM writes them.

    Returns ``(c2w (V, L, 4, 4), registered (V, L), interpolated (V, L))``: a query at a valid base time copies
    that pose (registered when the base's was, else flagged ``interpolated`` as the base's was), any other is
    interpolated from the view's valid base poses and flagged ``interpolated``; NaN for a view without a valid base
    pose. float64."""
    c2w, t_us, t_query = np.asarray(c2w, np.float64), np.asarray(t_us, np.int64), np.asarray(t_query, np.int64)
    n_views, n_latent = t_query.shape
    if c2w.shape[:2] != t_us.shape or t_us.shape[0] != n_views:
        raise ValueError(f"base poses {c2w.shape[:2]} and times {t_us.shape} do not match {n_views} views")
    out = np.full((n_views, n_latent, 4, 4), np.nan)
    reg = np.zeros((n_views, n_latent), bool)
    interp = np.zeros((n_views, n_latent), bool)
    for v in range(n_views):
        ok = np.flatnonzero(valid[v])
        if ok.size == 0:
            continue
        ok = ok[np.argsort(t_us[v, ok], kind="stable")]
        times, poses = t_us[v, ok], c2w[v, ok]
        keep = np.concatenate([[True], np.diff(times) > 0])  # strictly increasing times for the interpolation
        times, poses, src = times[keep], poses[keep], ok[keep]
        at = np.searchsorted(times, t_query[v])
        hit = (at < times.size) & (times[np.minimum(at, times.size - 1)] == t_query[v])
        out[v, hit] = poses[at[hit]]
        reg[v, hit] = np.asarray(registered[v], bool)[src[at[hit]]]
        interp[v, hit] = ~reg[v, hit]
        if (~hit).any():
            out[v, ~hit] = interpolate_c2w(times, poses, t_query[v, ~hit])
            interp[v, ~hit] = True
        if sharp[v]:  # one image: its pose in every slot, the copies neither registered nor interpolated
            out[v, 1:] = out[v, 0]
            reg[v, 1:] = interp[v, 1:] = False
    return out, reg, interp
