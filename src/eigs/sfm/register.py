"""Test cameras: register each ground-truth sharp image into the frozen model.

The model is never changed: a copy of the database receives the test images' features, each test image is
matched against nearby registered model images, its keypoints inherit the 3-D points of their matches, and an
absolute pose is estimated (LO-RANSAC + refinement, intrinsics fixed). When that fails (too few inliers, large
reprojection error), the ground-truth pose mapped into the model frame by the Sim(3) is the fallback.
"""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.sfm.colmap import (
    ColmapOptions,
    c2w_of,
    device,
    extract,
    pixel_scale,
    verification_options,
    verification_seed,
)

log = logging.getLogger(__name__)

MIN_INLIERS = 20
MAX_REPROJ_PX = 2.0
NEIGHBOURS = 12  # model images matched per test image


@dataclass
class Registration:
    """Per test image: ``c2w`` (4, 4) in the model frame or None, ``reproj_px`` mean inlier reprojection error,
    ``num_inliers``, ``num_matches`` (2-D–3-D correspondences tried)."""

    c2w: np.ndarray | None
    reproj_px: float
    num_inliers: int
    num_matches: int


def _neighbours(rec, guess_c2w: np.ndarray | None, n: int) -> list[int]:
    """Registered model image ids closest to ``guess_c2w`` (centre distance, penalising viewing-angle change);
    all of them (up to 4n, evenly spread) without a guess."""
    ids = sorted(rec.reg_image_ids())
    if guess_c2w is None or not np.all(np.isfinite(guess_c2w)):
        step = max(1, len(ids) // (4 * n))
        return ids[::step]
    cs = np.stack([c2w_of(rec.images[i]) for i in ids])
    d = np.linalg.norm(cs[:, :3, 3] - guess_c2w[:3, 3], axis=1)
    cos = np.einsum("ni,i->n", cs[:, :3, 2], guess_c2w[:3, 2])
    scale = float(np.median(np.linalg.norm(cs[:, :3, 3] - cs[:, :3, 3].mean(0), axis=1))) or 1.0
    score = d / scale + (1.0 - cos)
    return [ids[i] for i in np.argsort(score)[:n]]


def register_images(
    rec,
    db_path: Path,
    test_dir: Path,
    test_names: list[str],
    K: np.ndarray,
    width: int,
    height: int,
    distortion: np.ndarray | None,
    guesses: list[np.ndarray | None],
    work_dir: Path,
    opts: ColmapOptions,
    *,
    min_inliers: int = MIN_INLIERS,
    max_reproj_px: float = MAX_REPROJ_PX,
) -> list[Registration]:
    """Register ``test_names`` (PNGs in ``test_dir``) into ``rec`` (a pycolmap.Reconstruction whose image ids
    are those of ``db_path``). ``guesses``: approximate c2w per test image in the model frame (to choose the
    model images to match against), or None. The reconstruction and the original database stay unchanged."""
    import pycolmap

    reg_db = work_dir / "register.db"
    shutil.copyfile(db_path, reg_db)
    cam_id = next(iter(rec.cameras))
    ids = extract(reg_db, test_dir, test_names, K, width, height, distortion, work_dir, opts)
    pairs_file = work_dir / "register_pairs.txt"
    lines = []
    neighbours: dict[str, list[int]] = {}
    for name, guess in zip(test_names, guesses, strict=True):
        neighbours[name] = _neighbours(rec, guess, NEIGHBOURS)
        lines += [f"{name} {rec.images[i].name}" for i in neighbours[name]]
    pairs_file.write_text("\n".join(lines) + "\n")
    m = pycolmap.FeatureMatchingOptions()
    m.num_threads = opts.num_threads
    pairing = pycolmap.ImportedPairingOptions()
    pairing.match_list_path = str(pairs_file)
    px = pixel_scale(opts, width, height)
    pycolmap.match_image_pairs(
        reg_db,
        matching_options=m,
        pairing_options=pairing,
        verification_options=verification_options(px, verification_seed(opts)),
        device=device(opts.device),
    )

    camera = rec.cameras[cam_id]
    est = pycolmap.AbsolutePoseEstimationOptions()
    est.ransac.max_error = 4.0 * px
    est.ransac.random_seed = opts.seed
    ref = pycolmap.AbsolutePoseRefinementOptions()
    ref.refine_focal_length = False
    ref.refine_extra_params = False
    db = pycolmap.Database.open(reg_db)
    out: list[Registration] = []
    try:
        for name in test_names:
            tid = ids[name]
            kp = np.asarray(db.read_keypoints(tid), np.float64)[:, :2]
            corr: dict[tuple[int, int], None] = {}
            for mid in neighbours[name]:
                if not db.exists_two_view_geometry(tid, mid):
                    continue
                tvg = db.read_two_view_geometry(tid, mid)
                matches = np.asarray(tvg.inlier_matches)
                if matches.size == 0:
                    continue
                image = rec.images[mid]
                for i_test, i_model in matches:
                    p2 = image.points2D[int(i_model)]
                    if p2.has_point3D():
                        corr[(int(i_test), int(p2.point3D_id))] = None
            if len(corr) < max(4, min_inliers):
                out.append(Registration(None, float("nan"), 0, len(corr)))
                continue
            ij = np.array(list(corr), np.int64)
            p2d = kp[ij[:, 0]]
            p3d = np.stack([rec.points3D[int(p)].xyz for p in ij[:, 1]])
            res = pycolmap.estimate_and_refine_absolute_pose(p2d, p3d, camera, est, ref)
            if res is None:
                out.append(Registration(None, float("nan"), 0, len(corr)))
                continue
            pose = res["cam_from_world"]
            inl = np.asarray(res["inlier_mask"], bool)
            proj = camera.img_from_cam((p3d[inl] @ pose.rotation.matrix().T) + pose.translation)
            err = float(np.mean(np.linalg.norm(np.asarray(proj) - p2d[inl], axis=1))) if inl.any() else float("nan")
            n_in = int(inl.sum())
            ok = n_in >= min_inliers and np.isfinite(err) and err <= max_reproj_px
            c2w = np.linalg.inv(np.vstack([pose.matrix(), [0, 0, 0, 1]])) if ok else None
            out.append(Registration(c2w, err, n_in, len(corr)))
    finally:
        db.close()
    return out
