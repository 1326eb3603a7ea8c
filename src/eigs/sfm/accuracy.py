"""Accuracy of the SfM stage's latent poses against the scene's ground truth (report.json ``accuracy``): the Sim(3)
of the estimate onto the ground truth, ATE, rotation errors and the relative latent errors. docs/sfm.md."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from eigs.artifacts.edi import EdiResult
    from eigs.metrics.trajectory import Sim3
    from eigs.scene.model import Scene

log = logging.getLogger(__name__)

MIN_MATCHED = 3  # latents with ground truth needed for the Sim(3) alignment


def ground_truth_accuracy(
    scene: Scene, edi: EdiResult, c2w: np.ndarray, registered: np.ndarray, report: dict
) -> tuple[tuple[np.ndarray, Any] | None, Sim3 | None]:
    """Accuracy of the estimated latent poses against the scene's ground truth, when it has some:
    (ground truth ((V, L, 4, 4) poses, description) or None, Sim(3) canonical estimate → ground truth or None).
    ``c2w``: (V, L, 4, 4) canonical latent poses; ``registered``: (V, L). Fills ``report["accuracy"]``."""
    from eigs.scene.truth import latent_poses_at

    gt = latent_poses_at(scene, edi.timestamps_us)
    if gt is None:
        return None, None
    estimated = registered.copy()
    estimated[np.asarray(edi.sharp, bool), 1:] = False  # copied slots of sharp views are no estimates
    estimated &= np.all(np.isfinite(gt[0]), axis=(-2, -1))  # latents with ground truth
    n_matched = int(np.count_nonzero(estimated))
    if n_matched < MIN_MATCHED:
        what = "no registered latent pose has" if n_matched == 0 else f"only {n_matched} registered latent poses have"
        note = (
            f"{what} ground truth at its time ({MIN_MATCHED} needed for a Sim(3)): the latent times (EDI "
            "timestamps_us, from the frames' exposure windows or timestamps) lie outside the ground truth, or the "
            "frames have no times"
        )
        log.warning("accuracy not computed: %s", note)
        report["accuracy"] = {"n": n_matched, "ate_rmse": None, "note": note, "ground_truth": gt[1]}
        return None, None
    est_to_gt, report["accuracy"] = accuracy(c2w, estimated, gt[0], edi.sharp)
    report["accuracy"]["ground_truth"] = gt[1]
    a = report["accuracy"]
    log.info(
        "accuracy: ATE %.4g (%.3f %% of extent %.4g), rotation error median %.3f°",
        a["ate_rmse"],
        a["ate_percent_of_extent"],
        a["extent"],
        a["rotation_error_deg_median"],
    )
    return gt, est_to_gt


def accuracy(c2w: np.ndarray, registered: np.ndarray, gt: np.ndarray, sharp: np.ndarray) -> tuple[Sim3, dict]:
    """Sim(3) of registered latents onto ground truth, ATE, rotation errors, relative latent errors."""
    from eigs.metrics.trajectory import extent, latent_relative_errors, motion_ratio_per_view, trajectory_accuracy

    g = gt.reshape(-1, 4, 4)
    ext = extent(g[np.all(np.isfinite(g), axis=(1, 2))][:, :3, 3])
    acc = trajectory_accuracy(c2w[registered], gt[registered], gt_extent=ext)
    out = acc.summary()

    def eye_if_nan(a):
        return np.where(np.all(np.isfinite(a), axis=(-2, -1))[..., None, None], a, np.eye(4))

    rel = latent_relative_errors(eye_if_nan(c2w), eye_if_nan(gt), acc.sim.scale, valid=registered)
    moving = ~np.asarray(sharp, bool)
    tr = motion_ratio_per_view(rel["t_err"][moving], rel["t_motion"][moving], 1e-6 * max(ext, 1e-12))
    rr = motion_ratio_per_view(rel["r_err_deg"][moving], rel["r_motion_deg"][moving], 1e-4)

    def med(a):
        a = np.asarray(a, float)
        a = a[np.isfinite(a)]
        return float(np.median(a)) if a.size else float("nan")

    out["relative_latent"] = {
        "definition": "per view: median over k>=1 of the error of T0^-1 Tk against ground truth, divided by the "
        "view's true intra-exposure motion (largest true |T0^-1 Tk|); then the median over views",
        "views_compared": int(np.isfinite(tr).sum()),
        "translation_ratio_median": med(tr),
        "rotation_ratio_median": med(rr),
        "translation_ratio_per_view": [None if not np.isfinite(x) else float(x) for x in tr],
        "rotation_ratio_per_view": [None if not np.isfinite(x) else float(x) for x in rr],
        "translation_error_median": med(rel["t_err"][moving][:, 1:]),
        "rotation_error_deg_median": med(rel["r_err_deg"][moving][:, 1:]),
        "true_translation_motion_median": med(rel["t_motion"][moving].max(axis=1)) if moving.any() else None,
        "true_rotation_motion_deg_median": med(rel["r_motion_deg"][moving].max(axis=1)) if moving.any() else None,
    }
    return acc.sim, out
