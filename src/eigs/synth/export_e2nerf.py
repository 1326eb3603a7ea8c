"""Write a scene in the E²NeRF *synthetic* on-disk layout (../shared/docs/e2nerf-dataset.md §2, §4, §5).

>>> from eigs.synth.export_e2nerf import write_e2nerf_synthetic
>>> write_e2nerf_synthetic(generated_or_scene, "out/toy_e2nerf")

Layout written (V training views, B = 4 bins, P = min(V, number of novel views) test pairs)::

    transform_train.json   camera_angle_x; frames[2i] = training view i, frames[2i+1] = novel view i (or a
                           filler when there is none); each frame's transform_matrix is a list of 4B + 2 = 18
                           Blender-axes camera-to-world matrices at times start_i + (j − 1)·Δ, j = 0..17,
                           Δ = exposure/(4B), so entries 1, 5, 9, 13, 17 are the B + 1 latent poses
    transform_test.json    2P frames: frames[2k] = blur view k (GT at transform_matrix[1], the first latent
                           pose), frames[2k+1] = novel view k (all 18 matrices equal: novel views are unshaken)
    train/r_{2i}.png       blurry frame of view i (RGBA, alpha 255), i = 0..V−1
    test/r_{j}.png         sharp ground truth of test frame j (RGBA, alpha 255), j = 0..2P−1
    events.pt              torch.save of a float64 tensor (V, B, H·W): signed net event count per pixel
                           (flat index y·W + x) per bin

Binning (documented in docs/synthetic.md): bin k of view i holds the raw events with
edges[i, k] ≤ t < edges[i, k+1], where edges[i] are the B + 1 latent times (start_i + k·exposure/B; the last
edge is the exposure end, so the bins cover exactly the view's exposure [start, end)). With
``include_pre_latent=True`` bin 0 also holds the events of [start_i − Δ, start_i), mimicking E²NeRF, whose bin
0 includes the 10 ms before latent pose 0. The edges used are written to both JSON files under
``"eigs"``/``"bin_edges_us"``; every frame also carries ``eigs_time_us`` (times of its matrices), ``eigs_kind``
(``train``, ``novel``, ``blur``, ``filler``) and ``eigs_view``. E²NeRF's loaders ignore these extra keys.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from eigs.errors import EigsError
from eigs.scene import Scene
from eigs.util.image import write_png

log = logging.getLogger(__name__)


def opencv_to_blender(c2w: np.ndarray) -> np.ndarray:
    """(..., 4, 4) OpenCV camera-to-world → Blender/OpenGL axes (camera y and z negated). Self-inverse."""
    out = np.array(c2w, dtype=np.float64, copy=True)
    out[..., :3, 1:3] *= -1.0
    return out


def _pose_fn(source: Any, scene: Scene):
    """A function times (N,) µs → (N, 4, 4) OpenCV c2w: the exact path of a Generated, else interpolation."""
    path = getattr(source, "path", None)
    if path is not None:
        return lambda t: path(np.asarray(t, dtype=np.float64))
    from eigs.synth.trajectory import interpolate_poses

    if scene.trajectory is not None:
        tr = scene.trajectory
        return lambda t: interpolate_poses(np.asarray(t), tr.t_us, tr.c2w)
    ps = scene.poses
    order = np.argsort(ps.latent_t_us.ravel(), kind="stable")
    t_all, c_all = ps.latent_t_us.ravel()[order], ps.latent_c2w.reshape(-1, 4, 4)[order]
    keep = np.concatenate([[True], np.diff(t_all) > 0])
    return lambda t: interpolate_poses(np.asarray(t), t_all[keep], c_all[keep])


def e2nerf_event_bins(
    scene: Scene, edges_us: np.ndarray, first_edge_us: np.ndarray | None = None
) -> np.ndarray:
    """E²NeRF's ``events.pt`` layout: signed net counts (V, B, H·W) float64 of the whole scene's raw events in
    bins [edges[v,k], edges[v,k+1]) (not :func:`eigs.edi.binning.bin_events`, which bins one view's events
    into (B, H, W) int32 for EDI).

    ``edges_us``: (V, B + 1) int64 increasing; ``first_edge_us``: optional (V,) replacement for edges[:, 0]
    (to widen bin 0 backwards)."""
    ev = scene.events
    cam = scene.camera
    v_n, b_n = edges_us.shape[0], edges_us.shape[1] - 1
    hw = cam.width * cam.height
    out = np.zeros((v_n, b_n, hw), np.float64)
    if ev is None or len(ev) == 0:
        return out
    for v in range(v_n):
        e = edges_us[v].astype(np.int64).copy()
        if first_edge_us is not None:
            e[0] = int(first_edge_us[v])
        lo, hi = np.searchsorted(ev.t, [e[0], e[-1]], side="left")
        t = ev.t[lo:hi]
        b = np.searchsorted(e, t, side="right") - 1  # e[k] ≤ t < e[k+1]
        idx = b * hw + ev.y[lo:hi].astype(np.int64) * cam.width + ev.x[lo:hi].astype(np.int64)
        out[v] = np.bincount(idx, weights=ev.p[lo:hi].astype(np.float64), minlength=b_n * hw).reshape(b_n, hw)
    return out


def _rgba(img: np.ndarray) -> np.ndarray:
    if img.shape[-1] == 1:
        img = np.repeat(img, 3, axis=-1)
    alpha = np.full(img.shape[:-1] + (1,), 255, np.uint8)
    return np.concatenate([img, alpha], axis=-1)


def write_e2nerf_synthetic(
    source: Any, out_dir: str | os.PathLike, *, include_pre_latent: bool = False
) -> dict[str, Any]:
    """Write ``source`` (a :class:`eigs.synth.generate.Generated` or a :class:`eigs.scene.Scene` with frames,
    exposures, raw events, latent poses and sharp images) to ``out_dir`` in the E²NeRF synthetic layout (see
    the module docstring). Atomic: the directory appears complete or not at all. Returns a summary dict
    (``n_views``, ``n_test``, ``bin_edges_us`` (V, B+1), ``matrix_times_us`` (V, 4B+2))."""
    import torch

    from eigs.util.atomic import atomic_path

    scene: Scene = getattr(source, "scene", source)
    if not isinstance(scene, Scene):
        raise EigsError(out_dir, f"cannot export a {type(source).__name__}; give a Generated or a Scene")
    scene.require("frames", "exposure", "events", "poses", "sharp", path=out_dir,
                  hint="the E²NeRF layout needs blurry frames, exposures, raw events, latent poses and sharp images")
    cam = scene.camera
    if not (np.isclose(cam.K[0, 0], cam.K[1, 1]) and np.isclose(cam.K[0, 2], cam.width / 2)
            and np.isclose(cam.K[1, 2], cam.height / 2)) or cam.has_distortion:
        raise EigsError(out_dir, "E²NeRF's synthetic layout needs fx = fy, principal point (W/2, H/2), no distortion")
    n_views = scene.n_views
    latent_t = scene.poses.latent_t_us
    n_bins = latent_t.shape[1] - 1
    if n_bins != 4:
        log.warning("E²NeRF expects 4 bins (5 latent poses); writing %d", n_bins)
    exposure = scene.frames.exposure_us
    starts = exposure[:, 0].astype(np.int64)
    # matrix entry j (j = 0..4B+1) at start + (j − 1)·Δ with Δ = (latent spacing)/4, as float µs
    spacing = (latent_t[:, -1] - latent_t[:, 0]) / n_bins
    delta = spacing / 4.0
    j = np.arange(4 * n_bins + 2)
    mat_t = latent_t[:, :1] + (j[None, :] - 1) * delta[:, None]
    pose_at = _pose_fn(source, scene)
    mats = opencv_to_blender(pose_at(mat_t.ravel()).reshape(n_views, j.size, 4, 4))
    # entries 1, 5, ..., 4B+1 are exactly the latent poses
    mats[:, 1::4] = opencv_to_blender(scene.poses.latent_c2w)

    sh = scene.sharp
    blur_gt = {int(sh.view[i]): i for i in range(len(sh.kind)) if sh.kind[i] == 0 and sh.view[i] >= 0}
    novel = np.flatnonzero(sh.kind == 1)
    n_pairs = min(n_views, novel.size)
    missing = [v for v in range(n_pairs) if v not in blur_gt]
    if missing:
        raise EigsError(out_dir, f"no blur-view ground truth for view(s) {missing[:5]}")

    first_edge = np.rint(starts - delta).astype(np.int64) if include_pre_latent else None
    counts = e2nerf_event_bins(scene, latent_t, first_edge)
    edges = latent_t.astype(np.int64).copy()
    if first_edge is not None:
        edges[:, 0] = first_edge

    angle_x = float(2.0 * np.arctan(cam.width / (2.0 * cam.K[0, 0])))
    ext = {
        "bin_edges_us": edges.tolist(),
        "bins": "bin k holds events with bin_edges_us[v][k] <= t < bin_edges_us[v][k+1] (µs)",
        "exposure_us": exposure.tolist(),
        "camera_response": scene.camera_response,
        "width": cam.width,
        "height": cam.height,
        "scene": scene.name,
        "contrast_threshold": scene.contrast_threshold,
        "background": None if scene.background is None else np.asarray(scene.background).tolist(),
    }

    def frame(path: str, m: np.ndarray, t: np.ndarray, kind: str, view: int) -> dict[str, Any]:
        return {"file_path": path, "transform_matrix": m.tolist(), "eigs_time_us": [float(x) for x in t],
                "eigs_kind": kind, "eigs_view": view}

    train_frames, test_frames = [], []
    for i in range(n_views):
        train_frames.append(frame(f"./train/r_{2 * i}", mats[i], mat_t[i], "train", i))
        if i < novel.size:
            m = opencv_to_blender(np.repeat(sh.c2w[novel[i]][None], j.size, axis=0))
            train_frames.append(frame(f"./test/r_{2 * i + 1}", m, np.full(j.size, -1.0), "novel", -1))
        else:
            m = np.repeat(mats[i, 1][None], j.size, axis=0)
            train_frames.append(frame("", m, np.full(j.size, float(latent_t[i, 0])), "filler", i))
    for k in range(n_pairs):
        test_frames.append({**train_frames[2 * k], "file_path": f"./test/r_{2 * k}", "eigs_kind": "blur"})
        test_frames.append(train_frames[2 * k + 1])

    out_dir = Path(out_dir)
    with atomic_path(out_dir, directory=True) as tmp:
        (tmp / "train").mkdir()
        (tmp / "test").mkdir()
        for name, frames in (("transform_train.json", train_frames), ("transform_test.json", test_frames)):
            (tmp / name).write_text(json.dumps({"camera_angle_x": angle_x, "frames": frames, "eigs": ext}))
        for i in range(n_views):
            write_png(tmp / "train" / f"r_{2 * i}.png", _rgba(scene.frames.blurry[i]))
        for k in range(n_pairs):
            write_png(tmp / "test" / f"r_{2 * k}.png", _rgba(sh.images[blur_gt[k]]))
            write_png(tmp / "test" / f"r_{2 * k + 1}.png", _rgba(sh.images[novel[k]]))
        torch.save(torch.from_numpy(counts), tmp / "events.pt")
    log.info("wrote E²NeRF synthetic layout to %s (%d views, %d test frames)", out_dir, n_views, 2 * n_pairs)
    return {"n_views": n_views, "n_test": 2 * n_pairs, "bin_edges_us": edges, "matrix_times_us": mat_t}
