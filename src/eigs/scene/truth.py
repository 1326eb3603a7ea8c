"""A scene's ground-truth camera poses at given times: what SfM is scored against and what evaluation compares a
method's motion with. Interpolation in time: linear centres, spherical-linear rotations (camera-to-world, OpenCV
axes)."""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger(__name__)


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



def latent_poses_at(
    scene, timestamps_us: np.ndarray, *, ground_truth_only: bool = True, clamp: bool = False
) -> tuple[np.ndarray, str] | None:
    """Scene poses at the latent times ``timestamps_us`` (V, L): ``(c2w (V, L, 4, 4), source)`` or None.

    Sources in order: the scene's latent poses (``ground-truth`` source, or any source when
    ``ground_truth_only`` is False), exact when their times equal ``timestamps_us`` and interpolated within
    each view otherwise; then the dense ground-truth trajectory. ``source`` names what was used. Latent times
    outside the trajectory get its end poses with ``clamp``, else NaN (no ground truth there).
    """
    ts = np.asarray(timestamps_us, np.int64)
    p = scene.poses
    if p is not None and (p.source == "ground-truth" or not ground_truth_only):
        if p.latent_c2w.shape[0] != ts.shape[0]:
            log.warning(
                "scene has latent poses for %d views but EDI has %d: ignoring them", p.latent_c2w.shape[0], ts.shape[0]
            )
        elif p.latent_t_us.shape == ts.shape and np.array_equal(p.latent_t_us, ts):
            return np.array(p.latent_c2w, np.float64), f"scene poses ({p.source})"
        else:
            out = np.stack([interpolate_c2w(p.latent_t_us[v], p.latent_c2w[v], ts[v]) for v in range(ts.shape[0])])
            return out, f"scene poses ({p.source}), interpolated to the latent times"
    tr = scene.trajectory
    if tr is not None and tr.t_us.shape[0] >= 1:
        lo, hi = int(tr.t_us[0]), int(tr.t_us[-1])
        outside = int(np.count_nonzero((ts < lo) | (ts > hi)))
        if outside:
            what = "its end poses are used" if clamp else "they have no ground truth"
            log.warning("%d latent times lie outside the ground-truth trajectory: %s", outside, what)
        out = interpolate_c2w(tr.t_us, tr.c2w, ts.ravel()).reshape(*ts.shape, 4, 4)
        if not clamp:
            out[(ts < lo) | (ts > hi)] = np.nan
        return out, "ground-truth trajectory, interpolated to the latent times"
    return None
