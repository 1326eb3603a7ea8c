"""The test cameras of the SfM stage (``test_cameras.h5``): every ground-truth sharp image placed in the model's
canonical frame, by the given poses, by registration into the COLMAP model, or mapped from the ground truth; with
the registration summary of report.json ``test_cameras``. docs/sfm.md."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from eigs.errors import EigsError

if TYPE_CHECKING:
    from eigs.artifacts.poses import TestCameras
    from eigs.metrics.trajectory import Sim3
    from eigs.scene.model import Scene
    from eigs.sfm.options import ColmapOptions, SfmConfig

log = logging.getLogger(__name__)


def place_test_cameras(
    scene: Scene,
    rec,
    db: Path | None,
    work: Path,
    mode: str,
    canon: Sim3,
    est_to_gt: Sim3 | None,
    cfg: SfmConfig,
    opts: ColmapOptions,
) -> tuple[TestCameras, dict]:
    """Cameras of every ground-truth sharp image in the model (canonical) frame and their summary (report.json
    ``test_cameras``): given mode maps the ground truth by the canonical transform; otherwise each image is registered
    into ``rec`` (pycolmap model, database ``db``) when ``cfg.register_test_cameras``, and the rest mapped from the
    ground truth by ``est_to_gt``⁻¹ (or by the registered ones' alignment)."""
    from eigs.artifacts.poses import METHOD_FALLBACK, METHOD_GIVEN, METHOD_REGISTERED, METHODS, TestCameras
    from eigs.metrics.trajectory import trajectory_accuracy, umeyama

    sh = scene.sharp
    cam = scene.camera
    S = len(sh.t_us)
    method = np.full(S, METHOD_FALLBACK, np.uint8)
    err = np.full(S, np.nan)
    n_in = np.zeros(S, np.int64)
    # ground truth → model frame: (canonical est → gt)⁻¹ in COLMAP mode, the canonical transform in given mode
    gt_to_model = canon if mode == "given" else (None if est_to_gt is None else est_to_gt.inverse())
    guesses = gt_to_model.apply_c2w(sh.c2w) if gt_to_model is not None else np.full((S, 4, 4), np.nan)
    c2w = guesses.copy()
    summary: dict = {"count": S}
    if mode == "given":
        method[:] = METHOD_GIVEN
    elif cfg.register_test_cameras:
        from eigs.util.image import write_png

        tdir = work / "test"
        tdir.mkdir()
        tnames = [f"test_{i:04d}.png" for i in range(S)]
        for i, n in enumerate(tnames):
            write_png(tdir / n, sh.images[i])
        from eigs.sfm.register import register_images

        regs = register_images(
            rec, db, tdir, tnames, cam.K, cam.width, cam.height, cam.distortion, list(guesses), work, opts
        )
        for i, r in enumerate(regs):
            n_in[i] = r.num_inliers
            err[i] = r.reproj_px
            if r.c2w is not None:
                c2w[i] = r.c2w
                method[i] = METHOD_REGISTERED
        ok = method == METHOD_REGISTERED
        if gt_to_model is None and ok.sum() >= 3:  # no latent ground truth: align with the registered ones
            gt_to_model = umeyama(sh.c2w[ok][:, :3, 3], c2w[ok][:, :3, 3])
            c2w[~ok] = gt_to_model.apply_c2w(sh.c2w[~ok])
        if ok.any():
            fin = err[ok]
            summary["reprojection_error_px_median"] = float(np.median(fin))
            summary["reprojection_error_px_max"] = float(np.max(fin))
            summary["inliers_median"] = float(np.median(n_in[ok]))
        if gt_to_model is not None and ok.sum() >= 1:
            ref = gt_to_model.apply_c2w(sh.c2w[ok])
            acc = trajectory_accuracy(c2w[ok], ref) if ok.sum() >= 3 else None
            d = np.linalg.norm(c2w[ok][:, :3, 3] - ref[:, :3, 3], axis=1)
            summary["registered_vs_mapped_ground_truth"] = {
                "centre_distance_median_canonical": float(np.median(d)),
                "rotation_deg_median": float(np.median(acc.rotation_errors_deg)) if acc else None,
            }
    if gt_to_model is None and np.any(method == METHOD_FALLBACK):
        raise EigsError(
            None,
            f"{int(np.sum(method == METHOD_FALLBACK))} test camera(s) could not be registered and there is no "
            "ground truth to place them (no latent ground-truth poses, fewer than 3 registered test images)",
        )
    summary.update({v: int(np.sum(method == k)) for k, v in METHODS.items()})
    log.info(
        "test cameras: %s",
        ", ".join(f"{summary[v]} {v}" for v in METHODS.values() if summary[v]),
    )
    tc = TestCameras(
        c2w=c2w,
        K=np.tile(np.asarray(cam.K, np.float64), (S, 1, 1)),
        width=cam.width,
        height=cam.height,
        index=np.arange(S, dtype=np.int64),
        kind=np.asarray(sh.kind, np.uint8),
        view=np.asarray(sh.view, np.int64),
        t_us=np.asarray(sh.t_us, np.int64),
        method=method,
        reprojection_error_px=err,
        num_inliers=n_in,
    )
    return tc, summary
