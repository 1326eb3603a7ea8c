"""``motion.npz`` of a run folder: the motion a method applies during each training view's exposure.

Written by training for every method that models motion within the exposure (the multi-render and trajectory
methods); read by evaluation, which scores it against the ground-truth camera motion (:mod:`eigs.metrics.motion`).

- ``points``: (G, 3) float32 centres of the Gaussians the displacements were evaluated at: a seeded sample of at
  most :data:`MAX_POINTS` of the trained model's centres, model (canonical) frame, scene units.
- ``displacement``: (V, N, G, 3) float32 how the method moves each point to render latent time k = 1..N of view v
  from the view's reference camera (latent k = 0): for per-Gaussian methods the offsets the renders use (ADE,
  pose prior), for fixed-pose and trajectory methods the rigid motion of their camera expressed as a motion of the
  scene, ``P_0 · P_k⁻¹ x − x``.
- ``reference_c2w``: (V, 4, 4) float64 each view's reference camera (latent k = 0) as training used it.
- ``camera_c2w``: (V, N, 4, 4) float64 the camera poses at the latent times, for methods that have one (trajectory
  and fixed-pose methods); absent otherwise.
- ``views``: (V,) bool, the views training drew steps from (valid reference pose; views EDI marked sharp included);
  the displacement of a view outside them is zero (it has no motion to report).
- ``method``: the method name.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from eigs.artifacts._npz import read_npz, write_npz
from eigs.artifacts.run import MOTION
from eigs.errors import EigsError

MOTION_FORMAT = "eigs-motion"
FORMAT_VERSION = 1
MAX_POINTS = 2048  # centres sampled for the motion file (the error metrics are means over points: 2048 is plenty)
FILE_NAME = MOTION  # in the run folder (eigs.artifacts.run)


@dataclass
class RunMotion:
    """See the module docstring for the fields and their shapes."""

    method: str
    points: np.ndarray
    displacement: np.ndarray
    reference_c2w: np.ndarray
    views: np.ndarray
    camera_c2w: np.ndarray | None = None

    def validate(self, path: str | os.PathLike | None) -> None:
        g = self.points.shape[0] if self.points.ndim == 2 else -1
        if self.points.shape != (g, 3):
            raise EigsError(path, f"motion: points must be (G, 3), got {self.points.shape}")
        d = self.displacement
        if d.ndim != 4 or d.shape[2:] != (g, 3):
            raise EigsError(path, f"motion: displacement must be (V, N, {g}, 3), got {d.shape}")
        v, n = d.shape[:2]
        if self.reference_c2w.shape != (v, 4, 4) or self.views.shape != (v,):
            raise EigsError(path, "motion: reference_c2w must be (V, 4, 4) and views (V,)")
        if self.camera_c2w is not None and self.camera_c2w.shape != (v, n, 4, 4):
            raise EigsError(path, f"motion: camera_c2w must be ({v}, {n}, 4, 4), got {self.camera_c2w.shape}")
        for name in ("points", "displacement"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise EigsError(path, f"motion: {name} has NaN/Inf values")


def sample_indices(n: int, seed: int = 0) -> np.ndarray:
    """Sorted indices of at most :data:`MAX_POINTS` of ``n`` points (all of them when n is small; seeded)."""
    if n <= MAX_POINTS:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, MAX_POINTS, replace=False))


def write_motion(motion: RunMotion, path: str | os.PathLike) -> None:
    motion.validate(path)
    arrays = {
        "method": np.array(motion.method),
        "points": motion.points.astype(np.float32),
        "displacement": motion.displacement.astype(np.float32),
        "reference_c2w": motion.reference_c2w.astype(np.float64),
        "views": motion.views.astype(bool),
    }
    if motion.camera_c2w is not None:
        arrays["camera_c2w"] = motion.camera_c2w.astype(np.float64)
    write_npz(path, MOTION_FORMAT, FORMAT_VERSION, arrays)


def read_motion(path: str | os.PathLike) -> RunMotion:
    """Read a run's ``motion.npz`` (or the run folder holding it)."""
    p, z = read_npz(path, FILE_NAME, MOTION_FORMAT, FORMAT_VERSION, "motion")
    try:
        motion = RunMotion(
            method=str(z["method"]), points=z["points"], displacement=z["displacement"],
            reference_c2w=z["reference_c2w"], views=z["views"], camera_c2w=z.get("camera_c2w"),
        )  # fmt: skip
    except KeyError as err:
        raise EigsError(p, f"unreadable motion file (no {err})") from None
    motion.validate(p)
    return motion
