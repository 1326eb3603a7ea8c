"""Evaluate one run folder: render, quantise to 8 bits, save the PNGs, score them.

Synthetic scenes (ground-truth sharp images and ``sfm/test_cameras.h5``): every test camera is rendered, and PSNR,
SSIM in every lineage (:data:`eigs.metrics.pixel.SSIM_MODES`), LPIPS-alex, the sharpness (the high-frequency power
ratio, :func:`eigs.metrics.sharpness.hf_ratio`) and the coherence (the ground truth's high-frequency detail the render
reproduces, :func:`eigs.metrics.sharpness.hf_coherence`: noise does not raise it) are computed against the ground
truth, separately for blur views (kind 0: a training view's ground truth at its first latent time, the reference
pose) and novel views (kind 1). Cameras come only from ``test_cameras.h5`` (docs/sfm.md, "Test cameras"). A view
whose ground truth is flat above 0.25 cycles/pixel has neither of the last two: it is counted in
``sharpness_undefined`` and ``coherence_undefined``, left out of their means (empty cells in ``per_image.csv``) and
logged, never scored silently.

Scenes without ground truth (and, with ``hidden_ground_truth``, simulated recordings through the real-data path
whose ground truth was kept aside for scoring, beside their test-camera scores): BRISQUE of renders at the training
views' reference poses (latent k = 0 of ``poses.h5``) and on a render path (:func:`eigs.util.cameras.render_path`:
an ellipse across the viewing direction for forward-facing captures, else an orbit), as E²NeRF's real protocol
(blur views plus a render path). An image whose BRISQUE is undefined (e.g. constant: a path frame that misses the
scene) is counted in ``brisque_undefined`` and left out of the mean, never scored silently.

Every run also reports training seconds and steps (``config.json``), the number of Gaussians (``n_voxels`` for a
field run, whose ``n_gaussians`` is null) and the test-time frames per second (render only, after a warm-up render).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from eigs.artifacts import run as run_folder
from eigs.errors import EigsError
from eigs.evaluate.options import EvaluateOptions

log = logging.getLogger("eigs.evaluate")

SSIM_TABLE_MODE = "3dgs"  # the lineage the tables show (docs/metrics.md)
LPIPS_NET = "alex"
SHARPNESS = "sharpness"  # the high-frequency power ratio (eigs.metrics.sharpness.hf_ratio)
COHERENCE = "coherence"  # the ground truth's high-frequency detail reproduced (eigs.metrics.sharpness.hf_coherence)
BAND_SCORES = (SHARPNESS, COHERENCE)  # undefined (NaN) where the ground truth is flat in the band
KIND_NAMES = {0: "blur", 1: "novel"}


def read_run_config(run_dir: Path) -> dict[str, Any]:
    """``config.json`` of a finished run (``train``, ``inputs``, ``run`` sections)."""
    doc = run_folder.read_config(run_dir)
    path = run_dir / run_folder.CONFIG
    try:
        int(doc["train"]["sh_degree"])
        float(doc["run"]["train_seconds"])
    except (ValueError, KeyError, TypeError) as err:
        raise EigsError(path, f"unreadable run config ({err})") from None
    return doc


def finite_or_none(v: float) -> float | None:
    """JSON-safe number: non-finite values become null (the caller logs why)."""
    return float(v) if math.isfinite(v) else None


def _mean(values: list[float]) -> float:
    return float(np.mean(values)) if values else math.nan


def score_pair(img: np.ndarray, ref: np.ndarray, resources: str | None) -> dict[str, float]:
    """PSNR, SSIM in every lineage, LPIPS-alex, the sharpness and the coherence of one uint8 render against its uint8
    ground truth; the last two are NaN where the ground truth is flat in their band (the caller counts and logs it)."""
    from eigs.metrics.perceptual import lpips
    from eigs.metrics.pixel import SSIM_MODES, psnr, ssim
    from eigs.metrics.sharpness import UndefinedSharpness, hf_scores

    out = {"psnr": psnr(img, ref)}
    for mode in SSIM_MODES:
        out[f"ssim_{mode}"] = ssim(img, ref, mode)
    out[f"lpips_{LPIPS_NET}"] = lpips(img, ref, LPIPS_NET, resources)
    try:
        out[SHARPNESS], out[COHERENCE] = hf_scores(img, ref)
    except UndefinedSharpness:
        out[SHARPNESS] = out[COHERENCE] = math.nan
    return out


def group_means(name: str, per: list[dict[str, float]]) -> dict[str, Any]:
    """The ``name`` group of metrics.json from its views' scores: ``n``, the mean of each score, and for the sharpness
    and the coherence ``<key>_undefined``, the views without one (flat ground truth), which its mean leaves out."""
    out: dict[str, Any] = {"n": len(per)}
    for k in per[0]:
        values = [p[k] for p in per]
        if k in BAND_SCORES:
            defined = [v for v in values if math.isfinite(v)]
            if len(defined) < len(values):
                log.warning("%s: %d of %d views have a flat ground truth; %s undefined for them, left out of the "
                            "mean", name, len(values) - len(defined), len(values), k)  # fmt: skip
            out[k], out[f"{k}_undefined"] = _mean(defined), len(values) - len(defined)
        else:
            out[k] = _mean(values)
    return out


def evaluate_run(
    run_dir: str | Path,
    scene_path: str | Path,
    sfm_dir: str | Path,
    output: str | Path,
    *,
    resources: str | None = None,
    path_frames: int = EvaluateOptions.path_frames,
    device: str = "auto",
    hidden_ground_truth: bool = False,
    test_pose_iters: int = EvaluateOptions.test_pose_iters,
) -> dict[str, Any]:
    """Evaluate ``run_dir``; write ``output`` (metrics.json), ``per_image.csv`` and ``renders/`` beside it.

    Returns the metrics document (also written). Layout of ``renders/``: synthetic scenes ``blur/``, ``novel/``
    (renders) and ``gt_blur/``, ``gt_novel/`` (ground truth), files ``{row:04d}.png`` with the row of the image in
    the scene's ``gt/sharp``; other scenes ``train/{view:04d}.png`` and ``path/{i:04d}.png``.
    ``hidden_ground_truth``: the scene is a recording through the real-data path whose ground truth was kept aside
    for scoring (``config/davis346.yaml``): both are scored, the test cameras and the BRISQUE sets, and the
    metrics say so (``hidden_ground_truth``).
    ``test_pose_iters`` > 0: the second protocol as well (:mod:`eigs.evaluate.test_poses`): every test camera refined
    against its image on the frozen model, scored into the groups ``novel_pose_opt`` and ``blur_pose_opt`` (renders
    in ``renders/novel_pose_opt/`` …) beside today's, and the refinements' sizes under ``test_pose_opt``.
    """
    import torch

    from eigs.artifacts.poses import METHODS, read_poses, read_test_cameras
    from eigs.evaluate.renderer import CloudTensors, load_model, render_uint8
    from eigs.scene import read_scene
    from eigs.util.atomic import atomic_path
    from eigs.util.image import write_png

    run_dir, sfm_dir, output = Path(run_dir), Path(sfm_dir), Path(output)
    doc = read_run_config(run_dir)
    train, facts = doc["train"], doc["run"]
    scene = read_scene(scene_path, events=False)
    if device == "cuda" and not torch.cuda.is_available():
        raise EigsError("--device", "cuda requested but no CUDA device is available")
    dev = torch.device("cuda" if device == "cuda" or (device == "auto" and torch.cuda.is_available()) else "cpu")
    g = load_model(run_dir, int(train["sh_degree"]), int(scene.channels), dev)
    bg = scene.background if scene.background is not None else np.zeros(scene.channels)
    poses = read_poses(sfm_dir)
    w, h = poses.width, poses.height
    if (w, h) != (scene.camera.width, scene.camera.height):
        raise EigsError(sfm_dir, f"poses are {w}x{h}, the scene {scene.camera.width}x{scene.camera.height}")
    tc_path = sfm_dir / "test_cameras.h5"
    tc = read_test_cameras(tc_path) if (scene.sharp is not None and tc_path.exists()) else None
    has_gt = tc is not None and len(tc) > 0

    rows: list[dict[str, Any]] = []
    groups: dict[str, dict[str, Any]] = {}
    path_kind = ""
    times: list[float] = []
    pose_opt: dict[str, Any] | None = None
    if test_pose_iters > 0 and not isinstance(g, CloudTensors):
        log.warning("test-pose refinement is for Gaussian models; %s is a field run: scored by today's protocol only",
                    run_dir)  # fmt: skip
    renders_dir = output.parent / "renders"
    with atomic_path(renders_dir, directory=True) as tmp:
        if has_gt:
            assert tc is not None and scene.sharp is not None
            images, times = render_uint8(g, tc.c2w, tc.K, w, h, bg)
            for kind, name in KIND_NAMES.items():
                sel = np.nonzero(tc.kind == kind)[0]
                per: list[dict[str, float]] = []
                for i in sel:
                    ref = np.asarray(scene.sharp.images[int(tc.index[i])])
                    write_png(tmp / f"gt_{name}" / f"{int(tc.index[i]):04d}.png", ref)
                    per.append(_score_test_image(images[i], ref, tc, i, name, tmp, resources, rows))
                if per:
                    groups[name] = group_means(name, per)
            if test_pose_iters > 0 and isinstance(g, CloudTensors):
                pose_opt = _score_refined_cameras(g, tc, scene, w, h, bg, test_pose_iters, tmp, resources, rows,
                                                  groups)  # fmt: skip
        if not has_gt or hidden_ground_truth:
            if not poses.valid[:, 0].any():
                raise EigsError(sfm_dir, "no training view has a valid reference pose (latent k = 0)")
            t, path_kind = _score_brisque(g, poses, w, h, bg, path_frames, tmp, resources, rows, groups)
            times = times or t
            if not any(math.isfinite(r.get("brisque", math.nan)) for r in rows):
                log.warning("BRISQUE is undefined for every render of %s", run_dir)

    fps = len(times) / sum(times) if times and sum(times) > 0 else math.nan
    metrics: dict[str, Any] = {}
    for name, grp in groups.items():
        clean = {}
        for k, v in grp.items():
            if isinstance(v, float) and not math.isfinite(v):
                log.warning("%s %s is %s; written as null", name, k, v)
            clean[k] = finite_or_none(v) if isinstance(v, float) else v
        metrics[name] = clean
    result = {
        "format": "eigs-metrics",
        "version": 1,
        "run_dir": str(run_dir),
        "run": run_dir.name,
        "method": train.get("method"),
        "method_options": facts.get("method_options", {}),
        "scene": scene.name,
        "bins": int(poses.n_latent - 1),
        "ground_truth": bool(has_gt),
        "hidden_ground_truth": bool(hidden_ground_truth),
        "ssim_table_mode": SSIM_TABLE_MODE,
        "lpips_net": LPIPS_NET,
        "metrics": metrics,
        "train_seconds": float(facts["train_seconds"]),
        "steps": int(train.get("steps", 0)),
        "n_gaussians": len(g) if isinstance(g, CloudTensors) else None,
        "n_voxels": None if isinstance(g, CloudTensors) else g.n_voxels,
        "fps": finite_or_none(fps),
        "render_ms": finite_or_none(1e3 * float(np.mean(times))) if times else None,
        "frames_timed": len(times),
        "device": str(dev),
        "width": int(w),
        "height": int(h),
        "test_cameras": (
            {v: int(np.sum(tc.method == k)) for k, v in METHODS.items()} if has_gt and tc is not None else None
        ),
        "path": {"kind": path_kind, "frames": int(path_frames)} if path_kind else None,
        "motion": motion_metrics(run_dir, scene, poses.timestamps_us),
        "cameras": camera_metrics(run_dir, scene, poses.timestamps_us),
        "test_pose_opt": pose_opt,
    }
    with atomic_path(output.parent / "per_image.csv") as tmp:
        tmp.write_text(per_image_csv(rows))
    with atomic_path(output) as tmp:
        tmp.write_text(json.dumps(result, indent=2, allow_nan=False) + "\n")
    return result


def _score_test_image(
    image: np.ndarray, ref: np.ndarray, tc: Any, i: int, name: str, tmp: Path, resources: str | None,
    rows: list[dict[str, Any]],
) -> dict[str, float]:
    """Test camera ``i``'s render ``image`` written to ``tmp/<name>/`` and scored against ``ref``: its row appended
    to ``rows`` (per_image.csv), its scores returned."""
    from eigs.artifacts.poses import METHODS
    from eigs.util.image import write_png

    row = int(tc.index[i])
    write_png(tmp / name / f"{row:04d}.png", image)
    s = score_pair(image, ref, resources)
    rows.append({"set": name, "image": f"{row:04d}.png", "view": int(tc.view[i]),
                 "camera": METHODS.get(int(tc.method[i]), "?"), **s})  # fmt: skip
    return s


def _score_refined_cameras(
    g: Any, tc: Any, scene: Any, w: int, h: int, bg: np.ndarray, iters: int, tmp: Path, resources: str | None,
    rows: list[dict[str, Any]], groups: dict[str, dict[str, Any]],
) -> dict[str, Any]:
    """The second protocol (:mod:`eigs.evaluate.test_poses`): each test camera refined on the frozen model against its
    ground truth, rendered there and scored into ``<set>_pose_opt``; returns the protocol's facts and the sizes of
    the refinements (rotation in degrees, translation in scene units: medians and maxima)."""
    from eigs.evaluate.renderer import render_uint8
    from eigs.evaluate.test_poses import LR, refine_test_camera

    rot, trans, before, after = [], [], [], []
    for kind, base in KIND_NAMES.items():
        name = f"{base}_pose_opt"
        per: list[dict[str, float]] = []
        for i in np.nonzero(tc.kind == kind)[0]:
            ref = np.asarray(scene.sharp.images[int(tc.index[i])])
            refined, e0, e1 = refine_test_camera(g, tc.c2w[i], tc.K[i], ref, w, h, bg, iters)
            rel = np.linalg.inv(np.asarray(tc.c2w[i], np.float64)) @ refined
            rot.append(math.degrees(math.acos(float(np.clip((np.trace(rel[:3, :3]) - 1) / 2, -1.0, 1.0)))))
            trans.append(float(np.linalg.norm(rel[:3, 3])))
            before.append(e0)
            after.append(e1)
            image = render_uint8(g, refined[None], np.asarray(tc.K[i])[None], w, h, bg)[0][0]
            per.append(_score_test_image(image, ref, tc, i, name, tmp, resources, rows))
        if per:
            groups[name] = group_means(name, per)
    return {
        "protocol": "test cameras refined on the frozen model against their images (eigs.evaluate.test_poses)",
        "iters": int(iters),
        "lr": LR,
        "cameras": len(rot),
        "rotation_deg_median": finite_or_none(float(np.median(rot))) if rot else None,
        "rotation_deg_max": finite_or_none(float(np.max(rot))) if rot else None,
        "translation_median": finite_or_none(float(np.median(trans))) if trans else None,
        "translation_max": finite_or_none(float(np.max(trans))) if trans else None,
        "l1_before_mean": finite_or_none(_mean(before)),
        "l1_after_mean": finite_or_none(_mean(after)),
    }


def _score_brisque(
    g: Any,
    poses: Any,
    w: int,
    h: int,
    bg: np.ndarray,
    path_frames: int,
    tmp: Path,
    resources: str | None,
    rows: list[dict[str, Any]],
    groups: dict[str, dict[str, Any]],
) -> tuple[list[float], str]:
    """BRISQUE of renders at the training views' reference poses (``train``) and on a render path (``path``), and
    of both (``all``): PNGs under ``tmp``, rows and groups appended. Returns (render seconds, path kind)."""
    from eigs.evaluate.renderer import render_uint8
    from eigs.metrics.noreference import brisque
    from eigs.util.cameras import render_path
    from eigs.util.image import write_png

    valid = poses.valid[:, 0]
    views = np.nonzero(valid)[0]
    path, path_kind = render_path(poses.c2w[valid, 0], path_frames)
    sets = {
        "train": (poses.c2w[valid, 0], [f"{v:04d}.png" for v in views]),
        "path": (path, [f"{i:04d}.png" for i in range(path_frames)]),
    }
    times: list[float] = []
    mine: list[dict[str, Any]] = []
    for name, (c2w, names) in sets.items():
        if len(c2w) == 0:
            continue
        ks = np.repeat(np.asarray(poses.K)[None], len(c2w), axis=0)
        images, t = render_uint8(g, c2w, ks, w, h, bg)
        times += t
        scores, undefined = [], 0
        for img, fname in zip(images, names, strict=True):
            write_png(tmp / name / fname, img)
            try:
                b = brisque(img, resources)
            except EigsError as err:
                if "model" in str(err).lower() or "resources" in str(err).lower():
                    raise
                undefined += 1
                log.warning("%s/%s: BRISQUE undefined (%s); left out of the mean", name, fname, err)
                b = math.nan
            else:
                scores.append(b)
            mine.append({"set": name, "image": fname, "brisque": b})
        groups[name] = {"n": len(images), "brisque": _mean(scores), "brisque_undefined": undefined}
    all_scores = [r["brisque"] for r in mine if math.isfinite(r["brisque"])]
    groups["all"] = {"n": len(mine), "brisque": _mean(all_scores), "brisque_undefined": len(mine) - len(all_scores)}
    rows += mine
    return times, path_kind


def _ground_truth_to_score(file: Path, scene: Any, timestamps_us: np.ndarray) -> tuple[np.ndarray, str] | None:
    """The ground-truth poses (V, L, 4, 4) at the latent times and their source, to score the run folder's ``file``
    (``motion.npz``, ``cameras.npz``) against; None when the run has no such file or the scene no ground truth."""
    from eigs.scene.truth import latent_poses_at

    if not file.exists():
        return None
    got = latent_poses_at(scene, timestamps_us)
    if got is None:
        log.info("%s: the scene has no ground-truth poses; %s not scored", file.parent, file.name)
    return got


def motion_metrics(run_dir: Path, scene: Any, timestamps_us: np.ndarray) -> dict[str, Any] | None:
    """The run's motion within the exposures against the ground-truth camera motion (:mod:`eigs.metrics.motion`):
    None when the run models no motion (no ``motion.npz``) or the scene has no ground-truth poses."""
    from eigs.artifacts.motion import read_motion
    from eigs.artifacts.run import MOTION as FILE_NAME
    from eigs.metrics.motion import motion_errors

    got = _ground_truth_to_score(run_dir / FILE_NAME, scene, timestamps_us)
    if got is None:
        return None
    gt, source = got
    m = read_motion(run_dir)
    if gt.shape[:2] != (m.displacement.shape[0], m.displacement.shape[1] + 1):
        raise EigsError(run_dir / FILE_NAME, f"motion of {m.displacement.shape[:2]} views × latents does not match "
                        f"the ground truth's {gt.shape[:2]}")  # fmt: skip
    errs = motion_errors(m.points, m.displacement, m.reference_c2w, gt, m.views, m.camera_c2w)
    return {"ground_truth": source, "points": int(m.points.shape[0]),
            **{k: finite_or_none(v) if isinstance(v, float) else v for k, v in errs.items()}}  # fmt: skip


def camera_metrics(run_dir: Path, scene: Any, timestamps_us: np.ndarray) -> dict[str, Any] | None:
    """The run's training cameras before and after camera refinement against the ground truth at the views' reference
    times (latent k = 0): ATE (RMSE of the centres after a Sim(3) fit of each set on its own, and in % of the
    ground-truth extent) and rotation errors (:func:`eigs.metrics.trajectory.trajectory_accuracy`), over the views
    trained with a pose and a ground truth. None when the run did not refine its cameras (no ``cameras.npz``) or the
    scene has no ground-truth poses."""
    from eigs.artifacts.cameras import read_refined_cameras
    from eigs.artifacts.run import CAMERAS
    from eigs.metrics.trajectory import extent, trajectory_accuracy

    got = _ground_truth_to_score(run_dir / CAMERAS, scene, timestamps_us)
    if got is None:
        return None
    gt, source = got
    cams = read_refined_cameras(run_dir)
    if gt.shape[0] != cams.views.shape[0]:
        raise EigsError(run_dir / CAMERAS, f"cameras of {cams.views.shape[0]} views do not match the ground truth's "
                        f"{gt.shape[0]}")  # fmt: skip
    gt0 = gt[:, 0]
    use = cams.views & np.all(np.isfinite(gt0), axis=(1, 2))
    if int(use.sum()) < 3:
        log.info("%s: %d trained views with ground truth, 3 needed for a Sim(3); refined cameras not scored",
                 run_dir, int(use.sum()))  # fmt: skip
        return None
    ext = extent(gt0[use][:, :3, 3])
    out: dict[str, Any] = {"ground_truth": source, "views": int(use.sum())}
    keys = ("ate_percent_of_extent", "rotation_error_deg_median", "rotation_error_deg_max")
    for name, c2w in (("before", cams.before), ("after", cams.after)):
        acc = trajectory_accuracy(c2w[use], gt0[use], gt_extent=ext).summary()
        out[name] = {k: finite_or_none(acc[k]) for k in keys}
    turn = np.linalg.norm(cams.twist[use, :3], axis=1)
    out["correction_deg_median"] = float(np.degrees(np.median(turn)))
    return out


def per_image_csv(rows: list[dict[str, Any]]) -> str:
    """One CSV row per scored image (empty cells for NaN)."""
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if isinstance(v, float) and not math.isfinite(v) else v) for k, v in r.items()})
    return buf.getvalue()
