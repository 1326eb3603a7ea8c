"""Latent frames COLMAP registered inconsistently with their own exposure, and their removal.

The B + 1 latent frames of one view are taken within one exposure, so their poses differ only by the
intra-exposure motion. On small, noisy frames incremental mapping occasionally registers one of them from a few
dozen coincidental 2-D–3-D matches at a wildly wrong pose (seen on the built-in scenes: one latent flipped by
173° while its four siblings were right); its points then bend the whole model in bundle adjustment. Such a
frame is treated as not registered: it is removed from the model, the model is re-adjusted, and the frame's
pose is interpolated from its siblings like any other unregistered latent.
"""

from __future__ import annotations

import logging
from collections import defaultdict

import numpy as np

from eigs.metrics.trajectory import project_to_rotation, rotation_angle_deg

log = logging.getLogger(__name__)

MAX_ROTATION_DEG = 10.0  # from the view's median orientation
MAX_CENTRE_FRACTION = 0.5  # of the median distance between neighbouring views' centres
MIN_SIBLINGS = 3  # registered latents a view needs before its median means anything


def sibling_outliers(
    c2w_by_name: dict[str, np.ndarray],
    view_of_name: dict[str, int],
    *,
    max_rotation_deg: float = MAX_ROTATION_DEG,
    max_centre_fraction: float = MAX_CENTRE_FRACTION,
) -> list[str]:
    """Names of registered latent frames whose pose disagrees with their view's other latents.

    ``c2w_by_name``: registered images → (4, 4) camera-to-world; ``view_of_name``: image → training view. Per view
    with ≥ :data:`MIN_SIBLINGS` registered latents: the median orientation (chordal mean) and the coordinate-wise
    median centre; a latent is an outlier when its rotation from that orientation exceeds ``max_rotation_deg`` or
    its centre lies farther than ``max_centre_fraction`` × the median distance between the centres of
    neighbouring views (no centre test with fewer than two such views). Intra-exposure motion is far smaller than
    either bound on any camera that takes distinct views.
    """
    groups: dict[int, list[str]] = defaultdict(list)
    for name in c2w_by_name:
        groups[view_of_name[name]].append(name)
    medians = {}
    for v, names in groups.items():
        if len(names) < MIN_SIBLINGS:
            continue
        poses = np.stack([np.asarray(c2w_by_name[n], np.float64) for n in names])  # (n, 4, 4)
        medians[v] = (project_to_rotation(poses[:, :3, :3].sum(0)), np.median(poses[:, :3, 3], axis=0))
    if not medians:
        return []
    spacing = np.inf
    if len(medians) >= 2:
        centres = np.stack([c for _, c in medians.values()])  # (V', 3)
        d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
        np.fill_diagonal(d, np.inf)
        spacing = float(np.median(d.min(axis=1)))
    out = []
    for v, (r_med, c_med) in medians.items():
        for n in groups[v]:
            t = np.asarray(c2w_by_name[n], np.float64)
            rot = float(rotation_angle_deg(t[None, :3, :3], r_med[None])[0])
            off = float(np.linalg.norm(t[:3, 3] - c_med))
            if rot > max_rotation_deg or off > max_centre_fraction * spacing:
                out.append(n)
    return sorted(out)


def reject_sibling_outliers(
    rec, view_of_name: dict[str, int], *, refine_intrinsics: bool, rounds: int = 2
) -> list[str]:
    """Remove :func:`sibling_outliers` from the pycolmap reconstruction ``rec`` (in place) and bundle-adjust
    the rest (intrinsics fixed unless ``refine_intrinsics``; on ``MAPPER_THREADS`` threads, reproducible);
    repeated up to ``rounds`` times, since a wrong frame can hide a second one. Returns the removed image names."""
    import pycolmap

    from eigs.sfm.colmap import MAPPER_THREADS, c2w_of

    removed: list[str] = []
    for _ in range(rounds):
        by_name = {im.name: im for im in rec.images.values() if im.has_pose}
        bad = sibling_outliers({n: c2w_of(im) for n, im in by_name.items()}, view_of_name)
        if not bad:
            break
        for n in bad:
            rec.deregister_frame(by_name[n].frame_id)
        ba = pycolmap.BundleAdjustmentOptions()
        ba.refine_focal_length = refine_intrinsics
        ba.refine_extra_params = refine_intrinsics
        ba.refine_principal_point = False
        ba.ceres.solver_options.num_threads = MAPPER_THREADS  # default -1: every core, not reproducible
        pycolmap.bundle_adjustment(rec, ba)
        removed += bad
        log.warning("removed %d latent frame(s) registered far from their view's other latents: %s",
                    len(bad), ", ".join(bad))
    return removed
