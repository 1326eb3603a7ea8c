"""E²NeRF dataset layouts (``--format e2nerf-synthetic`` / ``e2nerf-real``) → a scene with binned events.

Facts: ``docs/ingestion.md`` and the dataset note (``e2nerf-dataset.md``). Each view has its own clock (µs):

- synthetic: exposure [0, 170000]; latent poses ``transform_matrix`` entries 1, 5, 9, 13, 17 at
  10000 + 40000·k (k = 0..4); bin edges 0, 50000, 90000, 130000, 170000.
- real: exposure [0, 100004]; latent poses ``poses_bounds.npy`` rows 5i..5i+4 at 25001·k; bin edges
  0, 25001, 50002, 75003, 100004.

``events.pt`` (float64 (V, 4, H·W), signed net counts per bin, flat index y·W + x) → ``events/binned`` int32
(V, 4, H, W); every value must be an integer.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.options import IngestOptions, parse_intrinsics, parse_views
from eigs.scene.model import (
    SHARP_KIND_BLUR_VIEW,
    SHARP_KIND_NOVEL_VIEW,
    BinnedEvents,
    Camera,
    Frames,
    Poses,
    Scene,
    SharpImages,
)

log = logging.getLogger(__name__)

SYN_EXPOSURE_US = (0, 170_000)
SYN_LATENT_ENTRIES = (1, 5, 9, 13, 17)
SYN_LATENT_T_US = np.array([10_000, 50_000, 90_000, 130_000, 170_000], dtype=np.int64)
SYN_BIN_EDGES_US = np.array([0, 50_000, 90_000, 130_000, 170_000], dtype=np.int64)
SYN_TEST_ENTRY = 1  # ground truth is rendered at transform_matrix[1]
SYN_MAX_FRAMES = 200  # load_blender.py reads frames[0:200:2] (train) and frames[0:200] (test)
REAL_BIN_US = 25_001
REAL_EXPOSURE_US = (0, 4 * REAL_BIN_US)
REAL_LATENT_T_US = REAL_BIN_US * np.arange(5, dtype=np.int64)
REAL_BIN_EDGES_US = REAL_LATENT_T_US.copy()
REAL_POSES_PER_VIEW = 5
N_BINS = 4
POSE_TOL = 1e-6  # blur-view ground-truth pose vs the view's first latent pose


def load_event_tensor(path: Path, n_views: int, height: int, width: int) -> np.ndarray:
    """``events.pt`` → (V, 4, H, W) int32. Accepts (V, 4, H·W) (as E²NeRF saves it) or (V, 4, H, W); values
    must be finite integers that fit int32. Memory-maps the file when torch can, converting view by view."""
    import torch

    if not path.is_file():
        raise EigsError(path, "missing event tensor")
    try:
        try:
            ten = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
        except RuntimeError as err:  # legacy (non-zip) serialisation cannot be memory-mapped
            if "mmap" not in str(err):
                raise
            ten = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:
        raise EigsError(
            path, f"not a readable torch tensor file, truncated or corrupted ({type(err).__name__})"
        ) from None
    if not isinstance(ten, torch.Tensor):
        raise EigsError(path, f"holds a {type(ten).__name__}, expected one tensor")
    shape = tuple(ten.shape)
    if shape not in ((n_views, N_BINS, height * width), (n_views, N_BINS, height, width)):
        raise EigsError(
            path,
            f"has shape {'×'.join(map(str, shape))}, expected {n_views}×{N_BINS}×{height * width} "
            f"(views × bins × H·W for {n_views} images of {width}×{height})",
        )
    if ten.dtype.is_complex or ten.dtype == torch.bool:
        raise EigsError(path, f"has dtype {ten.dtype}, expected signed event counts")
    out = np.empty((n_views, N_BINS, height, width), dtype=np.int32)
    for v in range(n_views):
        a = ten[v].numpy().reshape(N_BINS, height, width)
        if a.dtype.kind == "f":
            if not np.all(np.isfinite(a)):
                raise EigsError(path, f"view {v} has NaN/Inf counts")
            frac = a != np.round(a)
            if np.any(frac):
                b, i, j = (int(k[0]) for k in np.nonzero(frac))
                raise EigsError(
                    path, f"count {float(a[b, i, j])!r} at view {v}, bin {b}, pixel (x={j}, y={i}) is not an integer"
                )
        if a.size and (a.max() > np.iinfo(np.int32).max or a.min() < np.iinfo(np.int32).min):
            raise EigsError(path, f"view {v} has counts beyond int32")
        out[v] = a
    return out


def _read_json(path: Path) -> dict:
    if not path.is_file():
        raise EigsError(path, "missing file")
    try:
        meta = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise EigsError(path, f"not valid JSON ({err})") from None
    if not isinstance(meta, dict) or not isinstance(meta.get("frames"), list):
        raise EigsError(path, "has no 'frames' list")
    return meta


def _frame_matrices(path: Path, frame: object, i: int, min_entries: int) -> np.ndarray:
    """``transform_matrix`` of frame ``i`` → (M, 4, 4) float64 with M ≥ ``min_entries``."""
    if not isinstance(frame, dict) or "transform_matrix" not in frame:
        raise EigsError(path, f"frame {i} has no transform_matrix")
    try:
        m = np.asarray(frame["transform_matrix"], dtype=np.float64)
    except (TypeError, ValueError):
        raise EigsError(path, f"frame {i}: transform_matrix is not a list of 4×4 matrices") from None
    if m.shape == (4, 4):
        raise EigsError(
            path, f"frame {i}: transform_matrix is one 4×4 matrix (plain NeRF layout), E²NeRF lists one per sub-frame"
        )
    if m.ndim != 3 or m.shape[1:] != (4, 4) or m.shape[0] < min_entries:
        raise EigsError(
            path,
            f"frame {i}: transform_matrix has shape {'×'.join(map(str, m.shape))}, "
            f"expected ≥ {min_entries} 4×4 matrices",
        )
    if not np.all(np.isfinite(m)):
        raise EigsError(path, f"frame {i}: transform_matrix has NaN/Inf")
    return m


def _rel_png(file_path: str) -> str:
    """A frame's ``file_path`` as E²NeRF opens it (``basedir/file_path + '.png'``), normalised: ``train/r_0.png``."""
    p = file_path.replace("\\", "/")
    while p.startswith("./"):
        p = p[2:]
    return p if p.endswith(".png") else p + ".png"


def _file_path_mismatches(path: Path, frames: list, indices: list[int], expected: list[str]) -> list[str]:
    """Frames whose ``file_path`` names another file than the one E²NeRF's loader opens for them by counting.

    ``file_path`` is informational only (``load_blender.py`` never reads it): absent, empty or non-string entries
    are fine; a string naming a different image is reported. Returns one description per mismatching frame."""
    out = []
    for j, want in zip(indices, expected, strict=True):
        fr = frames[j]
        fp = fr.get("file_path") if isinstance(fr, dict) else None
        if isinstance(fp, str) and fp and _rel_png(fp) != want:
            out.append(f"frame {j}: {fp!r} (read as {want})")
    if out:
        log.warning(
            "%s: file_path of %d frame(s) names other images than E²NeRF's loader opens; read by index as it does "
            "(%s%s)",
            path,
            len(out),
            "; ".join(out[:3]),
            " …" if len(out) > 3 else "",
        )
    return out


def _eigs_time_base(path: Path, meta: dict, frames: list[dict], n_views: int) -> tuple[np.ndarray, ...] | None:
    """The time base an eigs export states (``eigs`` block + ``eigs_time_us`` per frame), checked for consistency:
    (exposure (V, 2), bin edges (V, 5), latent times (V, 5)) int64 µs; None for genuine E²NeRF data."""
    ext = meta.get("eigs")
    if ext is None:
        return None
    try:
        exposure = np.asarray(ext["exposure_us"], dtype=np.float64)
        edges = np.asarray(ext["bin_edges_us"], dtype=np.float64)
        times = np.asarray([fr["eigs_time_us"] for fr in frames], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise EigsError(path, "has an 'eigs' block without exposure_us/bin_edges_us/eigs_time_us") from None
    if exposure.shape != (n_views, 2) or edges.shape != (n_views, N_BINS + 1) or times.ndim != 2:
        raise EigsError(path, f"'eigs' block shapes {exposure.shape}, {edges.shape} do not match {n_views} views")
    latent = times[:, list(SYN_LATENT_ENTRIES)]
    for name, a in (("exposure_us", exposure), ("bin_edges_us", edges), ("eigs_time_us", latent)):
        if not np.all(np.isfinite(a)) or np.any(np.abs(a - np.rint(a)) > 1e-6):
            raise EigsError(path, f"'eigs' {name} holds non-integer µs")
    exposure, edges, latent = (np.rint(a).astype(np.int64) for a in (exposure, edges, latent))
    if np.any(latent[:, 1:] != edges[:, 1:]) or np.any(edges[:, 0] > latent[:, 0]):
        raise EigsError(path, "'eigs' bin_edges_us disagree with the latent times of entries 1, 5, 9, 13, 17")
    return exposure, edges, latent


def llff_images(folder: Path) -> list[Path]:
    """The images of an LLFF ``images/`` folder as ``load_llff.py`` finds them: the files whose names end in
    ``JPG``, ``jpg`` or ``png``, sorted by name (view i = the i-th; names need not be numbers)."""
    if not folder.is_dir():
        raise EigsError(folder, "missing folder (images)")
    out = sorted(
        (p for p in folder.iterdir() if p.is_file() and p.name.endswith(("JPG", "jpg", "png"))), key=lambda p: p.name
    )
    if not out:
        raise EigsError(folder, "holds no images (*.png, *.jpg, *.JPG, as load_llff.py reads)")
    return out


def _intrinsics_override(opts: IngestOptions, K: np.ndarray, source_desc: str) -> tuple[np.ndarray, np.ndarray, str]:
    if opts.intrinsics is None:
        return K, np.zeros(5), source_desc
    K2, dist = parse_intrinsics(opts.intrinsics)
    if np.any(dist != 0) and opts.undistort:
        raise EigsError(
            "--intrinsics",
            "has distortion, but binned events.pt cannot be undistorted exactly; add --no-undistort to keep it",
        )
    return K2, dist, f"--intrinsics {opts.intrinsics}"


def read_e2nerf_synthetic(folder: Path, opts: IngestOptions) -> tuple[Scene, list[str]]:
    """An E²NeRF synthetic scene folder → (Scene, notes)."""
    from eigs.ingest.images import read_images
    from eigs.ingest.poses import blender_to_opencv

    if not folder.is_dir():
        raise EigsError(folder, "no such folder")
    notes: list[str] = []
    train_json = folder / "transform_train.json"
    if not train_json.is_file() and (folder / "transforms_train.json").is_file():
        raise EigsError(train_json, "missing (found transforms_train.json: a plain NeRF-synthetic scene, not E²NeRF)")
    meta = _read_json(train_json)
    angle = meta.get("camera_angle_x")
    if not isinstance(angle, (int, float)) or not np.isfinite(angle) or not 0 < angle < np.pi:
        raise EigsError(train_json, f"camera_angle_x must be a number in (0, π), got {angle!r}")
    # load_blender.py: meta['frames'][0:200:2] with images train/r_{2i}.png, counted, never via file_path
    frames = meta["frames"]
    train_idx = list(range(0, min(len(frames), SYN_MAX_FRAMES), 2))
    if not train_idx:
        raise EigsError(train_json, "has no frames")
    n_views = len(train_idx)
    img_paths = [folder / "train" / f"r_{2 * v}.png" for v in range(n_views)]
    if not (folder / "train").is_dir():
        raise EigsError(folder / "train", "missing folder (train images r_N.png)")
    for v, p in enumerate(img_paths):
        if not p.is_file():
            raise EigsError(p, f"missing: E²NeRF's loader opens it for frame {train_idx[v]} of {train_json.name}")
    wanted = set(img_paths)
    unread = sorted(q.name for q in (folder / "train").glob("r_*.png") if q not in wanted)
    if unread:
        notes.append(f"train/ images not read (E²NeRF reads r_0 … r_{2 * (n_views - 1)}): {', '.join(unread[:5])}")
    mismatch = _file_path_mismatches(train_json, frames, train_idx, [f"train/{p.name}" for p in img_paths])
    if mismatch:
        notes.append(f"warning: {len(mismatch)} train frame file_path(s) name other images; read by index")
    latent = np.empty((n_views, len(SYN_LATENT_ENTRIES), 4, 4))
    train_frames = []
    for v, j in enumerate(train_idx):
        m = _frame_matrices(train_json, frames[j], j, max(SYN_LATENT_ENTRIES) + 1)
        latent[v] = m[list(SYN_LATENT_ENTRIES)]
        train_frames.append(frames[j])
    latent = blender_to_opencv(latent)
    blurry = read_images(img_paths, desc="train images")
    _, h, w, c = blurry.shape

    base = _eigs_time_base(train_json, meta, train_frames, n_views)
    if base is None:
        exposure = np.tile(np.array(SYN_EXPOSURE_US, np.int64), (n_views, 1))
        edges, latent_t = np.tile(SYN_BIN_EDGES_US, (n_views, 1)), np.tile(SYN_LATENT_T_US, (n_views, 1))
        notes.append("time base: E²NeRF's (exposure [0, 170000] µs, latent poses at 10000 + 40000·k µs)")
        ext: dict = {}
    else:
        exposure, edges, latent_t = base
        notes.append("time base: the eigs export's (the 'eigs' block of transform_train.json)")
        ext = meta["eigs"]

    focal = 0.5 * w / np.tan(0.5 * float(angle))
    K = np.array([[focal, 0.0, w / 2], [0.0, focal, h / 2], [0.0, 0.0, 1.0]])
    K, dist, calib = _intrinsics_override(opts, K, f"camera_angle_x = {angle} (pinhole, principal point W/2, H/2)")

    counts = load_event_tensor(folder / "events.pt", n_views, h, w)

    sharp = None
    test_json = folder / "transform_test.json"
    if test_json.is_file():
        tmeta = _read_json(test_json)
        test_imgs, test_c2w, test_kind, test_view = [], [], [], []
        tframes = tmeta["frames"][:SYN_MAX_FRAMES]  # load_blender.py: frames[0:200], images test/r_{i}.png
        test_imgs = [folder / "test" / f"r_{k}.png" for k in range(len(tframes))]
        mismatch = _file_path_mismatches(
            test_json, tframes, list(range(len(tframes))), [f"test/r_{k}.png" for k in range(len(tframes))]
        )
        if mismatch:
            notes.append(f"warning: {len(mismatch)} test frame file_path(s) name other images; read by index")
        for k, fr in enumerate(tframes):
            mats = _frame_matrices(test_json, fr, k, SYN_TEST_ENTRY + 1)
            test_c2w.append(mats[SYN_TEST_ENTRY])
            if k % 2 == 0:
                if k // 2 >= n_views:
                    raise EigsError(test_json, f"blur-view ground truth r_{k} has no training view {k // 2}")
                test_kind.append(SHARP_KIND_BLUR_VIEW)
                test_view.append(k // 2)
            else:
                test_kind.append(SHARP_KIND_NOVEL_VIEW)
                test_view.append(-1)
        if test_imgs:
            images = read_images(test_imgs, desc="test images")
            if images.shape[1:] != blurry.shape[1:]:
                raise EigsError(
                    folder / "test",
                    f"test images are {images.shape[2]}×{images.shape[1]}×{images.shape[3]}, train images {w}×{h}×{c}",
                )
            c2w = blender_to_opencv(np.asarray(test_c2w))
            kind = np.asarray(test_kind, dtype=np.uint8)
            view = np.asarray(test_view, dtype=np.int64)
            t_us = np.where(kind == SHARP_KIND_BLUR_VIEW, latent_t[np.maximum(view, 0), 0], -1).astype(np.int64)
            sharp = SharpImages(images, c2w, t_us, kind, view)
            blur = np.flatnonzero(kind == SHARP_KIND_BLUR_VIEW)
            diff = np.abs(c2w[blur] - latent[view[blur], 0]).max(initial=0.0)
            if diff > POSE_TOL:
                notes.append(
                    f"blur-view ground-truth poses differ from the views' first latent poses by up to {diff:.3g}"
                )
    else:
        notes.append("no transform_test.json: no sharp ground truth")

    scene = Scene(
        name=opts.name or folder.name,
        camera=Camera(K=K, width=w, height=h, distortion=dist),
        channels=c,
        camera_response=opts.camera_response or str(ext.get("camera_response", "unknown")),
        synthetic=True,
        background=np.zeros(c) if base is None else None,  # E²NeRF: white_bkgd = False; an export does not say
        contrast_threshold=opts.contrast_threshold
        if opts.contrast_threshold is not None
        else ext.get("contrast_threshold"),
        source=f"e2nerf-synthetic:{folder}",
        frames=Frames(blurry=blurry, exposure_us=exposure),
        binned=BinnedEvents(counts=counts, bin_edges_us=edges),
        poses=Poses(latent, latent_t, "ground-truth"),
        sharp=sharp,
    )
    notes.insert(0, f"calibration: {calib}")
    return scene, notes


def read_e2nerf_real(folder: Path, opts: IngestOptions) -> tuple[Scene, list[str]]:
    """An E²NeRF real-world (LLFF) scene folder → (Scene, notes)."""
    from eigs.ingest.images import read_images
    from eigs.ingest.poses import llff_to_opencv

    if not folder.is_dir():
        raise EigsError(folder, "no such folder")
    img_paths = llff_images(folder / "images")
    n_views = len(img_paths)

    pb_path = folder / "poses_bounds.npy"
    if not pb_path.is_file():
        raise EigsError(pb_path, "missing file")
    try:
        pb = np.load(pb_path, allow_pickle=False)
    except Exception as err:
        raise EigsError(pb_path, f"not a readable .npy array, truncated or corrupted ({type(err).__name__})") from None
    if pb.ndim != 2 or pb.shape[1] != 17:
        raise EigsError(pb_path, f"has shape {'×'.join(map(str, pb.shape))}, expected N×17 (LLFF rows)")
    if pb.shape[0] != REAL_POSES_PER_VIEW * n_views:
        raise EigsError(
            pb_path,
            f"has {pb.shape[0]} poses but images/ has {n_views} images (expected {REAL_POSES_PER_VIEW}·{n_views} = "
            f"{REAL_POSES_PER_VIEW * n_views})",
        )
    pb = pb.astype(np.float64)
    if not np.all(np.isfinite(pb)):
        raise EigsError(pb_path, f"has NaN/Inf (first in row {int(np.flatnonzero(~np.isfinite(pb).all(1))[0])})")
    hwf = pb[:, :15].reshape(-1, 3, 5)[:, :, 4]
    if np.any(np.abs(hwf - hwf[0]) > 1e-9 * np.abs(hwf[0])):
        raise EigsError(pb_path, "rows disagree on the camera (h, w, focal): one shared camera expected")

    blurry = read_images(img_paths, desc="images")
    _, h, w, c = blurry.shape
    fh, fw, focal = (float(v) for v in hwf[0])
    if (fh, fw) != (float(h), float(w)):
        raise EigsError(pb_path, f"hwf says {fw:g}×{fh:g} but the images are {w}×{h}")
    if not focal > 0:
        raise EigsError(pb_path, f"focal length {focal} is not positive")
    K = np.array([[focal, 0.0, w / 2], [0.0, focal, h / 2], [0.0, 0.0, 1.0]])
    K, dist, calib = _intrinsics_override(opts, K, f"{pb_path.name} hwf (focal {focal:g}, principal point W/2, H/2)")
    latent = llff_to_opencv(pb).reshape(n_views, REAL_POSES_PER_VIEW, 4, 4)

    names = [folder / "events.pt", folder / "event.pt"]
    present = [p for p in names if p.is_file()]
    if len(present) == 2:
        raise EigsError(folder, "holds both events.pt and event.pt; keep one")
    if not present:
        raise EigsError(names[0], "missing event tensor (events.pt or event.pt)")
    counts = load_event_tensor(present[0], n_views, h, w)

    scene = Scene(
        name=opts.name or folder.name,
        camera=Camera(K=K, width=w, height=h, distortion=dist),
        channels=c,
        camera_response=opts.camera_response or "unknown",
        synthetic=False,
        contrast_threshold=opts.contrast_threshold,
        source=f"e2nerf-real:{folder}",
        frames=Frames(
            blurry=blurry,
            exposure_us=np.tile(np.array(REAL_EXPOSURE_US, np.int64), (n_views, 1)),
            names=[p.name for p in img_paths],
        ),
        binned=BinnedEvents(counts=counts, bin_edges_us=np.tile(REAL_BIN_EDGES_US, (n_views, 1))),
        poses=Poses(latent, np.tile(REAL_LATENT_T_US, (n_views, 1)), "estimated"),
    )
    return scene, [f"calibration: {calib}"]


GT_K_RTOL = 1e-9  # ground-truth camera vs the layout's (poses_bounds.npy hwf is stored in float64)


def merge_groundtruth(scene: Scene, path: Path) -> tuple[Scene, str]:
    """Merge a ground-truth scene file (``eigs synth --e2nerf-real-layout`` writes it beside the layout) into a
    scene read from an E²NeRF real layout: its latent ground-truth poses (on the layout's per-view clock,
    25001·k µs) replace the layout's ``poses_bounds.npy`` poses, and its sharp images become the scene's ground
    truth. For scoring only: the sfm stage runs COLMAP on the EDI frames unless given poses are allowed
    (``sfm: allow_given``, default true: set it false, or ``mode: colmap``), and uses the ground truth for its
    accuracy report and the test cameras; evaluation scores against the sharp images. Returns (scene, note)."""
    from eigs.scene import read_scene

    if not path.is_file():
        raise EigsError(path, "no such ground-truth file")
    gt = read_scene(path, events=False)
    cam, gcam = scene.camera, gt.camera
    if (gcam.width, gcam.height) != (cam.width, cam.height) or not np.allclose(gcam.K, cam.K, rtol=GT_K_RTOL,
                                                                              atol=0.0):
        raise EigsError(path, f"ground-truth camera (K {gcam.K.tolist()}, {gcam.width}×{gcam.height}) differs from "
                        f"the layout's (K {cam.K.tolist()}, {cam.width}×{cam.height})")
    if gt.channels != scene.channels:
        raise EigsError(path, f"ground truth has {gt.channels} channel(s), the layout's images {scene.channels}")
    if gt.poses is None or gt.poses.source != "ground-truth":
        raise EigsError(path, "holds no ground-truth latent poses")
    lt = scene.poses.latent_t_us
    if gt.poses.latent_t_us.shape != lt.shape or not np.array_equal(gt.poses.latent_t_us, lt):
        raise EigsError(path, f"ground-truth latent times {gt.poses.latent_t_us.shape} differ from the layout's "
                        f"({scene.n_views} views at 25001·k µs)")
    if gt.sharp is None:
        raise EigsError(path, "holds no sharp ground-truth images")
    blur = gt.sharp.kind == SHARP_KIND_BLUR_VIEW
    if np.any(blur & ((gt.sharp.view < 0) | (gt.sharp.view >= scene.n_views))):
        raise EigsError(path, f"blur-view ground truth names views outside 0..{scene.n_views - 1}")
    s = Scene(**scene.__dict__)
    s.poses = gt.poses
    s.sharp = gt.sharp
    s.source = f"{scene.source} + ground truth {path} (scoring only)"
    note = (f"ground truth: {path.name} (latent poses, {len(gt.sharp.kind)} sharp images; for scoring: sfm "
            "report and test cameras, evaluation)")
    return s, note


def select_views(scene: Scene, idx: np.ndarray) -> Scene:
    """Keep training views ``idx`` (M,) of an in-memory scene: frames, binned events, poses; blur-view ground
    truth of dropped views is dropped, the rest renumbered; novel views are kept."""
    s = Scene(**scene.__dict__)
    if s.frames is not None:
        ex = s.frames.exposure_us
        nm = s.frames.names
        names = None if nm is None else [nm[i] for i in idx]
        s.frames = Frames(s.frames.blurry[idx], None if ex is None else ex[idx], names=names)
    if s.binned is not None:
        s.binned = BinnedEvents(s.binned.counts[idx], s.binned.bin_edges_us[idx])
    if s.poses is not None:
        s.poses = Poses(s.poses.latent_c2w[idx], s.poses.latent_t_us[idx], s.poses.source)
    if s.sharp is not None:
        new = np.full(scene.n_views, -1, dtype=np.int64)
        new[idx] = np.arange(idx.size)
        sh = s.sharp
        is_blur = sh.kind == SHARP_KIND_BLUR_VIEW
        keep = ~is_blur | (new[np.where(is_blur, sh.view, 0)] >= 0)
        view = np.where(is_blur, new[np.where(is_blur, sh.view, 0)], -1)[keep]
        s.sharp = SharpImages(sh.images[keep], sh.c2w[keep], sh.t_us[keep], sh.kind[keep], view)
    return s


def ingest_e2nerf(fmt: str, source: str, out: str | Path, opts: IngestOptions) -> str:
    """Read an E²NeRF layout and write the scene atomically; returns the summary."""
    from eigs.scene import summarize, write_scene

    opts.refuse(fmt, "exposure_us", "time_window", "keep_events", "time_unit", "frames", "sensor_size",
                "frames_homography", "time_offset_us")
    folder = Path(source)
    if fmt == "e2nerf-synthetic":
        opts.refuse(fmt, "groundtruth")
        scene, notes = read_e2nerf_synthetic(folder, opts)
    else:
        scene, notes = read_e2nerf_real(folder, opts)
        if opts.groundtruth is not None:
            scene, note = merge_groundtruth(scene, Path(opts.groundtruth))
            notes.append(note)
    if opts.views is not None:
        scene = select_views(scene, parse_views(opts.views, scene.n_views))
    write_scene(scene, out, compression=opts.compression)
    from eigs.ingest.summary import insert_before_groundtruth

    extra = [f"  {n}" if n.startswith(("calibration", "time base")) else f"  note: {n}" for n in notes]
    return "\n".join(insert_before_groundtruth(summarize(scene).splitlines(), extra))
