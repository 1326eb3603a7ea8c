"""The SfM stage: scene + EDI latent frames → ``sfm/`` (COLMAP model, poses.h5, test_cameras.h5, report.json). Mode
resample (another B's finished SfM read at this B's latent times: resample.py) writes the same files from that SfM
without COLMAP. Phases otherwise: choose the mode → features → matching → mapping (COLMAP mode) or fixed-pose
triangulation (given mode) → registration check → canonical frame → fill unregistered latents within their view →
accuracy against ground truth (accuracy.py) → test cameras (testcams.py) → write (report.json and report.png:
report.py).
See docs/sfm.md.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.sfm.accuracy import ground_truth_accuracy
from eigs.sfm.options import MODES, ColmapOptions, SfmConfig
from eigs.sfm.report import write_report
from eigs.sfm.testcams import place_test_cameras

log = logging.getLogger(__name__)


class _Timer:
    def __init__(self) -> None:
        self.times: dict[str, float] = {}

    def __call__(self, name: str):
        timer = self

        class _Ctx:
            def __enter__(self):
                self.t0 = time.perf_counter()
                log.info("%s …", name)

            def __exit__(self, *exc):
                timer.times[name] = round(time.perf_counter() - self.t0, 3)

        return _Ctx()


def resolve_mode(cfg: SfmConfig, scene, path: str) -> tuple[str, str]:
    """``(mode, reason)``; raises when ``given`` is requested but the scene has no poses."""
    if cfg.mode not in MODES:
        raise EigsError(None, f"unknown mode {cfg.mode!r} ({', '.join(MODES)})")
    if cfg.mode == "resample":
        if not cfg.base:
            raise EigsError(path, "mode resample needs the scene's SfM at another B (sfm: base, or --from DIR)")
        return "resample", f"requested: the latent poses of {cfg.base} at this B's latent times"
    if cfg.mode == "model":
        if not cfg.path:
            raise EigsError(path, "mode model needs the COLMAP model directory (sfm: path, or --model DIR)")
        return "model", f"requested: the poses of the COLMAP model {cfg.path}"
    has_gt = scene.poses is not None and scene.poses.source == "ground-truth"
    if cfg.mode == "given":
        if scene.poses is None and scene.trajectory is None:
            raise EigsError(path, "--mode given: the scene has no latent poses and no trajectory (use --mode colmap)")
        return "given", "requested"
    if cfg.mode == "colmap":
        return "colmap", "requested"
    if has_gt and cfg.allow_given:
        return "given", "auto: the scene's latent poses are ground truth and given poses are allowed"
    if has_gt:
        return "colmap", "auto: the scene has ground-truth poses but given poses are not allowed"
    return "colmap", "auto: the scene has no ground-truth latent poses"


def _remedies(mode: str) -> str:
    tips = [
        "more latent frames (raise the number of bins, `edi: bins:`)",
        "an estimated contrast threshold for EDI (sharper latent frames)",
        "a lower `sfm: min_registered_fraction`",
    ]
    if mode == "colmap":
        tips.append("given poses (`--mode given`) when the scene has them")
        tips.append("another matcher (`--matcher exhaustive`) or `--global-mapping`")
    return "; ".join(tips)


@dataclass
class _Latents:
    """The latent images given to COLMAP: one per sharp view, B + 1 per other view."""

    slots: list[tuple[int, int]]  # (view, latent index) of each image
    names: list[str]  # file names, ``latent_png_name(v, k)``
    view_of_name: dict[str, int]
    n_views: int
    per_view: int  # L = B + 1

    @classmethod
    def of(cls, sharp: np.ndarray, n_views: int, per_view: int) -> _Latents:
        from eigs.artifacts.edi import latent_png_name

        slots = [(v, k) for v in range(n_views) for k in (range(1) if sharp[v] else range(per_view))]
        names = [latent_png_name(v, k) for v, k in slots]
        view_of_name = {n: v for (v, _k), n in zip(slots, names, strict=True)}
        return cls(slots, names, view_of_name, n_views, per_view)


def run_sfm(
    scene_path: str | os.PathLike,
    edi_path: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    latent_dir: str | os.PathLike | None = None,
    cfg: SfmConfig | None = None,
) -> dict:
    """Run the stage and write ``out_dir`` atomically. Returns the report (also in ``report.json``).

    Phases (one function each): read inputs → mode → latent images → features → matching and poses (given:
    guided matching + fixed-pose triangulation; COLMAP: matching + mapping + sibling check) → registration check
    → canonical frame → fill unregistered latents → drop single-view points → accuracy → test cameras → write.
    """
    from eigs.sfm import colmap as cm
    from eigs.util.atomic import atomic_path

    cfg = cfg or SfmConfig()
    cm.quiet(cfg.verbose)
    timer = _Timer()
    scene_path, edi_path, out_dir = Path(scene_path), Path(edi_path), Path(out_dir)
    scene, edi = _read_inputs(scene_path, edi_path, timer)
    mode, reason = resolve_mode(cfg, scene, str(scene_path))
    lat = _Latents.of(edi.sharp, edi.n_views, edi.n_bins + 1)
    log.info("mode: %s (%s); %d views × %d latent frames", mode, reason, lat.n_views, lat.per_view)
    report: dict = {
        "scene": scene.name,
        "mode": mode,
        "mode_reason": reason,
        "views": lat.n_views,
        "latent_per_view": lat.per_view,
        "sharp_views": [int(v) for v in np.flatnonzero(edi.sharp)],
    }
    if mode == "resample":
        return _run_resample(scene, edi, out_dir, cfg, timer, report)
    if mode == "model":
        return _run_model(scene, edi, lat, latent_dir, edi_path, out_dir, cfg, timer, report)
    with atomic_path(out_dir, directory=True) as tmp:
        work = tmp / "work"
        work.mkdir()
        ldir = _latent_images(latent_dir, edi_path, lat, scene.camera, work)
        db = work / "database.db"
        name_to_id, px = _features(db, ldir, lat, scene.camera, cfg.colmap, timer, report)
        if mode == "given":
            rec, rejected = _given_reconstruction(
                scene, scene_path, edi, db, ldir, work, lat, name_to_id, px, cfg, timer, report
            )
        else:
            rec, rejected = _colmap_reconstruction(db, ldir, work, lat, px, cfg, timer, report)
        raw, registered = _registration(rec, lat, edi.sharp, rejected, mode, cfg, out_dir, report)
        if mode == "colmap":
            raw, registered = _self_check(rec, raw, registered, edi.timestamps_us, lat, cfg, out_dir, report)
        canon, c2w = _canonical_frame(rec, raw, registered, report)
        c2w, interpolated = _fill_unregistered(c2w, registered, edi.timestamps_us, cfg, report)
        _drop_points(rec, lat, report)
        gt, est_to_gt = ground_truth_accuracy(scene, edi, c2w, registered, report)
        tc = None
        if scene.sharp is not None and len(scene.sharp.t_us):
            with timer("test cameras"):
                tc, report["test_cameras"] = place_test_cameras(
                    scene, rec, db, work, mode, canon, est_to_gt, cfg, cfg.colmap
                )
        _write_outputs(
            tmp, rec, scene, edi, c2w, registered, interpolated, mode, canon, tc, gt, est_to_gt, cfg, timer, report
        )
        if cfg.keep_work:
            log.info("work files kept in %s", out_dir / "work")
        else:
            shutil.rmtree(work, ignore_errors=True)
    log.info("wrote %s", out_dir)
    return report


def _read_inputs(scene_path: Path, edi_path: Path, timer: _Timer):
    """The scene (without events) and the EDI result (without latent frames); checks they agree."""
    from eigs.artifacts.edi import read_edi
    from eigs.scene import read_scene

    with timer("read inputs"):
        scene = read_scene(scene_path, events=False)
        edi = read_edi(edi_path, latent=False)
    if edi.n_views != scene.n_views:
        raise EigsError(edi_path, f"EDI has {edi.n_views} views but the scene {scene.n_views} (rerun edi)")
    if edi.n_views == 0:
        raise EigsError(scene_path, "the scene has no training views")
    return scene, edi


def _latent_images(latent_dir, edi_path: Path, lat: _Latents, cam, work: Path) -> Path:
    """The directory of latent PNGs: ``latent_dir`` (default: next to the EDI file) when it holds every image,
    else written from the EDI file into ``work/latent``. Checks the image size against the camera."""
    import cv2

    from eigs.artifacts.edi import read_edi, write_latent_pngs

    ldir = Path(latent_dir) if latent_dir is not None else edi_path.parent / "latent"
    if not all((ldir / n).is_file() for n in lat.names):
        log.info("latent PNGs not found in %s: writing them from %s", ldir, edi_path)
        ldir = work / "latent"
        write_latent_pngs(read_edi(edi_path).latent, ldir, lat.slots)
    probe = cv2.imread(str(ldir / lat.names[0]), cv2.IMREAD_UNCHANGED)
    if probe is None or probe.shape[:2] != (cam.height, cam.width):
        got = "unreadable" if probe is None else f"{probe.shape[1]}×{probe.shape[0]}"
        raise EigsError(ldir / lat.names[0], f"latent frame is {got}, the camera is {cam.width}×{cam.height}")
    return ldir


def _features(db: Path, ldir: Path, lat: _Latents, cam, opts: ColmapOptions, timer: _Timer, report: dict):
    """SIFT features of every latent image into ``db``: (name → COLMAP image id, pixel scale of the thresholds)."""
    from eigs.sfm import colmap as cm

    with timer("features"):
        name_to_id = cm.extract(db, ldir, lat.names, cam.K, cam.width, cam.height, cam.distortion, db.parent, opts)
    report["feature_scale"] = cm.feature_scale(cam.width, cam.height, opts.feature_scale)
    report["threads"] = {  # docs/sfm.md, "Reproducibility"
        "features_and_matching": opts.num_threads,
        "mapping_and_bundle_adjustment": cm.MAPPER_THREADS,
        "verification_seed": cm.verification_seed(opts),
    }
    return name_to_id, cm.pixel_scale(opts, cam.width, cam.height)


def _run_model(scene, edi, lat, latent_dir, edi_path, out_dir, cfg, timer, report) -> dict:
    """Model mode (eigs.sfm.model): the poses of the user's COLMAP model, matched to the views by name; its points
    when it has some, else points triangulated from the latent frames at those poses (the given-mode path). No
    mapping, no registration; test cameras from the Sim(3) to ground truth when the scene has some."""
    from dataclasses import replace

    from eigs.sfm.model import model_poses
    from eigs.util.atomic import atomic_path

    with timer("read model"):
        mp = model_poses(cfg.path, scene, edi.timestamps_us, edi.sharp, cfg.intrinsics_tolerance)
    report["model"] = mp.report
    registered = np.ones((lat.n_views, lat.per_view), bool)
    report["registration"] = {"images": len(lat.names), "registered": len(lat.names), "fraction": 1.0,
                              "unregistered": [], "rejected_far_from_view": []}  # fmt: skip
    with atomic_path(out_dir, directory=True) as tmp:
        work = tmp / "work"
        work.mkdir()
        if mp.reconstruction.num_points3D() > 0:
            rec = mp.reconstruction
            report["model"]["points_from"] = "the model"
        else:
            ldir = _latent_images(latent_dir, edi_path, lat, scene.camera, work)
            db = work / "database.db"
            name_to_id, px = _features(db, ldir, lat, scene.camera, cfg.colmap, timer, report)
            rec, _ = _given_reconstruction(scene, None, edi, db, ldir, work, lat, name_to_id, px, cfg, timer, report,
                                           poses=mp.latent_c2w)  # fmt: skip
            _drop_points(rec, lat, report)
            report["model"]["points_from"] = "triangulated from the latent frames at the model's poses"
        canon, c2w = _canonical_frame(rec, mp.latent_c2w, registered, report)
        report["model"]["canonical_scale"] = canon.scale
        c2w, interpolated = _fill_unregistered(c2w, registered, edi.timestamps_us, cfg, report)
        if "points" not in report:
            report["points"] = {"count": int(rec.num_points3D()), "removed_single_view": 0,
                                "mean_reprojection_error_px": float(rec.compute_mean_reprojection_error())}  # fmt: skip
        gt, est_to_gt = ground_truth_accuracy(scene, edi, c2w, registered, report)
        tc = None
        if scene.sharp is not None and len(scene.sharp.t_us):
            with timer("test cameras"):
                no_reg = replace(cfg, register_test_cameras=False)
                tc, report["test_cameras"] = place_test_cameras(
                    scene, rec, None, work, "model", canon, est_to_gt, no_reg, cfg.colmap
                )
        _write_outputs(tmp, rec, scene, edi, c2w, registered, interpolated, "model", canon, tc, gt, est_to_gt, cfg,
                       timer, report)  # fmt: skip
        shutil.rmtree(work, ignore_errors=True)
    log.info("wrote %s", out_dir)
    return report


def _given_reconstruction(scene, scene_path, edi, db, ldir, work, lat, name_to_id, px, cfg, timer, report,
                          poses=None):  # fmt: skip
    """Given mode: matches guided by the known poses, then points triangulated with the poses fixed. ``poses``:
    (V, L, 4, 4) latent poses to use instead of the scene's (model mode)."""
    from eigs.sfm import colmap as cm
    from eigs.sfm.given import guided_match, triangulate

    got = _given_poses(scene, edi.timestamps_us, scene_path) if poses is None else poses
    c2w_by_name = {n: got[v, k] for (v, k), n in zip(lat.slots, lat.names, strict=True)}
    cam = scene.camera
    with timer("matching (epipolar-guided, known poses)"):
        view_of = {name_to_id[n]: v for n, v in lat.view_of_name.items()}
        report["matcher"] = "epipolar-guided"
        report["guided_matching"] = guided_match(
            db, {name_to_id[n]: c for n, c in c2w_by_name.items()}, view_of, max_epipolar_px=4.0 * px
        )
    with timer("triangulation (poses fixed)"):
        rec = triangulate(
            db,
            ldir,
            work / "tri",
            name_to_id,
            c2w_by_name,
            cam.K,
            cam.width,
            cam.height,
            cam.distortion,
            num_threads=cm.MAPPER_THREADS,  # bundle adjustment: reproducible on one thread (colmap.py)
            px=px,
        )
    report["models"] = [len(lat.names)]
    return rec, []


# What mode resample takes from the base as it is: the COLMAP model (init reads its points) and the test cameras.
_BASE_FILES = ("cameras.bin", "images.bin", "points3D.bin", "frames.bin", "rigs.bin", "test_cameras.h5")


def _run_resample(scene, edi, out_dir: Path, cfg: SfmConfig, timer: _Timer, report: dict) -> dict:
    """Mode resample (eigs.sfm.resample): the base SfM's latent poses read at this EDI's latent times, its model and
    test cameras copied; accuracy over every resampled pose. No features, no COLMAP."""
    import json

    from eigs.artifacts.poses import LatentPoses, read_poses, write_poses
    from eigs.sfm.resample import resample_latent_poses
    from eigs.util.atomic import atomic_path

    base_dir = Path(cfg.base)  # type: ignore[arg-type]
    with timer("resample"):
        base = read_poses(base_dir)
        cam = scene.camera
        if base.n_views != edi.n_views:
            raise EigsError(base_dir, f"the base SfM has {base.n_views} views, the EDI result {edi.n_views}")
        if (base.width, base.height) != (cam.width, cam.height) or not np.allclose(base.K, cam.K, rtol=1e-9):
            raise EigsError(base_dir, "the base SfM's camera (size or intrinsics) is not the scene's")
        missing = [n for n in ("points3D.bin", "cameras.bin", "images.bin") if not (base_dir / n).is_file()]
        if missing:
            raise EigsError(base_dir, f"the base SfM has no {', '.join(missing)} (rerun its sfm)")
        c2w, registered, interpolated = resample_latent_poses(
            base.c2w, base.timestamps_us, base.valid, base.registered, edi.timestamps_us, edi.sharp
        )
    valid = np.all(np.isfinite(c2w), axis=(-2, -1))
    report["resample"] = {
        "base": str(base_dir),
        "base_latent_per_view": base.n_latent,
        "base_mode": base.mode,
        "copied": int((valid & ~interpolated).sum()),
        "interpolated": int(interpolated.sum()),
    }
    base_report = base_dir / "report.json"
    if base_report.is_file():  # the base's own figures, for reference
        got = json.loads(base_report.read_text())
        report["resample"]["base_accuracy_ate_rmse"] = got.get("accuracy", {}).get("ate_rmse")
        for key in ("points", "test_cameras"):
            if key in got:
                report[key] = got[key]
    log.info("resampled %d latent poses from %s (%d at its own times, %d interpolated within their view)",
             int(valid.sum()), base_dir, report["resample"]["copied"], report["resample"]["interpolated"])  # fmt: skip
    no_pose = [int(v) for v in range(c2w.shape[0]) if not valid[v].all()]
    if no_pose:
        log.warning("views without a pose for every latent: %s", no_pose)
    gt, est_to_gt = ground_truth_accuracy(scene, edi, c2w, valid, report)  # every pose, interpolated ones too
    with atomic_path(out_dir, directory=True) as tmp:
        for name in _BASE_FILES:
            if (base_dir / name).is_file():
                shutil.copy2(base_dir / name, tmp / name)
        write_poses(
            LatentPoses(c2w=c2w, timestamps_us=np.asarray(edi.timestamps_us, np.int64), registered=registered,
                        interpolated=interpolated, sharp=np.asarray(edi.sharp, bool), K=np.asarray(base.K, np.float64),
                        width=base.width, height=base.height, mode=base.mode, canonical=base.canonical),
            tmp / "poses.h5",
        )  # fmt: skip
        report["timings_s"] = timer.times
        write_report(tmp, report, c2w, valid, gt[0] if gt is not None else None, est_to_gt, cfg.plot)
    log.info("wrote %s", out_dir)
    return report


def _colmap_reconstruction(db, ldir, work, lat, px, cfg, timer, report):
    """COLMAP mode: matching, incremental (or global) mapping with a spatial second pass after sequential
    matching, then the rejection of latents registered far from their view's siblings."""
    from eigs.sfm import colmap as cm
    from eigs.sfm.outliers import reject_sibling_outliers

    opts = cfg.colmap
    with timer("matching"):
        report["matcher"] = cm.match(db, len(lat.names), lat.per_view, opts, px=px)
    with timer("mapping"):
        res = cm.map_images(db, ldir, work / "map", opts, px=px)
        if res.reconstruction is not None and report["matcher"] == "sequential" and res.model_sizes[0] < len(lat.names):
            res = _spatial_pass(db, ldir, work, res, lat.slots, lat.names, lat.per_view, opts, px)
        if res.lost_to_other_models and report["matcher"] == "sequential" and opts.matcher == "auto":
            kept = _exhaustive_pass(db, ldir, work, res, len(lat.names), lat.per_view, opts, px)
            if kept is not res:
                report["matcher"] = "sequential+exhaustive"
            res = kept
    report["models"] = res.model_sizes
    if res.reconstruction is None:
        raise EigsError(
            ldir,
            f"COLMAP reconstructed nothing from {len(lat.names)} latent frames (too few features or matches). "
            f"Remedies: {_remedies('colmap')}",
        )
    rec = res.reconstruction
    with timer("sibling check"):
        rejected = reject_sibling_outliers(rec, lat.view_of_name, refine_intrinsics=opts.refine_intrinsics)
    if res.lost_to_other_models:
        report["models_note"] = (
            f"COLMAP split the scene into {len(res.model_sizes)} models; the largest "
            f"({res.model_sizes[0]} images) was kept, {res.lost_to_other_models} images registered only "
            "in the others"
        )
    return rec, rejected


def _registration(rec, lat: _Latents, sharp, rejected, mode, cfg, out_dir, report):
    """((V, L, 4, 4) model-frame c2w, NaN where unregistered; (V, L) registered). Sharp views' one pose is copied
    to every slot. Raises when fewer than ``min_registered_fraction`` of the images registered."""
    from eigs.sfm import colmap as cm

    raw = np.full((lat.n_views, lat.per_view, 4, 4), np.nan)
    registered = np.zeros((lat.n_views, lat.per_view), bool)
    by_name = {im.name: im for im in rec.images.values() if im.has_pose}
    for (v, k), n in zip(lat.slots, lat.names, strict=True):
        if n in by_name:
            raw[v, k] = cm.c2w_of(by_name[n])
            registered[v, k] = True
    for v in np.flatnonzero(sharp):  # one image per sharp view: copy its pose to every slot
        raw[v, :] = raw[v, 0]
        registered[v, :] = registered[v, 0]
    names = lat.names
    n_reg = sum(n in by_name for n in names)
    frac = n_reg / len(names)
    unreg = [n for n in names if n not in by_name]
    report["registration"] = {
        "images": len(names),
        "registered": n_reg,
        "fraction": frac,
        "unregistered": unreg,
        "rejected_far_from_view": rejected,
    }
    log.info("registered %d of %d latent frames (%.1f %%)", n_reg, len(names), 100 * frac)
    if frac < cfg.min_registered_fraction:
        shown = ", ".join(unreg[:8]) + (" …" if len(unreg) > 8 else "")
        raise EigsError(
            out_dir,
            f"only {n_reg} of {len(names)} latent frames registered ({100 * frac:.0f} % < "
            f"{100 * cfg.min_registered_fraction:.0f} %); unregistered: {shown}. Remedies: {_remedies(mode)}",
        )
    return raw, registered


def _self_check(rec, raw, registered, timestamps_us, lat: _Latents, cfg, out_dir, report):
    """The self-check of the camera path (eigs.sfm.selfcheck) into ``report["self_check"]``; with
    ``cfg.self_check`` the views that fail it are deregistered (their latents count as unregistered) and a broken
    path stops the stage. Returns (raw, registered) without the dropped views."""
    from eigs.sfm.selfcheck import self_check

    sc = self_check(raw, registered, timestamps_us, report.get("models"))
    report["self_check"] = {"enforced": cfg.self_check, **sc.summary()}
    if not sc.applicable:
        log.info("self-check: not applied, the views are not one path in time (median path error %.2f steps: "
                 "independent viewpoints)", report["self_check"]["path_error_median"])  # fmt: skip
    for v in sc.failed_views:
        log.warning("self-check: view %d lies off the camera path (path error %.2f steps, turn %.1f°)%s", v,
                    sc.path_error[v], sc.turn_error_deg[v], "; dropped" if cfg.self_check else "")  # fmt: skip
    if not sc.passed:
        msg = "SfM self-check failed: " + "; ".join(sc.reasons)
        if cfg.self_check:
            raise EigsError(
                out_dir,
                f"{msg}. Its poses are not one camera moving in time; try the other mapper (`sfm: global_mapping`), "
                "sharper latent frames (an estimated EDI contrast threshold, more bins), given poses, or "
                "`sfm: self_check: false` to train on it anyway",
            )
        log.warning("%s (self_check is off: training on it)", msg)
    if not cfg.self_check or not sc.failed_views:
        return raw, registered
    failed = set(sc.failed_views)
    for im in list(rec.images.values()):
        if im.has_pose and lat.view_of_name[im.name] in failed:
            rec.deregister_frame(im.frame_id)
    raw, registered = raw.copy(), registered.copy()
    raw[sc.failed_views] = np.nan
    registered[sc.failed_views] = False
    report["registration"]["dropped_by_self_check"] = [int(v) for v in sc.failed_views]
    return raw, registered


def _canonical_frame(rec, raw, registered, report):
    """Move the model and the poses into the canonical frame: (transform, (V, L, 4, 4) c2w, NaN unregistered)."""
    from eigs.sfm import colmap as cm
    from eigs.sfm.canonical import canonical_transform, describe

    canon = canonical_transform(raw[registered][:, :3, 3])
    rec.transform(cm.sim3d(canon.scale, canon.R, canon.t))
    c2w = np.where(registered[..., None, None], canon.apply_c2w(np.nan_to_num(raw)), np.nan)
    report["canonical"] = describe(canon)
    return canon, c2w


def _fill_unregistered(c2w, registered, timestamps_us, cfg, report):
    """Interpolate unregistered latents from registered latents of the same view (when enabled):
    (c2w, (V, L) interpolated)."""
    from eigs.artifacts.edi import latent_png_name
    from eigs.sfm.poses import fill_within_views

    interpolated = np.zeros(registered.shape, bool)
    if (~registered).any() and cfg.interpolate_unregistered:
        c2w, interpolated = fill_within_views(c2w, registered, timestamps_us)
    no_pose = [int(v) for v in range(c2w.shape[0]) if not np.all(np.isfinite(c2w[v]))]
    report["registration"]["interpolated"] = [
        latent_png_name(v, k) for v, k in zip(*np.nonzero(interpolated), strict=True)
    ]
    report["registration"]["views_without_all_poses"] = no_pose
    if interpolated.any():
        log.warning("%d unregistered latent frames interpolated within their view", int(interpolated.sum()))
    if no_pose:
        log.warning("views without a pose for every latent: %s", no_pose)
    return c2w, interpolated


def _drop_points(rec, lat: _Latents, report: dict) -> None:
    """Remove points seen from one training view only; record the point statistics."""
    removed = _drop_single_view_points(rec, lat.view_of_name)
    if removed:
        log.info("removed %d points seen from one training view only (intra-exposure baseline)", removed)
    report["points"] = {
        "removed_single_view": removed,
        "count": int(rec.num_points3D()),
        "mean_reprojection_error_px": float(rec.compute_mean_reprojection_error()),
        "mean_track_length": float(rec.compute_mean_track_length()) if rec.num_points3D() else 0.0,
    }


def _write_outputs(
    tmp, rec, scene, edi, c2w, registered, interpolated, mode, canon, tc, gt, est_to_gt, cfg, timer, report
) -> None:
    """The COLMAP model, ``poses.h5``, ``test_cameras.h5``, ``report.png`` and ``report.json`` into ``tmp``."""
    from eigs.artifacts.poses import LatentPoses, write_poses, write_test_cameras

    cam = scene.camera
    rec.write(tmp)
    write_poses(
        LatentPoses(
            c2w=c2w,
            timestamps_us=np.asarray(edi.timestamps_us, np.int64),
            registered=registered,
            interpolated=interpolated,
            sharp=np.asarray(edi.sharp, bool),
            K=np.asarray(cam.K, np.float64),
            width=cam.width,
            height=cam.height,
            mode=mode,
            canonical=canon.matrix(),
        ),
        tmp / "poses.h5",
    )
    if tc is not None:
        write_test_cameras(tc, tmp / "test_cameras.h5")
    report["timings_s"] = timer.times
    write_report(tmp, report, c2w, registered, gt[0] if gt is not None else None, est_to_gt, cfg.plot)


def _drop_single_view_points(rec, view_of_name: dict[str, int]) -> int:
    """Delete 3-D points whose observations all come from one training view: their baseline is only the
    intra-exposure motion, so their depth is unreliable. Returns how many were removed."""
    view_of_id = {i: view_of_name.get(im.name, -1) for i, im in rec.images.items()}
    bad = [pid for pid, p in rec.points3D.items() if len({view_of_id[e.image_id] for e in p.track.elements}) < 2]
    for pid in bad:
        rec.delete_point3D(pid)
    return len(bad)


def _given_poses(scene, timestamps_us: np.ndarray, path: Path) -> np.ndarray:
    from eigs.scene.truth import latent_poses_at

    got = latent_poses_at(scene, timestamps_us, ground_truth_only=False, clamp=True)
    if got is None:
        raise EigsError(path, "--mode given: the scene has no poses for these views (use --mode colmap)")
    log.info("given poses: %s", got[1])
    return got[0]


def _spatial_pass(db, ldir, work, res, slots, names, L, opts, px):
    """Sequential matching misses pairs of views far apart in time: match spatial neighbours of the first
    model's camera centres (unregistered images take a registered sibling's centre) and map again."""
    from eigs.sfm import colmap as cm

    rec = res.reconstruction
    centre = {im.name: cm.c2w_of(im)[:3, 3] for im in rec.images.values() if im.has_pose}
    view_centre: dict[int, np.ndarray] = {}
    for (v, _k), n in zip(slots, names, strict=True):
        if n in centre:
            view_centre.setdefault(v, centre[n])
    import pycolmap

    d = pycolmap.Database.open(db)
    try:
        ids = {im.name: im.image_id for im in d.read_all_images()}
    finally:
        d.close()
    positions = {}
    for (v, _k), n in zip(slots, names, strict=True):
        pos = centre.get(n, view_centre.get(v))
        if pos is not None:
            positions[ids[n]] = pos
    cm.write_position_priors(db, positions)
    cm.match(db, len(names), L, opts, spatial=True, px=px)
    res2 = cm.map_images(db, ldir, work / "map2", opts, px=px)
    if res2.reconstruction is not None and res2.model_sizes[0] >= res.model_sizes[0]:
        return res2
    return res


def _exhaustive_pass(db, ldir, work, res, n_images, L, opts, px):
    """The scene is still split after sequential and spatial matching (issue 18: at B = 6 and 8 latent poses,
    10 of 24 views of `blocks` and `tree` fell outside the kept model): match the remaining pairs exhaustively
    (COLMAP skips pairs the database already holds) and map again. Returns the new result when its largest model
    registers more images than the old one, else ``res`` itself."""
    from dataclasses import replace

    from eigs.sfm import colmap as cm

    log.info("the scene is split into %d models after sequential matching: matching exhaustively", len(res.model_sizes))
    cm.match(db, n_images, L, replace(opts, matcher="exhaustive"), px=px)
    res2 = cm.map_images(db, ldir, work / "map3", opts, px=px)
    if res2.reconstruction is not None and res2.model_sizes[0] > res.model_sizes[0]:
        return res2
    return res
