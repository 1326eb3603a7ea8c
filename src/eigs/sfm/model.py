"""Model mode (``sfm: {mode: model, path: DIR}``): an existing COLMAP sparse model gives the poses; no mapping.

- **Reading**: ``pycolmap.Reconstruction(DIR)`` (binary ``*.bin`` or text ``*.txt``, COLMAP 3 or 4 layouts). Any
  failure, or a model without registered images, is one :class:`EigsError` naming the directory.
- **Matching**: training view v ↔ the model image whose name equals the scene's frame name v
  (``frames/names``, written by ingestion: the image path as the source lists it); failing that, the same file
  name (last path component); failing that, the same stem (``frame_12.jpg`` ↔ ``images/frame_12.png``). A view
  without an image (or whose image has no pose), or a name that matches several images, is an error naming the
  view and the name. Model images that match no view (frames not kept by ``--views``) are listed in the report.
- **Intrinsics**: each matched image's camera is compared with the scene's K. A model at another resolution is
  accepted when it is a uniform rescale of the scene's size (COLMAP on full-size frames, a scene ingested
  downsampled): K is compared after dividing by the factor. Focal lengths must agree within
  ``intrinsics_tolerance`` (relative), the principal point within ``intrinsics_tolerance`` × the image size, and
  distortion coefficients (COLMAP's SIMPLE_RADIAL / RADIAL / OPENCV / FULL_OPENCV mapped to OpenCV k1 k2 p1 p2
  k3) within ``intrinsics_tolerance`` of the scene's (zero after ingestion's undistortion). Otherwise: an error
  giving both values.
- **Convention**: COLMAP stores world-to-camera ``cam_from_world`` = [R | t] in OpenCV axes (x right, y down,
  z forward), as we do: our camera-to-world is its inverse, [Rᵀ | −Rᵀt]. No axis change.
- **Times and latent poses**: a model image's pose is taken at its frame's exposure midpoint (or its timestamp
  for frames without exposure windows). The latent poses within each exposure are interpolated in time through
  the neighbouring frames' poses (linear centres, slerp rotations: :func:`eigs.sfm.poses.interpolate_c2w`, the
  interpolation given mode applies to a dense trajectory), held at the first/last frame's pose beyond them. A
  latent time equal to the midpoint gets the model's pose exactly. Sharp views (EDI found no motion) and scenes
  whose frames have no times copy the frame's pose to every latent.
- **Scale**: the model's units are arbitrary; the stage moves everything into the canonical frame (centres
  centred, RMS radius 1) like every mode, and reports the model's RMS radius and the factor.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from eigs.errors import EigsError

log = logging.getLogger(__name__)

# COLMAP camera model → indices of (k1, k2, p1, p2, k3) in its extra parameters (after focal and principal point)
_DISTORTION = {
    "SIMPLE_PINHOLE": {},
    "PINHOLE": {},
    "SIMPLE_RADIAL": {0: 0},
    "RADIAL": {0: 0, 1: 1},
    "OPENCV": {0: 0, 1: 1, 2: 2, 3: 3},
    "FULL_OPENCV": {0: 0, 1: 1, 2: 2, 3: 3, 4: 4},
}
_FULL_OPENCV_REST = (5, 6, 7)  # k4 k5 k6 must be zero


@dataclass
class ModelPoses:
    """What a user's model gives the stage. ``c2w``: (V, 4, 4) camera-to-world (model frame) per training view;
    ``image_names``: the matched model image per view; ``latent_c2w``: (V, L, 4, 4) at the EDI latent times;
    ``report``: JSON-able facts for ``report.json``."""

    reconstruction: object
    c2w: np.ndarray
    image_names: list[str]
    latent_c2w: np.ndarray
    report: dict = field(default_factory=dict)


def read_model(path: str | Path):
    """The pycolmap Reconstruction at ``path``; EigsError naming it when it cannot be read or has no posed image."""
    from eigs.sfm.colmap import load_pycolmap

    pycolmap = load_pycolmap()
    p = Path(path)
    if not p.is_dir():
        raise EigsError(p, "no such COLMAP model directory")
    _probe(p)
    try:
        rec = pycolmap.Reconstruction(str(p))
    except Exception as err:  # pycolmap raises ValueError, IndexError, RuntimeError on bad files
        msg = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise EigsError(p, f"unreadable COLMAP model (truncated or corrupt?): {msg}") from None
    if not any(im.has_pose for im in rec.images.values()):
        raise EigsError(p, "the COLMAP model has no registered image")
    return rec


_PROBE = "import sys, pycolmap; pycolmap.Reconstruction(sys.argv[1])"
# Address space of the probing child, plus 64 × the model's size. Reading a small valid model peaks at 0.37 GB of
# address space (Python and pycolmap loaded); a damaged count makes the reader allocate until the cap, at about
# 3.5 CPU s per GB filled (a truncated points3D.bin: 2.2 CPU s under 1 GB, 14 under 4 GB, 106 uncapped).
PROBE_MEMORY_BYTES = 1 << 30


def _probe(p: Path) -> None:
    """Read the model once in a child process: COLMAP's reader aborts the whole process on some damaged files (a
    truncated points3D.bin fails a glog CHECK), which must become a one-line error, not a crash of the stage."""
    import subprocess
    import sys

    size = sum(f.stat().st_size for f in p.iterdir() if f.is_file())
    limit = PROBE_MEMORY_BYTES + 64 * size  # a damaged count makes the reader allocate absurd amounts: fail fast

    def cap() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # an aborted read leaves no core file in the user's folder

    proc = subprocess.run([sys.executable, "-c", _PROBE, str(p)], capture_output=True, text=True, check=False,
                          preexec_fn=cap)  # fmt: skip
    if proc.returncode == 0:
        return
    lines = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.split(":", 1)[0].endswith(("Error", "Exception"))]
    if errors:
        why = errors[-1].split(":", 1)[1].strip() or errors[-1].split(":", 1)[0]
        raise EigsError(p, f"unreadable COLMAP model (truncated or corrupt?): {why}")
    checks = [ln for ln in lines if "Check failed" in ln]
    what = checks[0].split("]", 1)[-1].strip() if checks else f"exit status {proc.returncode}"
    raise EigsError(p, f"unreadable COLMAP model (truncated or corrupt?): COLMAP's reader aborted ({what})")


def _key(name: str, level: int) -> str:
    pp = PurePosixPath(name.replace("\\", "/"))
    return str(pp) if level == 0 else pp.name if level == 1 else pp.stem


def match_views(rec, names: list[str], path: Path) -> tuple[list[int], list[str]]:
    """Model image id of every view (by name: full path, then file name, then stem) and the unmatched images."""
    images = {im.image_id: im for im in rec.images.values()}
    out: list[int] = []
    for v, name in enumerate(names):
        found = None
        for level in range(3):
            hits = [i for i, im in images.items() if _key(im.name, level) == _key(name, level)]
            if len(hits) > 1:
                shown = ", ".join(sorted(images[i].name for i in hits)[:4])
                raise EigsError(path, f"view {v} ({name}) matches several model images: {shown}")
            if hits:
                found = hits[0]
                break
        if found is None:
            raise EigsError(path, f"the model has no image for view {v} ({name})")
        if not images[found].has_pose:
            raise EigsError(path, f"the model's image {images[found].name} (view {v}) has no pose (unregistered)")
        out.append(found)
    used = set(out)
    if len(used) != len(out):
        raise EigsError(path, "two views matched the same model image (frame names that differ only by folder)")
    return out, sorted(im.name for i, im in images.items() if i not in used)


def camera_distortion(cam) -> np.ndarray:
    """OpenCV (k1, k2, p1, p2, k3) of a COLMAP camera; EigsError for models we cannot express so."""
    model = cam.model.name
    if model not in _DISTORTION:
        raise EigsError(None, f"camera {cam.camera_id}: model {model} is not a pinhole model with OpenCV distortion")
    extra = np.asarray(cam.params, np.float64)[list(cam.extra_params_idxs())]
    d = np.zeros(5)
    for src, dst in _DISTORTION[model].items():
        d[dst] = extra[src]
    if model == "FULL_OPENCV" and np.any(extra[list(_FULL_OPENCV_REST)] != 0):
        raise EigsError(None, f"camera {cam.camera_id}: FULL_OPENCV with k4..k6 ≠ 0 (rational model) is not supported")
    return d


def check_intrinsics(rec, image_ids: list[int], K: np.ndarray, width: int, height: int, distortion: np.ndarray,
                     tol: float, path: Path) -> dict:  # fmt: skip
    """Compare every camera used by ``image_ids`` with the scene's camera (module docstring); returns the report."""
    out = {}
    for cid in sorted({rec.images[i].camera_id for i in image_ids}):
        cam = rec.cameras[cid]
        sx, sy = cam.width / width, cam.height / height
        if abs(sx - sy) > tol * max(sx, sy) or min(sx, sy) <= 0:
            raise EigsError(path, f"camera {cid} is {cam.width}×{cam.height}, the scene {width}×{height}: not a "
                            "uniform rescale of the scene's frames")  # fmt: skip
        try:
            d = camera_distortion(cam)
        except EigsError as err:
            raise EigsError(path, err.problem) from None
        Km = np.asarray(cam.calibration_matrix(), np.float64)
        Ks = Km.copy()
        Ks[0] /= sx
        Ks[1] /= sy
        f_err = max(abs(Ks[0, 0] / K[0, 0] - 1), abs(Ks[1, 1] / K[1, 1] - 1))
        c_err = max(abs(Ks[0, 2] - K[0, 2]) / width, abs(Ks[1, 2] - K[1, 2]) / height)
        d_err = float(np.max(np.abs(d - np.asarray(distortion, np.float64))))
        what = f" (after dividing by the size ratio {sx:g})" if abs(sx - 1) > 1e-12 else ""
        if f_err > tol or c_err > tol:
            raise EigsError(
                path,
                f"camera {cid}{what} has fx, fy, cx, cy = {Ks[0, 0]:.6g}, {Ks[1, 1]:.6g}, {Ks[0, 2]:.6g}, "
                f"{Ks[1, 2]:.6g} but the scene {K[0, 0]:.6g}, {K[1, 1]:.6g}, {K[0, 2]:.6g}, {K[1, 2]:.6g} (pixel "
                f"centres at +0.5, COLMAP's convention and ours; tolerance {tol:g}, sfm: intrinsics_tolerance)",
            )
        if d_err > tol:
            raise EigsError(path, f"camera {cid} ({cam.model.name}) has distortion {np.round(d, 6).tolist()} but "
                            f"the scene {np.round(distortion, 6).tolist()} (tolerance {tol:g})")  # fmt: skip
        out[str(cid)] = {"model": cam.model.name, "size": [cam.width, cam.height], "scale": sx,
                         "focal_relative_error": f_err, "principal_point_error_fraction": c_err}  # fmt: skip
    return out


def frame_times(scene) -> np.ndarray | None:
    """(V,) int64 time of each frame's pose: exposure midpoints, else frame timestamps, else None."""
    fr = scene.frames
    if fr is None:
        return None
    if fr.exposure_us is not None:
        return (fr.exposure_us[:, 0] + fr.exposure_us[:, 1]) // 2
    return None if fr.t_us is None else np.asarray(fr.t_us, np.int64)


def model_poses(path: str | Path, scene, timestamps_us: np.ndarray, sharp: np.ndarray, tol: float) -> ModelPoses:
    """Read the model at ``path``, match it to the scene's views, check the intrinsics and give every latent its
    pose (module docstring). ``timestamps_us``: (V, L) EDI latent times; ``sharp``: (V,) EDI's sharp views."""
    from eigs.sfm.colmap import c2w_of
    from eigs.sfm.poses import interpolate_c2w

    p = Path(path)
    fr = scene.frames
    if fr is None or fr.names is None:
        raise EigsError(p, f"scene {scene.name} has no frame names to match the model's images by (scenes ingested "
                        "from raw formats or e2nerf-real layouts have them; re-ingest older scene files)")  # fmt: skip
    rec = read_model(p)
    ids, unmatched = match_views(rec, list(fr.names), p)
    cams = check_intrinsics(rec, ids, scene.camera.K, scene.camera.width, scene.camera.height,
                            scene.camera.distortion, tol, p)  # fmt: skip
    c2w = np.stack([c2w_of(rec.images[i]) for i in ids])
    if not np.all(np.isfinite(c2w)):
        raise EigsError(p, "the model has non-finite poses")
    ts = np.asarray(timestamps_us, np.int64)
    V, L = ts.shape
    t = frame_times(scene)
    latent = np.repeat(c2w[:, None], L, axis=1)
    if t is not None and V > 1 and np.all(np.diff(t) > 0):
        latent = interpolate_c2w(t, c2w, ts.ravel()).reshape(V, L, 4, 4)
        how = "interpolated in time through the frames' poses at their exposure midpoints (or timestamps)"
    else:
        how = "each frame's pose copied to its latents (frames without increasing times)"
    latent[np.asarray(sharp, bool)] = c2w[np.asarray(sharp, bool), None]
    centres = c2w[:, :3, 3]
    rms = float(np.sqrt(np.mean(np.sum((centres - centres.mean(0)) ** 2, axis=1))))
    report = {
        "path": str(p),
        "images": int(rec.num_images()),
        "matched": V,
        "unmatched_images": unmatched,
        "points": int(rec.num_points3D()),
        "cameras": cams,
        "latent_poses": how,
        "rms_radius_model_units": rms,
        "convention": "c2w = inverse(cam_from_world); COLMAP and eigs share OpenCV camera axes",
    }
    log.info("COLMAP model %s: %d views matched, %d images unmatched, %d points", p, V, len(unmatched),
             rec.num_points3D())  # fmt: skip
    return ModelPoses(rec, c2w, [rec.images[i].name for i in ids], latent, report)
