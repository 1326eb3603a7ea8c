"""Known-pose mode: the scene's latent poses are kept exactly; COLMAP only triangulates points.

Also the ground truth every mode is scored against: latent poses at the EDI latent times, from the scene's
ground-truth latent poses (exact when the times agree, else interpolated within each view) or its dense
ground-truth trajectory.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.sfm.poses import interpolate_c2w

log = logging.getLogger(__name__)


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


def triangulate(
    db_path: Path,
    image_dir: Path,
    out_dir: Path,
    name_to_id: dict[str, int],
    c2w: dict[str, np.ndarray],
    K: np.ndarray,
    width: int,
    height: int,
    distortion: np.ndarray | None,
    *,
    num_threads: int = 2,
    px: float = 1.0,
):
    """Triangulate the matched features with every pose fixed (``c2w``: image name → camera-to-world).

    Image and camera ids equal the database's. Returns the pycolmap.Reconstruction (poses unchanged).
    """
    import pycolmap

    from eigs.sfm.colmap import apply_thresholds, make_camera, rigid_from_c2w

    db = pycolmap.Database.open(db_path)
    try:
        cams = db.read_all_cameras()
    finally:
        db.close()
    if len(cams) != 1:
        raise EigsError(db_path, f"expected one shared camera in the database, found {len(cams)}")
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(make_camera(K, width, height, distortion, camera_id=cams[0].camera_id))
    for name, image_id in sorted(name_to_id.items(), key=lambda kv: kv[1]):
        img = pycolmap.Image(name=name, camera_id=cams[0].camera_id, image_id=image_id)
        rec.add_image_with_trivial_frame(img, rigid_from_c2w(c2w[name]))
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = num_threads
    apply_thresholds(opts, px)
    out_dir.mkdir(parents=True, exist_ok=True)
    return pycolmap.triangulate_points(
        rec, db_path, image_dir, out_dir, clear_points=True, options=opts, refine_intrinsics=False
    )
