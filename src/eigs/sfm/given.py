"""Known-pose mode: the scene's latent poses are kept exactly; COLMAP only triangulates points. (The ground truth
every mode is scored against comes from :func:`eigs.scene.truth.latent_poses_at`.)"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from eigs.errors import EigsError

log = logging.getLogger(__name__)

GUIDED_NEIGHBOURS = 24  # images of other views matched per image in given mode
GUIDED_RATIO = 0.8  # Lowe ratio among the candidates inside the epipolar band
GUIDED_MIN_MATCHES = 8


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


def _skew(t: np.ndarray) -> np.ndarray:
    return np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])


def _pair_candidates(c2w: dict[int, np.ndarray], view_of: dict[int, int], neighbours: int) -> set[tuple[int, int]]:
    """Image pairs to match: every pair inside a view, plus each image's ``neighbours`` closest images of other
    views (centre distance in units of the median spread plus 1 − cos of the viewing-direction angle, front-facing
    only)."""
    ids = sorted(c2w)
    cs = np.stack([c2w[i][:3, 3] for i in ids])
    zs = np.stack([c2w[i][:3, 2] for i in ids])
    spread = float(np.median(np.linalg.norm(cs - cs.mean(0), axis=1))) or 1.0
    pairs: set[tuple[int, int]] = set()
    for a, ia in enumerate(ids):
        score = np.linalg.norm(cs - cs[a], axis=1) / spread + (1.0 - zs @ zs[a])
        other = [b for b in np.argsort(score) if view_of[ids[b]] != view_of[ia] and zs[b] @ zs[a] > 0.0]
        for b in other[:neighbours]:
            pairs.add((min(ia, ids[b]), max(ia, ids[b])))
        for b, ib in enumerate(ids):
            if b != a and view_of[ib] == view_of[ia]:
                pairs.add((min(ia, ib), max(ia, ib)))
    return pairs


def guided_match(
    db_path: Path,
    c2w: dict[int, np.ndarray],
    view_of: dict[int, int],
    *,
    max_epipolar_px: float = 4.0,
    neighbours: int = GUIDED_NEIGHBOURS,
) -> dict[str, int]:
    """Match features with the known poses: for each candidate pair, mutual nearest SIFT descriptors among the
    keypoints within ``max_epipolar_px`` (original pixels) of the epipolar line, with a ratio test inside that
    band. The matches are written as verified (calibrated) two-view geometries, which triangulation reads.

    ``c2w``: image id → camera-to-world; ``view_of``: image id → training view. Wide baselines between tiny
    frames defeat blind matching; the epipolar band removes nearly all ambiguous candidates.
    """
    import pycolmap

    db = pycolmap.Database.open(db_path)
    try:
        cams = {c.camera_id: c for c in db.read_all_cameras()}
        images = {im.image_id: im for im in db.read_all_images() if im.image_id in c2w}
        rays, desc, fpx = {}, {}, {}
        for i, im in images.items():
            cam = cams[im.camera_id]
            kp = np.asarray(db.read_keypoints(i), np.float64)[:, :2]
            xy = np.asarray(cam.cam_from_img(kp), np.float64).reshape(-1, 2) if len(kp) else np.zeros((0, 2))
            rays[i] = np.concatenate([xy, np.ones((len(xy), 1))], 1)
            d = np.asarray(db.read_descriptors(i).data, np.float32)
            desc[i] = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
            fpx[i] = float(cam.mean_focal_length())
        pairs = _pair_candidates({i: c2w[i] for i in images}, view_of, neighbours)
        db.clear_matches()
        db.clear_two_view_geometries()
        n_pairs = n_matches = 0
        partners: dict[int, list[int]] = {}
        for a, b in sorted(pairs):
            partners.setdefault(a, []).append(b)
        for a, bs in partners.items():
            bs = [b for b in bs if len(rays[b]) >= 2]
            if len(rays[a]) < 2 or not bs:
                continue
            # one BLAS call per image (many small calls are slow under contention)
            sims = desc[a] @ np.concatenate([desc[b] for b in bs]).T
            offsets = np.cumsum([0] + [len(rays[b]) for b in bs])
            for j, b in enumerate(bs):
                rel = np.linalg.inv(c2w[b]) @ c2w[a]  # cam_b from cam_a
                t = rel[:3, 3]
                if np.linalg.norm(t) < 1e-9 * max(1.0, np.linalg.norm(c2w[a][:3, 3])):
                    continue  # identical centres (copied poses): no epipolar geometry
                E = _skew(t) @ rel[:3, :3]  # x_bᵀ E x_a = 0 in normalised coordinates
                la = rays[a] @ E.T  # (Na, 3) epipolar lines in b of the points of a
                lb = rays[b] @ E  # (Nb, 3) lines in a of the points of b
                num = np.abs(la @ rays[b].T)  # (Na, Nb) |x_bᵀ E x_a|
                m = band_matches(
                    sims[:, offsets[j] : offsets[j + 1]],
                    num,
                    fpx[b] / np.maximum(np.linalg.norm(la[:, :2], axis=1), 1e-12),
                    fpx[a] / np.maximum(np.linalg.norm(lb[:, :2], axis=1), 1e-12),
                    max_epipolar_px,
                    GUIDED_RATIO,
                )
                if len(m) < GUIDED_MIN_MATCHES:
                    continue
                m = m.astype(np.uint32)
                db.write_matches(a, b, m)
                tvg = pycolmap.TwoViewGeometry()
                tvg.config = pycolmap.TwoViewGeometryConfiguration.CALIBRATED
                tvg.inlier_matches = m
                tvg.E = E
                db.write_two_view_geometry(a, b, tvg)
                n_pairs += 1
                n_matches += len(m)
    finally:
        db.close()
    log.info("epipolar-guided matching: %d of %d image pairs matched, %d matches", n_pairs, len(pairs), n_matches)
    return {"pairs_tried": len(pairs), "pairs_matched": n_pairs, "matches": n_matches}


def band_matches(
    sims: np.ndarray, num: np.ndarray, scale_a: np.ndarray, scale_b: np.ndarray, max_px: float, ratio: float
) -> np.ndarray:
    """(K, 2) index pairs (i in image a, j in image b) matched inside the epipolar band: mutual nearest neighbours in
    descriptor distance d = √(2 − 2·s) (``sims`` (Na, Nb): cosine similarities of unit descriptors) among the
    pairs with ``num[i, j]·scale_a[i] ≤ max_px`` and ``num[i, j]·scale_b[j] ≤ max_px`` (``num``: |x_bᵀ E x_a|;
    ``scale_a``: pixels per unit of it in image b for the point i of a, ``scale_b`` in image a), that pass the
    ratio test d₁ < ``ratio``·d₂ against the second-best candidate inside the band in both directions.

    Works on similarities (the distance is decreasing in s): one masked copy of the block and a few reductions
    instead of a dense distance matrix and partial sorts. Equals the dense definition (tests/sfm/test_given.py)."""
    na, nb = sims.shape
    if na == 0 or nb == 0:
        return np.zeros((0, 2), np.int64)
    band = (num * scale_a[:, None] <= max_px) & (num * scale_b[None, :] <= max_px)
    s = np.where(band, sims, -np.inf)  # (Na, Nb)
    ia = np.arange(na)
    ja = np.argmax(s, axis=1)  # best of b for each point of a
    ib = np.argmax(s, axis=0)  # best of a for each point of b
    s1 = s[ia, ja]
    keep = np.isfinite(s1) & (ib[ja] == ia)
    cand = np.flatnonzero(keep)
    if cand.size == 0:
        return np.zeros((0, 2), np.int64)
    rows = s[cand]  # (K, Nb) a's rows of the mutual candidates (a copy): second best once the best is masked
    rows[np.arange(cand.size), ja[cand]] = -np.inf
    cols = s[:, ja[cand]].T  # (K, Na) their columns in b (a copy), likewise
    cols[np.arange(cand.size), cand] = -np.inf
    second_row, second_col = rows.max(axis=1), cols.max(axis=1)  # -inf when the row or column has one entry

    def dist(v: np.ndarray) -> np.ndarray:
        return np.sqrt(np.maximum(2.0 - 2.0 * v, 0.0))  # -inf → inf

    d1 = dist(s1[cand])
    ok = (d1 < ratio * dist(second_row)) & (d1 < ratio * dist(second_col))
    cand = cand[ok]
    return np.stack([cand, ja[cand]], 1)
