"""``cameras.npz`` of a run folder: the training cameras as camera refinement left them (``camera_refine: true``).

Written by training for every run that refined its cameras (:mod:`eigs.train.gaussian.camera_refine`); read by
evaluation, which scores both sets against the ground truth (:func:`eigs.metrics.trajectory.trajectory_accuracy`).

- ``before``: (V, 4, 4) float64 each view's reference camera (latent k = 0) as the SfM stage gave it, model frame,
  scene units; NaN rows for views without a valid pose.
- ``after``: (V, 4, 4) float64 the same cameras corrected, ``before · exp(ξ_v)``.
- ``twist``: (V, 6) float64 the corrections ``ξ_v = (ω, ν)``: rotation vector (radians), then translation (scene
  units), in the camera frame; zero for views training never drew.
- ``views``: (V,) bool, the views training drew steps from.
- ``method``: the method name.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from eigs.artifacts._npz import read_npz, write_npz
from eigs.artifacts.run import CAMERAS
from eigs.errors import EigsError

CAMERAS_FORMAT = "eigs-refined-cameras"
FORMAT_VERSION = 1


@dataclass
class RefinedCameras:
    """See the module docstring for the fields and their shapes."""

    method: str
    before: np.ndarray
    after: np.ndarray
    twist: np.ndarray
    views: np.ndarray

    def validate(self, path: str | os.PathLike | None) -> None:
        v = self.views.shape[0] if self.views.ndim == 1 else -1
        if self.before.shape != (v, 4, 4) or self.after.shape != (v, 4, 4) or self.twist.shape != (v, 6):
            shapes = f"{self.before.shape}, {self.after.shape}, {self.twist.shape}"
            raise EigsError(path, f"refined cameras: before and after must be (V, 4, 4) and twist (V, 6) for "
                            f"V = {v} views, got {shapes}")  # fmt: skip
        used = self.views.astype(bool)
        for name in ("before", "after", "twist"):
            if not np.all(np.isfinite(getattr(self, name)[used])):
                raise EigsError(path, f"refined cameras: {name} has NaN/Inf values in a trained view")


def write_refined_cameras(cameras: RefinedCameras, path: str | os.PathLike) -> None:
    cameras.validate(path)
    arrays = {"method": np.array(cameras.method), "views": cameras.views.astype(bool)}
    arrays |= {name: getattr(cameras, name).astype(np.float64) for name in ("before", "after", "twist")}
    write_npz(path, CAMERAS_FORMAT, FORMAT_VERSION, arrays)


def read_refined_cameras(path: str | os.PathLike) -> RefinedCameras:
    """Read a run's ``cameras.npz`` (or the run folder holding it)."""
    p, z = read_npz(path, CAMERAS, CAMERAS_FORMAT, FORMAT_VERSION, "refined-cameras")
    try:
        cameras = RefinedCameras(method=str(z["method"]), before=z["before"], after=z["after"], twist=z["twist"],
                                 views=z["views"])  # fmt: skip
    except KeyError as err:
        raise EigsError(p, f"unreadable refined-cameras file (no {err})") from None
    cameras.validate(p)
    return cameras
