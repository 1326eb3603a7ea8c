"""A thin wrapper around pycolmap 4 (see ../shared/docs/platform.md §4): database, features, matching, mapping.

Small frames are upsampled (integer factor, pixel-centre aligned) before SIFT so that 64–240 px images still
yield enough features; the keypoints are scaled back before matching, so the database, the model and every
reprojection error are in the original pixels and the image names are those of the original PNGs.
"""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.artifacts.colmap import load_pycolmap
from eigs.errors import EigsError
from eigs.sfm.options import ColmapOptions
from eigs.util.image import to_uint8

log = logging.getLogger(__name__)

EXHAUSTIVE_MAX_IMAGES = 150  # beyond this, sequential + spatial matching
FEATURE_TARGET_PX = 256  # upsample until the longer side reaches this (integer factor ≤ 4)
# Threads of COLMAP's mappers (incremental and global), fixed-pose triangulation and bundle adjustment, whatever
# ``num_threads`` says: Ceres on two threads sums in another order from run to run (blocks, the same database mapped
# twice at 2 threads: camera poses 1.6e-11 apart, other bytes; GLOMAP on chair's database three times at 2 threads:
# 2.3e-10 apart, at 1 thread identical), and a second thread did not make mapping faster (incremental: 13.8–21.1 s
# at one thread, 16.4–22.8 s at two; GLOMAP: 33.6–53.5 s at one, 40.9–71.3 s at two; shared 2-core machine).
# docs/sfm.md, "Reproducibility".
MAPPER_THREADS = 1


def quiet(verbose: bool = False) -> None:
    """Route pycolmap's glog to stderr (the rule's log) and keep only warnings (everything with ``verbose``)."""
    pycolmap = load_pycolmap()

    pycolmap.logging.logtostderr = True
    pycolmap.logging.minloglevel = 0 if verbose else 1
    pycolmap.logging.verbose_level = 0


def device(name: str):
    """pycolmap Device: ``cuda`` only when pycolmap was built with it; ``auto`` picks it then, else CPU."""
    import pycolmap

    if name == "cuda" and not pycolmap.has_cuda:
        raise EigsError(None, "--device cuda: this pycolmap build has no CUDA support")
    if name == "cuda" or (name == "auto" and pycolmap.has_cuda):
        return pycolmap.Device.cuda
    return pycolmap.Device.cpu


def feature_scale(width: int, height: int, requested: int | None = None) -> int:
    """Integer upsampling factor for SIFT (1 = none)."""
    if requested is not None:
        return max(1, int(requested))
    f = 1
    while max(width, height) * f < FEATURE_TARGET_PX and f < 4:
        f += 1
    return f


def camera_params(K: np.ndarray, distortion: np.ndarray | None, scale: float = 1.0) -> tuple[str, list[float]]:
    """COLMAP model name and parameters for a pinhole K (pixel centres at j+0.5, as COLMAP) and OpenCV
    distortion (k1, k2, p1, p2, k3); ``scale`` multiplies the focal lengths and principal point."""
    fx, fy, cx, cy = (float(K[0, 0]) * scale, float(K[1, 1]) * scale, float(K[0, 2]) * scale, float(K[1, 2]) * scale)
    d = np.zeros(5) if distortion is None else np.asarray(distortion, np.float64)
    if not np.any(d != 0):
        return "PINHOLE", [fx, fy, cx, cy]
    if d[4] == 0:
        return "OPENCV", [fx, fy, cx, cy, *map(float, d[:4])]
    return "FULL_OPENCV", [fx, fy, cx, cy, *map(float, d[:4]), float(d[4]), 0.0, 0.0, 0.0]


def pixel_scale(opts: ColmapOptions, width: int, height: int) -> float:
    """Factor for COLMAP's pixel thresholds (tuned for full-size images): 1/f with SIFT upsampling by f, so the
    thresholds mean the same as if COLMAP ran on the upsampled images."""
    return 1.0 / feature_scale(width, height, opts.feature_scale)


def verification_seed(opts: ColmapOptions) -> int:
    """RANSAC seed of two-view verification: ``opts.seed`` when matching runs on several threads, else -1.

    Unseeded (-1), each verifier thread draws from its own generator, seeded once (COLMAP's default 0) and consumed
    pair after pair: on one thread that sequence is fixed, on several it depends on which thread verified which
    pairs before (blocks at 2 threads: 1410 of 7140 two-view geometries differed between two runs). Seeded, every
    RANSAC call restarts the generator, so a pair's result no longer depends on its thread. One thread stays
    unseeded so that single-threaded outputs (the default suite's) are those of earlier versions."""
    return -1 if opts.num_threads == 1 else int(opts.seed)


def verification_options(px: float, seed: int = -1):
    """Two-view verification: RANSAC threshold 4 px scaled by ``px``, RANSAC ``seed`` (see
    :func:`verification_seed`)."""
    import pycolmap

    v = pycolmap.TwoViewGeometryOptions()
    v.ransac.max_error = 4.0 * px
    v.ransac.random_seed = int(seed)
    return v


def apply_thresholds(o, px: float) -> None:
    """Scale the reprojection thresholds of IncrementalPipelineOptions ``o`` by ``px``."""
    o.mapper.init_max_error = 4.0 * px
    o.mapper.abs_pose_max_error = 12.0 * px
    o.mapper.filter_max_reproj_error = 4.0 * px
    o.triangulation.merge_max_reproj_error = 4.0 * px
    o.triangulation.complete_max_reproj_error = 4.0 * px


def tighten_for_small_frames(o, opts: ColmapOptions) -> None:
    """Cap the incremental mapper's reprojection thresholds of IncrementalPipelineOptions ``o`` at
    ``opts.small_max_error_px`` (initial pair, filtering, triangulation) and ``opts.small_abs_pose_max_error_px``
    (registration of new images), in original pixels."""
    e, a = float(opts.small_max_error_px), float(opts.small_abs_pose_max_error_px)
    o.mapper.init_max_error = min(o.mapper.init_max_error, e)
    o.mapper.filter_max_reproj_error = min(o.mapper.filter_max_reproj_error, e)
    o.triangulation.merge_max_reproj_error = min(o.triangulation.merge_max_reproj_error, e)
    o.triangulation.complete_max_reproj_error = min(o.triangulation.complete_max_reproj_error, e)
    o.mapper.abs_pose_max_error = min(o.mapper.abs_pose_max_error, a)


def make_camera(K: np.ndarray, width: int, height: int, distortion: np.ndarray | None, camera_id: int = 1):
    import pycolmap

    model, params = camera_params(K, distortion)
    return pycolmap.Camera(model=model, width=int(width), height=int(height), params=params, camera_id=camera_id)


def enhance_for_features(im: np.ndarray) -> np.ndarray:
    """Brighten dark frames for SIFT only (keypoint positions are unaffected): stretch the 0.5–99.5 % range of
    the intensities to [0, 255] and apply the gamma that takes the median to 0.4. uint8 in, uint8 out."""
    x = im.astype(np.float32)
    lo, hi = np.percentile(x, [0.5, 99.5])
    if hi - lo < 1.0:
        return im
    y = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    med = float(np.median(y))
    if 0.05 < med < 0.3:
        y = y ** (np.log(0.4) / np.log(med))
    return to_uint8(y)


def _feature_copies(src_dir: Path, names: Sequence[str], dst_dir: Path, f: int, enhance: bool) -> None:
    """Copies of the images for feature extraction: upsampled by ``f`` (pixel-centre aligned), enhanced."""
    import cv2

    dst_dir.mkdir(parents=True, exist_ok=True)
    for name in names:
        im = cv2.imread(str(src_dir / name), cv2.IMREAD_UNCHANGED)
        if im is None:
            raise EigsError(src_dir / name, "cannot read image")
        if im.dtype != np.uint8:
            im = to_uint8(im.astype(np.float64) / np.iinfo(im.dtype).max)
        if enhance:
            im = enhance_for_features(im)
        if f > 1:
            im = cv2.resize(im, (im.shape[1] * f, im.shape[0] * f), interpolation=cv2.INTER_CUBIC)
        cv2.imwrite(str(dst_dir / name), im)


def extract(
    db_path: Path,
    image_dir: Path,
    names: Sequence[str],
    K: np.ndarray,
    width: int,
    height: int,
    distortion: np.ndarray | None,
    work_dir: Path,
    opts: ColmapOptions,
) -> dict[str, int]:
    """Extract SIFT features of ``names`` (files in ``image_dir``) into the database with one shared camera for
    them (a database that already holds images gets a second camera with the same parameters). Returns
    name → image id."""
    import pycolmap

    missing = [n for n in names if not (image_dir / n).is_file()]
    if missing:
        raise EigsError(image_dir, f"{len(missing)} image(s) missing, e.g. {missing[0]}")
    f = feature_scale(width, height, opts.feature_scale)
    src = image_dir
    copies = f > 1 or opts.enhance
    if copies:
        src = work_dir / f"features_x{f}"
        _feature_copies(image_dir, names, src, f, opts.enhance)
    reader = pycolmap.ImageReaderOptions()
    model, params = camera_params(K, distortion, scale=f)
    reader.camera_model = model
    reader.camera_params = ",".join(f"{p:.10g}" for p in params)
    ext = pycolmap.FeatureExtractionOptions()
    ext.num_threads = opts.num_threads
    ext.sift.max_num_features = opts.max_num_features
    ext.max_image_size = max(4096, max(width, height) * f)
    # Image ids in the order of ``names``: with several threads the extractor writes each image (and gives it its
    # id) when its features are done, so ids, and with them matching, triangulation and mapping orders, changed
    # from run to run. Importing the images first (one thread, in order) fixes the ids; the extractor then only
    # adds features to the images it finds in the database.
    pycolmap.Database.open(db_path).close()  # creates it when absent (import_images needs the file)
    pycolmap.import_images(
        db_path, src, camera_mode=pycolmap.CameraMode.SINGLE, image_names=list(names), options=reader
    )
    pycolmap.extract_features(
        db_path,
        src,
        image_names=list(names),
        camera_mode=pycolmap.CameraMode.SINGLE,
        reader_options=reader,
        extraction_options=ext,
        device=device(opts.device),
    )
    db = pycolmap.Database.open(db_path)
    try:
        wanted = set(names)
        images = [im for im in db.read_all_images() if im.name in wanted]
        ids = {im.name: im.image_id for im in images}
        if f > 1:
            for image_id in ids.values():
                kp = np.asarray(db.read_keypoints(image_id), np.float32)
                if kp.size:
                    kp = kp.copy()
                    kp[:, :2] /= f  # pixel-centre aligned upsampling: x_orig = x_up / f exactly
                    kp[:, 2:] /= f  # affine shape (a11 a12 a21 a22)
                    db.update_keypoints(image_id, kp)
            new_cams = {im.camera_id for im in images}
            for cam in db.read_all_cameras():
                if cam.camera_id in new_cams:
                    model, params = camera_params(K, distortion)
                    cam.width, cam.height, cam.params = int(width), int(height), params
                    db.update_camera(cam)
        n_kp = [db.num_keypoints_for_image(i) for i in ids.values()]
    finally:
        db.close()
    if copies:
        shutil.rmtree(src, ignore_errors=True)
    log.info(
        "features: %d images (SIFT at ×%d), %d keypoints per image (median), %d with fewer than 50",
        len(ids),
        f,
        int(np.median(n_kp)) if n_kp else 0,
        sum(n < 50 for n in n_kp),
    )
    return ids


def write_position_priors(db_path: Path, positions: dict[int, np.ndarray]) -> None:
    """Store camera centres (image id → (3,)) as pose priors for spatial matching."""
    import pycolmap

    db = pycolmap.Database.open(db_path)
    try:
        db.clear_pose_priors()
        data_ids = {im.image_id: im.data_id for im in db.read_all_images()}
        for image_id, pos in positions.items():
            if image_id not in data_ids:
                continue
            prior = pycolmap.PosePrior()
            prior.position = np.asarray(pos, np.float64).reshape(3, 1)
            prior.coordinate_system = pycolmap.PosePriorCoordinateSystem.CARTESIAN
            prior.corr_data_id = data_ids[image_id]
            db.write_pose_prior(prior)
    finally:
        db.close()


def match(
    db_path: Path, n_images: int, n_latent: int, opts: ColmapOptions, *, spatial: bool = False, px: float = 1.0
) -> str:
    """Match features: exhaustive up to :data:`EXHAUSTIVE_MAX_IMAGES` images, else sequential in (view, k)
    name order; ``spatial`` adds pose-prior (spatial) matching. Returns the matcher used."""
    import pycolmap

    kind = opts.matcher
    if kind == "auto":
        kind = "exhaustive" if n_images <= EXHAUSTIVE_MAX_IMAGES else "sequential"
    m = pycolmap.FeatureMatchingOptions()
    m.num_threads = opts.num_threads
    dev = device(opts.device)
    ver = verification_options(px, verification_seed(opts))
    if spatial:
        pairing = pycolmap.SpatialPairingOptions()
        pairing.max_num_neighbors = max(20, 4 * n_latent)
        pairing.num_threads = opts.num_threads
        pycolmap.match_spatial(
            db_path, matching_options=m, pairing_options=pairing, verification_options=ver, device=dev
        )
        return "spatial"
    if kind == "exhaustive":
        pycolmap.match_exhaustive(db_path, matching_options=m, verification_options=ver, device=dev)
    elif kind == "sequential":
        pairing = pycolmap.SequentialPairingOptions()
        pairing.overlap = opts.sequential_overlap or max(10, 3 * n_latent)
        pairing.quadratic_overlap = True
        pairing.num_threads = opts.num_threads
        pycolmap.match_sequential(
            db_path, matching_options=m, pairing_options=pairing, verification_options=ver, device=dev
        )
    else:
        raise EigsError(None, f"unknown matcher {opts.matcher!r} (auto, exhaustive or sequential)")
    return kind


@dataclass
class MappingResult:
    reconstruction: object  # pycolmap.Reconstruction, the largest model
    model_sizes: list[int]  # registered images per model, largest first
    lost_to_other_models: int  # images registered only in models other than the kept one


def map_images(
    db_path: Path,
    image_dir: Path,
    out_dir: Path,
    opts: ColmapOptions,
    *,
    fixed_intrinsics: bool = True,
    px: float = 1.0,
) -> MappingResult:
    """Incremental (or global) mapping; keeps the model with the most registered images. Both run on
    :data:`MAPPER_THREADS` threads (reproducible for a given database)."""
    import pycolmap

    out_dir.mkdir(parents=True, exist_ok=True)
    if opts.global_mapping:
        g = pycolmap.GlobalPipelineOptions()
        g.num_threads = MAPPER_THREADS
        g.random_seed = opts.seed
        recs = pycolmap.global_mapping(db_path, image_dir, out_dir, options=g)
    else:
        o = pycolmap.IncrementalPipelineOptions()
        o.num_threads = MAPPER_THREADS
        o.random_seed = opts.seed
        refine = opts.refine_intrinsics or not fixed_intrinsics
        o.ba_refine_focal_length = refine
        o.ba_refine_extra_params = refine
        o.ba_refine_principal_point = False
        o.multiple_models = True
        o.min_model_size = 3
        apply_thresholds(o, px)
        if px < 1.0:  # small frames, SIFT on upsampled copies: tighter thresholds (original pixels)
            tighten_for_small_frames(o, opts)
        recs = pycolmap.incremental_mapping(db_path, image_dir, out_dir, options=o)
    models = sorted(recs.values(), key=lambda r: r.num_reg_images(), reverse=True)
    if not models:
        return MappingResult(None, [], 0)
    kept = {im.name for im in models[0].images.values() if im.has_pose}
    # models may overlap; a split means images registered elsewhere but not in the largest model
    elsewhere = {im.name for r in models[1:] for im in r.images.values() if im.has_pose} - kept
    sizes = [int(r.num_reg_images()) for r in models]
    if elsewhere:
        log.warning(
            "COLMAP split the scene into %d models (%s registered images): keeping the largest; %d images "
            "registered only in the others are treated as unregistered",
            len(models),
            ", ".join(map(str, sizes)),
            len(elsewhere),
        )
    return MappingResult(models[0], sizes, len(elsewhere))


def c2w_of(image) -> np.ndarray:
    """Camera-to-world 4×4 (OpenCV axes, as COLMAP) of a registered pycolmap Image."""
    m = np.eye(4)
    m[:3, :4] = image.cam_from_world().matrix()
    return np.linalg.inv(m)


def rigid_from_c2w(c2w: np.ndarray):
    """pycolmap.Rigid3d (cam_from_world) of a camera-to-world 4×4."""
    import pycolmap

    w2c = np.linalg.inv(np.asarray(c2w, np.float64))
    R = w2c[:3, :3]
    u, _, vt = np.linalg.svd(R)  # re-orthonormalise (float noise from the inverse)
    return pycolmap.Rigid3d(pycolmap.Rotation3d(u @ vt), w2c[:3, 3].copy())


def sim3d(scale: float, R: np.ndarray, t: np.ndarray):
    import pycolmap

    return pycolmap.Sim3d(float(scale), pycolmap.Rotation3d(np.asarray(R, np.float64)), np.asarray(t, np.float64))


def remove_files(paths: Sequence[os.PathLike]) -> None:
    for p in paths:
        Path(p).unlink(missing_ok=True)
