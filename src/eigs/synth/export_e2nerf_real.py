"""Write a scene in the E²NeRF *real-world* (LLFF) layout, with its ground truth kept outside the layout.

>>> from eigs.synth.export_e2nerf_real import write_e2nerf_real
>>> write_e2nerf_real(generated, "out/blocks/e2nerf-real", groundtruth="out/blocks/groundtruth.h5")

What a user's DAVIS346 recording looks like after E²NeRF's real-data preprocessing
(../shared/docs/e2nerf-dataset.md §3, §5; ``data-preprocessing.py``)::

    images/{5i:03d}.jpg    blurry frame of view i (JPEG quality 95, cv2.imwrite's default; or PNG, lossless)
    events.pt              torch.save of a float64 tensor (V, 4, H·W): signed net counts, flat index y·W + x;
                           the events of the view's exposure [start, end) in bins k = ⌊(t − start) / 25001⌋
                           (E²NeRF's fixed 25,001 µs bins; an exposure ≤ 100,004 µs is required)
    poses_bounds.npy       5·V LLFF rows ``[R | t | (h, w, f)]`` + (near, far), view-major: the camera's
                           (h, w, f) with f = fx; the pose part and the bounds are **placeholders** (identity
                           rotation, zero translation; near 0.1, far 100), because the dataset's rows are
                           COLMAP estimates on its EDI frames, which the pipeline computes itself (sfm stage,
                           COLMAP mode). No ground truth is written inside the layout.

The ground truth goes to a separate scene file (``groundtruth``; default ``<out_dir>.groundtruth.h5``, beside
the layout): the latent ground-truth poses on the layout's per-view clock (25,001·k µs, k = 0..4, exactly where
E²NeRF's bin edges are, taken from the exact camera path), and the sharp images (blur views at the first latent
time, t = 0 of the view clock, and the novel views). ``eigs ingest --format e2nerf-real DIR --groundtruth FILE``
merges it into the scene for scoring (docs/ingestion.md, docs/evaluation.md).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from eigs.errors import EigsError
from eigs.scene import Camera, Poses, Scene, SharpImages

log = logging.getLogger(__name__)

REAL_BIN_US = 25_001  # E²NeRF's real-data bin width (µs): bin = int((t − start) / 25001)
N_BINS = 4
POSES_PER_VIEW = N_BINS + 1
PLACEHOLDER_BOUNDS = (0.1, 100.0)
IMAGE_FORMATS = ("jpg", "png")
JPEG_QUALITY = 95  # cv2.imwrite's default, which E²NeRF's preprocessing used


def real_event_bins(scene: Scene) -> np.ndarray:
    """E²NeRF real ``events.pt`` counts (V, 4, H·W) float64 from the scene's raw events: view v's exposure events
    (``events/view_index``, start ≤ t < end) in bins ⌊(t − start)/25001⌋. Raises when an exposure is longer than
    4·25001 µs (E²NeRF's preprocessing would index a fifth bin)."""
    ev, cam = scene.events, scene.camera
    exposure = scene.frames.exposure_us
    v_n, hw = scene.n_views, cam.width * cam.height
    long = np.flatnonzero(exposure[:, 1] - exposure[:, 0] > N_BINS * REAL_BIN_US)
    if long.size:
        raise EigsError(None, f"view {int(long[0])}: exposure longer than {N_BINS * REAL_BIN_US} µs does not fit "
                        f"E²NeRF's four 25001 µs bins")
    out = np.zeros((v_n, N_BINS, hw), np.float64)
    for v in range(v_n):
        lo, hi = (int(i) for i in ev.view_index[v])
        b = (ev.t[lo:hi] - exposure[v, 0]) // REAL_BIN_US
        idx = b * hw + ev.y[lo:hi].astype(np.int64) * cam.width + ev.x[lo:hi].astype(np.int64)
        out[v] = np.bincount(idx, weights=ev.p[lo:hi].astype(np.float64), minlength=N_BINS * hw).reshape(N_BINS, hw)
    return out


def placeholder_poses_bounds(n_views: int, camera: Camera) -> np.ndarray:
    """(5·V, 17) float64 LLFF rows: identity camera (OpenCV x right, y down, z forward → LLFF columns [down,
    right, back]), zero translation, hwf = (H, W, fx), bounds :data:`PLACEHOLDER_BOUNDS`."""
    m = np.zeros((3, 5))
    m[:, 0] = (0.0, 1.0, 0.0)  # down  = OpenCV y
    m[:, 1] = (1.0, 0.0, 0.0)  # right = OpenCV x
    m[:, 2] = (0.0, 0.0, -1.0)  # back = −OpenCV z
    m[:, 4] = (camera.height, camera.width, camera.K[0, 0])
    row = np.concatenate([m.ravel(), PLACEHOLDER_BOUNDS])
    return np.tile(row, (POSES_PER_VIEW * n_views, 1))


def groundtruth_scene(source: Any, layout: str | os.PathLike) -> Scene:
    """The ground truth of ``source`` (a Generated or a Scene with a trajectory or latent poses, and sharp
    images) on the real layout's per-view clock: latent poses at 25001·k µs after each exposure start (source
    ``ground-truth``), sharp images with blur views at t = 0 (the view clock) and novel views at −1."""
    from eigs.synth.export_e2nerf import _pose_fn

    scene: Scene = getattr(source, "scene", source)
    scene.require("sharp", path=str(layout), hint="the ground truth needs sharp images")
    starts = scene.frames.exposure_us[:, 0].astype(np.int64)
    view_t = REAL_BIN_US * np.arange(POSES_PER_VIEW, dtype=np.int64)
    pose_at = _pose_fn(source, scene)
    c2w = pose_at((starts[:, None] + view_t[None, :]).ravel()).reshape(scene.n_views, POSES_PER_VIEW, 4, 4)
    sh = scene.sharp
    t_us = np.where(sh.kind == 0, 0, -1).astype(np.int64)
    return Scene(
        name=scene.name,
        camera=scene.camera,
        channels=scene.channels,
        camera_response=scene.camera_response,
        synthetic=True,
        background=scene.background,
        contrast_threshold=scene.contrast_threshold,
        source=f"ground truth of {scene.source} for the e2nerf-real layout {Path(layout).name}",
        poses=Poses(c2w, np.tile(view_t, (scene.n_views, 1)), "ground-truth"),
        sharp=SharpImages(sh.images, sh.c2w, t_us, sh.kind, sh.view),
    )


def _write_image(path: Path, img: np.ndarray, fmt: str) -> None:
    import cv2

    bgr = img[..., 0] if img.shape[-1] == 1 else img[..., ::-1]
    params = [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY] if fmt == "jpg" else []
    if not cv2.imwrite(str(path), np.ascontiguousarray(bgr), params):
        raise EigsError(path, "could not write the image")


def write_e2nerf_real(
    source: Any,
    out_dir: str | os.PathLike,
    *,
    groundtruth: str | os.PathLike | None = None,
    image_format: str = "jpg",
) -> dict[str, Any]:
    """Write ``source`` (a :class:`eigs.synth.generate.Generated` or a :class:`eigs.scene.Scene` with frames,
    exposures, raw events and sharp images) to ``out_dir`` in the E²NeRF real layout (module docstring), and its
    ground truth to ``groundtruth`` (default ``<out_dir>.groundtruth.h5``; must lie outside ``out_dir``). Both
    writes are atomic. Returns ``{"n_views", "layout", "groundtruth", "counts"}`` (counts: (V, 4, H·W))."""
    import torch

    from eigs.scene import write_scene
    from eigs.util.atomic import atomic_path

    scene: Scene = getattr(source, "scene", source)
    if not isinstance(scene, Scene):
        raise EigsError(out_dir, f"cannot export a {type(source).__name__}; give a Generated or a Scene")
    if image_format not in IMAGE_FORMATS:
        raise EigsError(out_dir, f"image format must be one of {IMAGE_FORMATS}, got {image_format!r}")
    scene.require("frames", "exposure", "events", path=str(out_dir),
                  hint="the E²NeRF real layout needs blurry frames, exposures and raw events")
    if scene.events.view_index is None:
        raise EigsError(out_dir, "the events have no per-view exposure index")
    cam = scene.camera
    if not (np.isclose(cam.K[0, 0], cam.K[1, 1]) and np.isclose(cam.K[0, 2], cam.width / 2)
            and np.isclose(cam.K[1, 2], cam.height / 2)) or cam.has_distortion:
        raise EigsError(out_dir, "the LLFF layout keeps one focal length: needs fx = fy, principal point (W/2, H/2), "
                        "no distortion")
    out_dir = Path(out_dir)
    gt_path = Path(groundtruth) if groundtruth is not None else out_dir.with_name(out_dir.name + ".groundtruth.h5")
    if out_dir.resolve() in gt_path.resolve().parents:
        raise EigsError(gt_path, "the ground truth must lie outside the layout folder")
    counts = real_event_bins(scene)
    gt = groundtruth_scene(source, out_dir)
    n_views = scene.n_views
    with atomic_path(out_dir, directory=True) as tmp:
        (tmp / "images").mkdir()
        for i in range(n_views):
            _write_image(tmp / "images" / f"{POSES_PER_VIEW * i:03d}.{image_format}", scene.frames.blurry[i],
                         image_format)
        with open(tmp / "poses_bounds.npy", "wb") as fh:
            np.save(fh, placeholder_poses_bounds(n_views, cam))
        torch.save(torch.from_numpy(counts), tmp / "events.pt")
    write_scene(gt, gt_path)
    log.info("wrote E²NeRF real layout to %s (%d views, %s) and its ground truth to %s", out_dir, n_views,
             image_format, gt_path)
    return {"n_views": n_views, "layout": out_dir, "groundtruth": gt_path, "counts": counts}
