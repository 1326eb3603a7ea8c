"""What the viewer shows, with numpy only: run folders found and checked, Gaussians turned into viewer splats, and
SfM cameras turned into viewer cameras.

Conventions. Our Gaussians (:mod:`eigs.artifacts.gaussians`): means (N, 3) world units, log standard deviations,
unit quaternions w x y z, opacity logits, SH coefficients. A splat for the viewer: centre (N, 3), covariance
Σ = R diag(s²) Rᵀ (N, 3, 3) with s = exp(log_scales) and R the quaternion's rotation, colour the SH degree-0 term
0.5 + C0·dc clamped to [0, 1] (the viewer has no view-dependent colour), opacity sigmoid(logit) (N, 1).
Cameras: camera-to-world in OpenCV axes (x right, y down, z forward), the same axes viser's camera uses, so the
rotation goes over unchanged; the vertical field of view is 2·atan(H / 2 f_y) (the viewer centres the principal
point).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from eigs.artifacts import run as run_folder
from eigs.artifacts.gaussians import SH_C0, GaussianCloud
from eigs.errors import EigsError

MODEL_GAUSSIANS = run_folder.MODEL_PLY
MODEL_FIELD = run_folder.MODEL_NPZ
RunKind = Literal["gaussians", "field"]


@dataclass
class Splats:
    """Gaussians as the viewer draws them: ``centers`` (N, 3), ``covariances`` (N, 3, 3) world units²,
    ``rgbs`` (N, 3) in [0, 1], ``opacities`` (N, 1) in [0, 1]; all float32."""

    centers: np.ndarray
    covariances: np.ndarray
    rgbs: np.ndarray
    opacities: np.ndarray

    def __len__(self) -> int:
        return int(self.centers.shape[0])


def quat_to_matrix(quats: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions w x y z (any norm) → (N, 3, 3) rotation matrices."""
    q = np.asarray(quats, np.float64)
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def matrix_to_quat(rot: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix → (4,) unit quaternion w x y z with w ≥ 0."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(rot, np.float64)).as_quat()
    q = np.array([w, x, y, z])
    return q if w >= 0 else -q


def cloud_to_splats(cloud: GaussianCloud) -> Splats:
    """The viewer's splats of a Gaussian cloud (conventions in the module docstring)."""
    rot = quat_to_matrix(cloud.quats)
    var = np.exp(2.0 * np.asarray(cloud.log_scales, np.float64))  # (N, 3)
    cov = np.einsum("nij,nj,nkj->nik", rot, var, rot)
    rgb = np.clip(SH_C0 * np.asarray(cloud.f_dc, np.float64) + 0.5, 0.0, 1.0)
    alpha = 1.0 / (1.0 + np.exp(-np.asarray(cloud.opacity, np.float64)))
    return Splats(
        centers=np.ascontiguousarray(cloud.means, np.float32),
        covariances=cov.astype(np.float32),
        rgbs=rgb.astype(np.float32),
        opacities=alpha[:, None].astype(np.float32),
    )


@dataclass
class ViewCamera:
    """One camera of the scene as the viewer places it: ``c2w`` (4, 4) OpenCV axes; ``fov_y`` vertical field of
    view in radians; ``aspect`` width / height; ``look_at`` the orbit centre in front of it (world units)."""

    name: str
    c2w: np.ndarray
    fov_y: float
    aspect: float
    look_at: np.ndarray

    @property
    def position(self) -> np.ndarray:
        return np.asarray(self.c2w[:3, 3], np.float64)

    @property
    def wxyz(self) -> np.ndarray:
        return matrix_to_quat(self.c2w[:3, :3])

    @property
    def up(self) -> np.ndarray:
        """World direction of the image's up (−y in OpenCV axes)."""
        return -np.asarray(self.c2w[:3, 1], np.float64)


def fov_y(K: np.ndarray, height: int) -> float:
    """Vertical field of view (radians) of intrinsics ``K`` (3, 3) for an image ``height`` pixels high."""
    return float(2.0 * np.arctan2(height / 2.0, float(K[1, 1])))


def view_camera(name: str, c2w: np.ndarray, K: np.ndarray, width: int, height: int, centre: np.ndarray) -> ViewCamera:
    """A viewer camera at ``c2w`` whose orbit centre is the point of its optical axis nearest to ``centre`` (3,)
    (at least a tenth of the distance to ``centre`` in front of it)."""
    c2w = np.asarray(c2w, np.float64)
    pos, fwd = c2w[:3, 3], c2w[:3, 2] / np.linalg.norm(c2w[:3, 2])
    dist = float(np.linalg.norm(centre - pos))
    depth = max(float(np.dot(centre - pos, fwd)), 0.1 * dist, 1e-3)
    return ViewCamera(name, c2w, fov_y(K, height), width / height, pos + depth * fwd)


@dataclass
class RunInfo:
    """A run folder: ``path``; ``label`` shown in the viewer; ``kind`` gaussians (model.ply) or field (model.npz);
    ``sfm`` its SfM folder (poses.h5, test_cameras.h5); ``scene`` its scene file, or None when not found."""

    path: Path
    label: str
    kind: RunKind
    sfm: Path
    scene: Path | None

    @property
    def model(self) -> Path:
        return self.path / (MODEL_GAUSSIANS if self.kind == "gaussians" else MODEL_FIELD)


def _input_path(value: object, fallback: Path) -> Path:
    """A run config's input path: as written when it exists (relative to the working directory, as the workflow
    runs), else the run folder's standard neighbour ``fallback``."""
    if isinstance(value, str) and value and Path(value).exists():
        return Path(value)
    return fallback


def resolve_run(path: str | os.PathLike, *, sfm: str | os.PathLike | None = None,
                scene: str | os.PathLike | None = None) -> RunInfo:  # fmt: skip
    """Check a run folder (config.json and model.ply or model.npz) and find its SfM folder and scene file (from
    config.json's inputs, else the workflow layout ``<scene>/b<B>/<run>`` beside ``sfm/`` and ``../scene.h5``)."""
    run = Path(path)
    if not run.is_dir():
        raise EigsError(run, "no such run folder")
    cfg_path = run / run_folder.CONFIG
    if not cfg_path.is_file():
        raise EigsError(run, "no config.json (not a finished run folder; run `eigs train` first)")
    try:
        cfg = json.loads(cfg_path.read_text())
        inputs = cfg.get("inputs", {}) if isinstance(cfg, dict) else {}
    except (ValueError, OSError) as err:
        raise EigsError(cfg_path, f"unreadable run config ({err})") from None
    if (run / MODEL_GAUSSIANS).is_file():
        kind: RunKind = "gaussians"
    elif (run / MODEL_FIELD).is_file():
        kind = "field"
    else:
        raise EigsError(run, f"no {MODEL_GAUSSIANS} or {MODEL_FIELD} (training did not finish)")
    sfm_dir = Path(sfm) if sfm is not None else _input_path(inputs.get("sfm"), run.parent / "sfm")
    scene_file = Path(scene) if scene is not None else _input_path(inputs.get("scene"), run.parent.parent / "scene.h5")
    label = f"{run.parent.name}/{run.name}" if run.parent.name.startswith("b") else run.name
    return RunInfo(run, label, kind, sfm_dir, scene_file if scene_file.is_file() else None)


def sibling_runs(run: RunInfo) -> list[Path]:
    """The other finished run folders beside ``run`` (same parent, e.g. ``<scene>/b4/``) that use the same SfM
    folder, so they share its cameras and frame: the runs one can switch between at the same camera."""
    out = []
    for cand in sorted(p for p in run.path.parent.iterdir() if p.is_dir() and p.resolve() != run.path.resolve()):
        if not (cand / run_folder.CONFIG).is_file():
            continue
        if not ((cand / MODEL_GAUSSIANS).is_file() or (cand / MODEL_FIELD).is_file()):
            continue
        try:
            other = resolve_run(cand)
        except EigsError:
            continue
        if other.sfm.resolve() == run.sfm.resolve():
            out.append(cand)
    return out


def check_gaussian_run(run: RunInfo) -> None:
    """Raise the one-line error for a run the viewer cannot show (a field run)."""
    if run.kind == "field":
        raise EigsError(run.model, "a field run (model.npz) has no Gaussians to show in the 3D viewer; "
                                   "render its views with `eigs render`")  # fmt: skip


def scene_cameras(sfm: Path, centre: np.ndarray) -> tuple[list[ViewCamera], list[ViewCamera], tuple[int, int]]:
    """The training cameras (latent 0 of each view with a valid pose, as ``eigs render --cameras train``) and the
    test cameras (none when the scene has no test_cameras.h5) of an SfM folder, and the image size (width,
    height). ``centre`` (3,): the scene's centre, for the orbit centres."""
    from eigs.artifacts.poses import read_poses, read_test_cameras

    poses = read_poses(sfm)
    w, h = poses.width, poses.height
    valid = poses.valid[:, 0]
    train = [view_camera(f"train {v}", poses.c2w[v, 0], poses.K, w, h, centre) for v in np.nonzero(valid)[0]]
    test: list[ViewCamera] = []
    if (sfm / "test_cameras.h5").is_file():
        tc = read_test_cameras(sfm)
        test = [view_camera(f"test {i}", tc.c2w[i], tc.K[i], tc.width, tc.height, centre) for i in range(len(tc))
                if np.all(np.isfinite(tc.c2w[i]))]  # fmt: skip
    return train, test, (w, h)


def scene_centre(splats: Splats) -> np.ndarray:
    """A robust centre of the Gaussians (per-axis median of the centres of the more opaque half)."""
    keep = splats.opacities[:, 0] >= np.median(splats.opacities[:, 0])
    return np.median(splats.centers[keep], axis=0).astype(np.float64)


def up_direction(cameras: list[ViewCamera]) -> np.ndarray:
    """The world's up for orbiting: the normalised mean of the cameras' up directions (+z when they cancel)."""
    if not cameras:
        return np.array([0.0, 0.0, 1.0])
    up = np.mean([c.up for c in cameras], axis=0)
    n = float(np.linalg.norm(up))
    return up / n if n > 1e-6 else np.array([0.0, 0.0, 1.0])


def pick_camera(spec: str, train: list[ViewCamera], test: list[ViewCamera]) -> ViewCamera:
    """``test:I`` or ``train:I`` → that camera (I counts the cameras in order, from 0)."""
    kind, _, idx = spec.partition(":")
    cams = {"test": test, "train": train}.get(kind)
    if cams is None or not idx.isdigit():
        raise EigsError(None, f"--camera {spec!r}: expected test:I or train:I")
    i = int(idx)
    if i >= len(cams):
        raise EigsError(None, f"--camera {spec!r}: the scene has {len(cams)} {kind} cameras")
    return cams[i]
